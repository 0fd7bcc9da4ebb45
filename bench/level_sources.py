"""Task sources that stand in for the teacher service in the level side-by-side
(``bench/levels_side_by_side.py``): no curriculum at all, and Syllabus 0.7's curricula, each played by the
same workers and learner as the service's level kinds.

Syllabus's own Ray path cannot carry them as released: its environment wrapper
(``RayGymnasiumSyncWrapper``) sends ``update`` calls that its curriculum actor (``RayCurriculumWrapper``)
does not define, and ``DirectPrioritizedLevelReplay.update`` calls a ``TaskSampler`` method that 0.7 lacks.
So a Ray actor of ours holds Syllabus's curriculum object and feeds it through its public update methods,
the ones Syllabus's synchronous wrappers call at an episode's end; the workers draw from it in blocks and
report in blocks, as our teacher client does with the service.

Two more things are Syllabus's as released, and are worked around here in the open:

- ``TaskSampler.sample`` takes robust PLR's path whenever the share of levels seen reaches ``rho``: it sends
  every exploring draw to an evaluator, and errors without one. Plain PLR is its replay decision
  (``sample_replay_decision``) followed by a replay draw (``_sample_replay_level``) or an exploring one
  (``_sample_unseen_level`` while some level is unseen, else ``_sample_random_level``), as in the
  authors' code; ``_plr_draw`` calls exactly those, in that order.
- ``Curriculum.sample`` compares its distribution with ``[]``, which numpy 2 refuses for an array, the type
  ``OnlineLearningProgress`` returns; the actor draws from that same distribution with the same call
  (``np.random.choice`` over the task indices).
- Syllabus draws from numpy's global generator, so the actor seeds it once.
"""

from __future__ import annotations

import itertools
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import ray

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: the checkout's packages
from common.client.teacher_client import Assignment  # noqa: E402
from common.policy.trajectory import EpisodeStats  # noqa: E402
from rollout_worker.sampler import TaskSource  # noqa: E402

SYLLABUS_KINDS = ("syllabus-plr", "syllabus-learning-progress")
"""The Syllabus curricula the side-by-side runs (its Learnability needs an evaluator that plays every
training level with the current policy, which these workers do not offer)."""

BLOCK = 16
"""Tasks a worker draws, and results it sends, per call to the Syllabus actor (the teacher client's
``prefetch`` is twice a worker's environments: 16 at 8)."""


@dataclass(frozen=True)
class UniformLevels:
    """No curriculum: each worker draws its levels uniformly from the training set, with no service."""

    levels: int

    def __call__(self, seed: int) -> TaskSource:
        return _UniformLevelSource(self.levels, seed)


class _UniformLevelSource:
    def __init__(self, levels: int, seed: int) -> None:
        self.levels = levels
        self.rng = np.random.default_rng(seed)
        self.ids = (f"{seed}-{index}" for index in itertools.count())

    def next_task(self) -> Assignment:
        return Assignment(next(self.ids), {"level": int(self.rng.integers(self.levels))})

    def report(self, episode: EpisodeStats) -> None:
        pass


@ray.remote(num_cpus=0)
class SyllabusCurriculum:
    """One of Syllabus's curricula over the levels 0 to ``levels`` - 1, shared by a run's workers."""

    def __init__(self, kind: str, levels: int, seed: int, learning_progress_interval: int = 100) -> None:
        from syllabus.curricula import OnlineLearningProgress
        from syllabus.curricula.plr.task_sampler import TaskSampler
        from syllabus.task_space import DiscreteTaskSpace

        np.random.seed(seed)  # Syllabus samples from numpy's global generator
        self.kind = kind
        if kind == "syllabus-plr":
            # Syllabus's defaults (rank, temperature 0.1, staleness 0.1, proportionate replay at 0.5 once every
            # level is seen); the score is what the workers send (--ppo level_score), not Syllabus's value_l1 unless
            # level_score=value_l1.
            self.sampler = TaskSampler(list(range(levels)), 1, task_space=DiscreteTaskSpace(levels))
        elif kind == "syllabus-learning-progress":
            self.curriculum = OnlineLearningProgress(
                DiscreteTaskSpace(levels), update_interval=learning_progress_interval
            )
        else:
            raise ValueError(f"unknown Syllabus kind {kind!r}; expected one of {', '.join(SYLLABUS_KINDS)}")

    def sample(self, count: int) -> list[int]:
        if self.kind == "syllabus-plr":
            return [self._plr_draw() for _ in range(count)]
        curriculum = self.curriculum
        levels = np.random.choice(curriculum.num_tasks, size=count, p=curriculum._sample_distribution())
        return [int(level) for level in levels]

    def _plr_draw(self) -> int:
        sampler = self.sampler
        sampler.running_sample_count += 1
        if sampler.sample_replay_decision():
            return int(sampler._sample_replay_level())
        if sampler._proportion_filled < 1.0:
            return int(sampler._sample_unseen_level())
        return int(sampler._sample_random_level())

    def report(self, episodes: Sequence[tuple[int, float, int, bool, float | None]]) -> None:
        """Each finished episode as (level, return, length, success, score)."""
        for level, episode_return, length, success, score in episodes:
            if self.kind == "syllabus-plr":
                value = float(score) if score is not None else 0.0
                self.sampler.update_task_score(0, level, value, value, 1)
            else:
                self.curriculum.update_task_progress(level, success)
                self.curriculum.update_on_episode(episode_return, length, level, success)

    def distribution(self) -> list[float]:
        """The probability of each level at the next draw (for the results' diagnostics)."""
        if self.kind == "syllabus-plr":
            return [float(p) for p in self.sampler.sample_weights()]
        return [float(p) for p in self.curriculum._sample_distribution()]


@dataclass(frozen=True)
class SyllabusLevels:
    """Tasks from the named ``SyllabusCurriculum`` actor, drawn and reported in blocks of ``BLOCK``."""

    actor_name: str

    def __call__(self, seed: int) -> TaskSource:
        return _SyllabusSource(ray.get_actor(self.actor_name), seed)


class _SyllabusSource:
    def __init__(self, actor: Any, seed: int) -> None:
        self.actor = actor
        self.ids = (f"{seed}-{index}" for index in itertools.count())
        self.queued: list[int] = []
        self.unsent: list[tuple[int, float, int, bool, float | None]] = []

    def next_task(self) -> Assignment:
        if not self.queued:
            self.queued = ray.get(self.actor.sample.remote(BLOCK))
        return Assignment(next(self.ids), {"level": self.queued.pop(0)})

    def report(self, episode: EpisodeStats) -> None:
        level = int(episode.task["level"])
        self.unsent.append((level, episode.reward, episode.length, episode.success, episode.score))
        if len(self.unsent) >= BLOCK:
            self.actor.report.remote(self.unsent)  # fire and forget, as Syllabus's wrappers send updates
            self.unsent = []
