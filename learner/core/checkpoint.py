"""Checkpoints: everything ``--resume`` needs to continue a run where it stopped.

A checkpoint holds the policy, the optimiser, the observation normaliser, the shuffling RNG, the
run's counters and its config. Files are written to a temporary name and renamed, so a crash while
saving never leaves a truncated checkpoint behind; tensors and plain values only, so loading
needs no pickle.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch

from learner.core.config import TrainConfig

CHECKPOINT_DIR = "checkpoints"


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


@dataclass(frozen=True)
class Checkpoint:
    path: Path
    learner: dict[str, Any]
    counters: Counters
    config: TrainConfig


def save_checkpoint(run_dir: Path, learner_state: dict[str, Any], counters: Counters, config: TrainConfig) -> Path:
    directory = Path(run_dir) / CHECKPOINT_DIR
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"step_{counters.steps:010d}.pt"
    partial = path.with_suffix(".pt.partial")
    torch.save({"learner": learner_state, "counters": asdict(counters), "config": config.to_dict()}, partial)
    os.replace(partial, path)
    return path


def latest_checkpoint(run_dir: Path) -> Path | None:
    """The checkpoint with the most steps in ``run_dir``, if any (names sort by step count)."""
    candidates = sorted((Path(run_dir) / CHECKPOINT_DIR).glob("step_*.pt"))
    return candidates[-1] if candidates else None


def load_checkpoint(path: Path) -> Checkpoint:
    data = torch.load(path, weights_only=True)
    return Checkpoint(
        path=Path(path),
        learner=data["learner"],
        counters=Counters(**data["counters"]),
        config=TrainConfig.from_dict(data["config"]),
    )
