"""Running observation normalisation shared by the learner and the rollout workers.

The learner owns the statistics and updates them from each batch; workers receive a frozen copy
with every weight broadcast, so the policy always sees observations scaled exactly as it was
trained on them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class NormalizerState:
    """A picklable snapshot of the statistics (what travels to workers and into checkpoints)."""

    mean: np.ndarray
    var: np.ndarray
    count: float


NORMALIZER_EPSILON = 1e-8
"""Added to the variance before its square root, so a constant dimension does not divide by zero."""


class RunningNormalizer:
    """Per-dimension running mean and variance (parallel Welford), with clipping of the result."""

    def __init__(self, size: int, clip: float = 10.0) -> None:
        if size < 1:
            raise ValueError(f"normaliser size must be positive, got {size}")
        if clip <= 0:
            raise ValueError(f"normaliser clip must be positive, got {clip}")
        self.clip = float(clip)
        self.mean = np.zeros(size, dtype=np.float64)
        self.var = np.ones(size, dtype=np.float64)
        self.count = 0.0

    def update(self, batch: np.ndarray) -> None:
        """Fold a batch of shape (n, size) into the statistics."""
        batch = np.asarray(batch, dtype=np.float64).reshape(-1, self.mean.size)
        if batch.shape[0] == 0:
            return
        batch_mean = batch.mean(axis=0)
        batch_var = batch.var(axis=0)
        batch_count = float(batch.shape[0])
        total = self.count + batch_count
        delta = batch_mean - self.mean
        self.mean = self.mean + delta * batch_count / total
        combined_m2 = self.var * self.count + batch_var * batch_count + delta**2 * self.count * batch_count / total
        self.var = combined_m2 / total
        self.count = total

    def normalize(self, observations: np.ndarray) -> np.ndarray:
        scaled = (np.asarray(observations, dtype=np.float64) - self.mean) / np.sqrt(self.var + NORMALIZER_EPSILON)
        return np.clip(scaled, -self.clip, self.clip).astype(np.float32)

    def state(self) -> NormalizerState:
        return NormalizerState(mean=self.mean.copy(), var=self.var.copy(), count=self.count)

    def load_state(self, state: NormalizerState) -> None:
        if state.mean.shape != self.mean.shape:
            raise ValueError(f"normaliser state has size {state.mean.size}, expected {self.mean.size}")
        self.mean = np.array(state.mean, dtype=np.float64)
        self.var = np.array(state.var, dtype=np.float64)
        self.count = float(state.count)
