"""pybullet without the lines its C code prints.

pybullet writes its build time on import and ``argv[0]=`` on every connection straight to the C
streams, where they land between ``train``'s progress bar and ``evaluate``'s results. Import
pybullet and ``BulletClient`` from here, never directly, so the import happens silenced.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from collections.abc import Iterator

_LIBC = ctypes.CDLL(None)


@contextlib.contextmanager
def native_output_silenced() -> Iterator[None]:
    """Send what native code writes to file descriptors 1 and 2 to /dev/null while the block runs.

    C stdio buffers a piped stdout, so it is flushed on both sides: before, so nothing already
    written is lost; after, so nothing written inside leaks out later. Python exceptions still
    surface: they travel as objects, not through the descriptors.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    _LIBC.fflush(None)
    with contextlib.ExitStack() as restore:
        for descriptor in (1, 2):
            try:
                saved = os.dup(descriptor)
            except OSError:  # closed descriptor: nothing to protect
                continue
            restore.callback(os.close, saved)
            restore.callback(os.dup2, saved, descriptor)
        restore.callback(_LIBC.fflush, None)
        with open(os.devnull, "wb") as devnull:
            for descriptor in (1, 2):
                with contextlib.suppress(OSError):
                    os.dup2(devnull.fileno(), descriptor)
        yield


with native_output_silenced():
    import pybullet
    from pybullet_utils.bullet_client import BulletClient


def direct_client() -> BulletClient:
    """A physics client of its own (DIRECT mode: no window, no shared server)."""
    with native_output_silenced():
        return BulletClient(connection_mode=pybullet.DIRECT)


def gui_client() -> BulletClient:
    """A physics client that opens pybullet's window (needs a display; one per process). The window's
    own camera previews are switched off: they show nothing until a camera image is asked for."""
    with native_output_silenced():
        client = BulletClient(connection_mode=pybullet.GUI)
    for preview in (
        pybullet.COV_ENABLE_RGB_BUFFER_PREVIEW,
        pybullet.COV_ENABLE_DEPTH_BUFFER_PREVIEW,
        pybullet.COV_ENABLE_SEGMENTATION_MARK_PREVIEW,
    ):
        client.configureDebugVisualizer(preview, 0)
    return client


__all__ = ["BulletClient", "direct_client", "gui_client", "native_output_silenced", "pybullet"]
