"""Random numbers addressed by index, so a teacher's ``i``-th task never depends on batching or timing.

One PCG64 stream per (seed, purpose); draw ``i`` owns a fixed-width slice of it, reached with
``advance`` (a jump, not a replay), so drawing tasks 0..9 at once or in ten calls gives the same
numbers, and a rebuilt teacher can continue at any index.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtri

TASK_STREAM = 0
FIT_STREAM = 1


def indexed_uniforms(seed: int, stream: int, first: int, count: int, width: int) -> np.ndarray:
    """Uniform numbers in [0, 1), shape (count, width); row ``i`` depends only on (seed, stream,
    first + i). Each double consumes exactly one 64-bit output of PCG64, which keeps rows aligned."""
    bit_generator = np.random.PCG64(np.random.SeedSequence([seed, stream]))
    bit_generator.advance(first * width)
    return np.random.Generator(bit_generator).random((count, width))


def indexed_seed(seed: int, stream: int, index: int) -> int:
    """A 32-bit seed for the ``index``-th use of a library that takes an integer seed (scikit-learn)."""
    return int(np.random.SeedSequence([seed, stream, index]).generate_state(1)[0])


def standard_normals(uniforms: np.ndarray) -> np.ndarray:
    """Inverse-CDF normals from uniforms in [0, 1), so each normal costs exactly one indexed uniform;
    shifted off 0 so a drawn 0 stays finite (a 2**-54 bias is immaterial)."""
    normals: np.ndarray = ndtri(uniforms + 2.0**-54)
    return normals
