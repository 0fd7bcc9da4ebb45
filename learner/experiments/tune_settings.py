"""What defines a tune: its settings (saved in ``tune.json``) and the names of what it writes, shared by
the command (``tune``) and its reports (``tune_report``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from learner.commands.config_file import ConfigFile
from learner.core.config import TrainConfig
from learner.experiments.tune_space import SearchSpace, TeacherParameters, parse_search_space

SETTINGS_FILE = "tune.json"
EXPERIMENT = "tune"
RUNS_DIR = "runs"
SCHEDULERS = ("asha", "none")
METRICS: dict[str, str] = {"success": "eval/success_rate", "return": "eval/return"}
"""The metric a tune ranks by, and the in-run evaluation it comes from (the hardest task)."""
ASHA_REDUCTION = 3
MAX_TRIALS = 1000
"""The most trials one tune may run, grids included: a search space file cannot ask for an unbounded cost."""
DEFAULTS = TrainConfig()


@dataclass(frozen=True)
class TuneSettings:
    """What defines a tune, saved in ``tune.json`` so ``--resume`` carries on with the same."""

    search_space: dict[str, Any]
    env: str = DEFAULTS.env
    teacher: str = DEFAULTS.teacher
    trials: int = 8
    total_steps: int = 200_000
    scheduler: Literal["asha", "none"] = "asha"
    grace_steps: int | None = None
    metric: Literal["success", "return"] = "success"
    max_concurrent: int | None = None
    seed: int = 0
    workers: int = DEFAULTS.workers
    envs_per_worker: int = DEFAULTS.envs_per_worker
    eval_every: int = 1
    eval_episodes: int = 10
    checkpoint_every: int = 1
    ppo: dict[str, Any] = field(default_factory=dict)
    teacher_params: dict[str, Any] = field(default_factory=dict)

    def base_config(self) -> TrainConfig:
        """Every trial's config before its draws; by default a checkpoint each iteration, so a resumed trial
        loses little (long trials may take one every few iterations: each is ~150 kB on disk)."""
        config = TrainConfig(
            teacher=self.teacher,
            env=self.env,
            total_steps=self.total_steps,
            workers=self.workers,
            envs_per_worker=self.envs_per_worker,
            seed=self.seed,
            checkpoint_every=self.checkpoint_every,
            eval_every=self.eval_every,
            eval_episodes=self.eval_episodes,
        )
        return ConfigFile(ppo=self.ppo, teacher_params=self.teacher_params).applied_to(config)

    def space(self, teacher: TeacherParameters) -> SearchSpace:
        """The search space, checked; ``teacher`` is the tuned kind as the teacher service has it."""
        return parse_search_space(self.search_space, teacher)
