"""The validated policy: of a run's late checkpoints, the one that does best on validation episodes.

A run's last checkpoint is not always its best: on the hard family a student can lose late what it had, after
its teacher has reached the target (docs/results/student.md, lever 5). Choosing among checkpoints on episodes
that no other evaluation plays is model selection, as Stable-Baselines3's ``EvalCallback`` keeps its best model;
the episodes that then score the chosen policy stay untouched by the choice.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from learner.core.checkpoint import checkpoint_steps, run_checkpoints

VALIDATION_SEED = 200_000
"""Where the validation episodes' seeds start: above the in-run evaluations' (10,000 to 99,999) and the final
evaluations' (a screen's from 20,000, a bake-off's from 100,000), so no episode that scores a policy chose it."""
FIRST_STEP = 3_000_000
"""The earliest candidate: before it, on the hard family, CURROT is still moving the tasks."""
EVERY = 500_000
"""Steps between candidates."""
VALIDATION_EPISODES = 200


@dataclass(frozen=True)
class Validated:
    """A candidate checkpoint and its success on the validation episodes."""

    path: Path
    steps: int
    success: float


def candidate_checkpoints(run_dir: Path, first_step: int = FIRST_STEP, every: int = EVERY) -> list[Path]:
    """For each of ``first_step``, ``first_step + every``, ... below the run's last checkpoint, its first
    checkpoint at or after that step, and its last checkpoint; in step order, each once."""
    if first_step < 0 or every < 1:
        raise ValueError(f"first_step must be at least 0 and every at least 1, got {first_step} and {every}")
    found = [(checkpoint_steps(path), path) for path in run_checkpoints(run_dir)]
    if not found:
        raise ValueError(f"{run_dir}: no checkpoints")
    last_steps, last = found[-1]
    candidates: list[Path] = []
    for mark in range(first_step, last_steps, every):
        first = next(path for steps, path in found if steps >= mark)
        if first not in candidates:
            candidates.append(first)
    if last not in candidates:
        candidates.append(last)
    return candidates


def choose(validated: Sequence[Validated]) -> Validated:
    """The candidate with the highest validation success; of equals, the later one (it trained longer on the
    same tasks, and a run without a better earlier checkpoint keeps its final policy)."""
    if not validated:
        raise ValueError("no candidates to choose from")
    return max(validated, key=lambda candidate: (candidate.success, candidate.steps))
