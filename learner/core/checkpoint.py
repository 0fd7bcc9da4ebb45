"""Checkpoints: everything ``--resume`` needs to continue a run where it stopped.

A checkpoint holds the policy, the optimiser, the observation normaliser, the shuffling RNG, the
run's counters and its config. Files are written to a temporary name and renamed, so a crash while
saving never leaves a truncated checkpoint behind; tensors and plain values only, so loading
needs no pickle.

An evaluation-only checkpoint (``save_evaluation_only``) leaves out what only resuming reads, the
optimiser's state and the shuffling RNG, about two thirds of the file: the final checkpoint an archived
run keeps for git is one (``learner.experiments.run_archive``). It evaluates and renders as the full
one does; resuming from it stops with ``EvaluationOnlyCheckpointError``.
"""

from __future__ import annotations

import os
import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch

from learner.core.config import TrainConfig

CHECKPOINT_DIR = "checkpoints"
_STEP_FILE = re.compile(r"step_(\d+)\.pt")
RESUME_ONLY_STATE = ("optimizer", "shuffle_rng")
"""The learner state that only resuming reads, which an evaluation-only checkpoint leaves out."""


class EvaluationOnlyCheckpointError(ValueError):
    """Training was asked to resume from an evaluation-only checkpoint, which holds no optimiser state."""


@dataclass
class Counters:
    """Progress of a run; saved so a resumed run logs and anneals from where it stopped."""

    iteration: int = 0
    steps: int = 0
    episodes: int = 0
    offline_episodes: int = 0
    worker_replacements: int = 0
    results_dropped: int = 0
    """Results the workers' teacher clients dropped through outages longer than their buffers."""
    score_only_steps: int = 0
    """Steps of score-only episodes (robust PLR's explorations): played and counted in ``steps``, not trained on."""

    def budget_spent(self, counted: str) -> int:
        """The steps so far that count toward the budget (``charged_steps``)."""
        return charged_steps(self.steps, self.score_only_steps, counted)


def charged_steps(steps: int, score_only_steps: int, counted: str) -> int:
    """Of ``steps`` played, those that count toward the budget: all of them (``played``), or those trained on,
    the score-only ones left out (``trained``)."""
    return steps - score_only_steps if counted == "trained" else steps


@dataclass(frozen=True)
class Checkpoint:
    path: Path
    learner: dict[str, Any]
    counters: Counters
    config: TrainConfig

    @property
    def budget_spent(self) -> int:
        """The steps of the run's budget this checkpoint holds, counted as its trainer counts them."""
        return self.counters.budget_spent(self.config.budget_steps)

    @property
    def evaluation_only(self) -> bool:
        """Whether the optimiser's state and the shuffling RNG were left out (``save_evaluation_only``)."""
        return any(name not in self.learner for name in RESUME_ONLY_STATE)


def checkpoint_path(run_dir: Path, steps: int) -> Path:
    """Where a run's checkpoint at ``steps`` environment steps lies."""
    return Path(run_dir) / CHECKPOINT_DIR / f"step_{steps:010d}.pt"


def checkpoint_steps(path: Path) -> int:
    """The environment steps a checkpoint's file name records (``checkpoint_path``'s inverse)."""
    match = _STEP_FILE.fullmatch(Path(path).name)
    if match is None:
        raise ValueError(f"{path}: not a checkpoint file (step_<steps>.pt)")
    return int(match.group(1))


def _write(data: dict[str, Any], path: Path) -> None:
    partial = path.with_suffix(".pt.partial")
    torch.save(data, partial)
    os.replace(partial, path)


def save_checkpoint(run_dir: Path, learner_state: dict[str, Any], counters: Counters, config: TrainConfig) -> Path:
    path = checkpoint_path(run_dir, counters.steps)
    path.parent.mkdir(parents=True, exist_ok=True)
    _write({"learner": learner_state, "counters": asdict(counters), "config": config.to_dict()}, path)
    return path


def save_evaluation_only(source: Path, target: Path) -> Path:
    """Write checkpoint ``source`` at ``target`` (the same path rewrites it in place) without the state that
    only resuming reads; the policy, the normaliser, the counters and the config are kept as they are."""
    data = torch.load(source, weights_only=True)
    data["learner"] = {name: value for name, value in data["learner"].items() if name not in RESUME_ONLY_STATE}
    _write(data, Path(target))
    return Path(target)


def run_checkpoints(run_dir: Path) -> list[Path]:
    """The checkpoints in ``run_dir``, in step order (names sort by step count)."""
    return sorted((Path(run_dir) / CHECKPOINT_DIR).glob("step_*.pt"))


def latest_checkpoint(run_dir: Path) -> Path | None:
    """The checkpoint with the most steps in ``run_dir``, if any."""
    candidates = run_checkpoints(run_dir)
    return candidates[-1] if candidates else None


def load_checkpoint(path: Path) -> Checkpoint:
    data = torch.load(path, weights_only=True)
    return Checkpoint(
        path=Path(path),
        learner=data["learner"],
        counters=Counters(**data["counters"]),
        config=TrainConfig.from_dict(data["config"]),
    )
