"""Task sources that stand in for the teacher service in the level side-by-side
(``bench/levels_side_by_side.py``): no curriculum at all, and Syllabus 0.7's curricula with the settings of
its own procgen example (``syllabus/examples/training_scripts/cleanrl_procgen.py`` at the 0.7 tag), each
played by the same workers and learner as the service's level kinds.

Syllabus's own Ray path cannot carry them as released (its environment wrapper sends ``update`` calls its
curriculum actor does not define), so a Ray actor of ours holds Syllabus's curriculum object and feeds it
through the public methods Syllabus's synchronous wrappers call at an episode's end; the workers draw from it
and report to it in blocks of ``BLOCK``, as our teacher client does with the service. Syllabus draws from
numpy's global generator, which the actor seeds once. What each kind runs, and where it departs:

- ``syllabus-plr``: the example's ``--curriculum-method plr``, a ``TaskSampler`` with ``strategy="value_l1"``
  and ``replay_schedule="fixed"``, every other setting its default (rank transform, temperature 0.1,
  staleness 0.1, rho 1.0). Draws are its own unmodified ``TaskSampler.sample()``, the call
  ``PrioritizedLevelReplay.sample`` makes: the fixed schedule sweeps every level once and then replays every
  draw, so the evaluator that its robust path needs is never asked for. Each episode's score is the
  workers' ``value_l1`` (the run sets ``--ppo level_score=value_l1``) over the whole episode, given to
  ``update_task_score`` at its end; Syllabus's ``PrioritizedLevelReplay`` computes the same mean |GAE| from
  its own rollout buffer, in chunks of its rollout length.
- ``syllabus-learning-progress``: the example's ``online_lp``, ``OnlineLearningProgress`` with
  ``update_interval_steps`` of 25 batches, ``ema_alpha`` 0.1, ``p_theta`` 0.1 and ``normalize_success``
  False (the example's flag default). It is first asked for a distribution after its first update: until
  then the actor draws uniformly (Syllabus's multiprocessing wrapper asks at every environment's first reset,
  before any episode has ended, which sets both averages to 0 one interval early).
- ``syllabus-learnability``: the example's ``learnability_top10``, ``Learnability`` with ``sampling="topk"``,
  ``topk`` 10, ``learnable_prob`` 0.5, ``eval_interval_steps`` of 25 batches, ``eval_eps`` 20 per training
  level (the example's 20 x 200 over procgen's 200), ``continuous_progress`` True and ``normalize_success``
  False. Its evaluator (``WorkerEvaluator``) plays its episodes on the training workers, score-only, the
  levels in turn as the example's looping ``SequentialCurriculum`` hands them out: while an evaluation runs,
  every draw is one of its episodes, so training waits as it does in the example, and its steps count in
  the run's budget. Episodes of an evaluation still in flight when it has its count are played and dropped
  (Syllabus's evaluator drops its unfinished ones too). Syllabus calls the evaluator synchronously, from its
  own update or its first distribution; the actor makes those calls on a thread of its own (``_Suspendable``)
  that waits there until the workers have played the episodes.
"""

from __future__ import annotations

import functools
import itertools
import queue
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import ray

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: the checkout's packages
from common.client.teacher_client import Assignment  # noqa: E402
from common.policy.trajectory import EpisodeStats  # noqa: E402
from rollout_worker.sampler import TaskSource  # noqa: E402

SYLLABUS_KINDS = ("syllabus-plr", "syllabus-learning-progress", "syllabus-learnability")

BLOCK = 16
"""Tasks a worker draws, and results it sends, per call to the Syllabus actor (the teacher client's
``prefetch`` is twice a worker's environments: 16 at 8)."""

PLR_EXAMPLE = {"strategy": "value_l1", "replay_schedule": "fixed"}
"""The ``task_sampler_kwargs_dict`` of the example's ``plr`` method; every other ``TaskSampler`` setting is its
default."""
EXAMPLE_INTERVAL_BATCHES = 25
"""The example updates learning progress, and evaluates for learnability, every 25 batches of training steps."""
LEARNING_PROGRESS_EXAMPLE = {"ema_alpha": 0.1, "p_theta": 0.1, "normalize_success": False}
LEARNABILITY_EXAMPLE = {
    "sampling": "topk",
    "topk": 10,
    "learnable_prob": 0.5,
    "continuous_progress": True,
    "normalize_success": False,
}
EVALUATION_EPISODES_PER_LEVEL = 20
"""The example's ``eval_eps`` is 20 x 200, twenty episodes for each of procgen's 200 training levels."""

Result = tuple[int, float, int, bool, float | None, int]
"""One finished episode as the workers report it: (level, return, length, success, score, evaluation), where
evaluation is 0 for a training episode and k for an episode of the curriculum's k-th evaluation."""


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


class _Plr:
    """Syllabus's PLR as its example sets it up."""

    def __init__(self, levels: int) -> None:
        from syllabus.curricula.plr.task_sampler import TaskSampler
        from syllabus.task_space import DiscreteTaskSpace

        self.sampler = TaskSampler(list(range(levels)), 1, task_space=DiscreteTaskSpace(levels), **PLR_EXAMPLE)

    def sample(self, count: int) -> list[tuple[int, int]]:
        return [(int(self.sampler.sample()), 0) for _ in range(count)]

    def report(self, results: Sequence[Result]) -> None:
        for level, _, length, _, score, _ in results:
            if score is None:
                raise ValueError("Syllabus's PLR needs each episode's score: the workers sent none")
            self.sampler.update_task_score(0, level, float(score), float(score), int(length))

    def distribution(self) -> list[float]:
        return [float(p) for p in self.sampler.sample_weights()]

    def status(self) -> dict[str, Any]:
        return {"seen_share": float(self.sampler._proportion_filled)}


class _LearningProgress:
    """Syllabus's online learning progress as its example sets it up, first asked after its first update."""

    def __init__(self, levels: int, interval_steps: int) -> None:
        from syllabus.curricula import OnlineLearningProgress
        from syllabus.task_space import DiscreteTaskSpace

        self.levels = levels
        self.curriculum = OnlineLearningProgress(
            DiscreteTaskSpace(levels), update_interval_steps=interval_steps, **LEARNING_PROGRESS_EXAMPLE
        )
        self.uniform_draws = 0

    @property
    def updated(self) -> bool:
        return self.curriculum.task_rates is not None

    def sample(self, count: int) -> list[tuple[int, int]]:
        if not self.updated:
            self.uniform_draws += count
            return [(int(level), 0) for level in np.random.randint(self.levels, size=count)]
        # Curriculum.sample's own draw; it compares the distribution with [], which numpy 2 refuses for the
        # array OnlineLearningProgress returns.
        levels = np.random.choice(self.levels, size=count, p=self.curriculum._sample_distribution())
        return [(int(level), 0) for level in levels]

    def report(self, results: Sequence[Result]) -> None:
        for level, episode_return, length, success, _, _ in results:
            self.curriculum.update_task_progress(level, success)
            self.curriculum.update_on_episode(episode_return, length, level, success)

    def distribution(self) -> list[float]:
        if not self.updated:
            return [1.0 / self.levels] * self.levels
        return [float(p) for p in self.curriculum._sample_distribution()]

    def status(self) -> dict[str, Any]:
        return {"updated": self.updated, "uniform_draws_before_first_update": self.uniform_draws}


class _Suspendable:
    """Runs calls into a Syllabus curriculum one at a time on a thread of its own. ``run`` returns once the
    call has finished, or once it is waiting inside ``WorkerEvaluator.evaluate_agent`` for episodes that only
    the actor's later calls can gather; ``resume`` hands it their rates and returns as ``run`` does."""

    def __init__(self) -> None:
        self._calls: queue.Queue[Callable[[], None]] = queue.Queue()
        self._settled = threading.Event()
        self._answered = threading.Event()
        self._rates: np.ndarray | None = None
        self._error: BaseException | None = None
        self.waiting_for: int | None = None
        """Episodes the suspended call's evaluation asks for; None while no call waits."""
        threading.Thread(target=self._serve, name="syllabus-calls", daemon=True).start()

    def _serve(self) -> None:
        while True:
            call = self._calls.get()
            try:
                call()
            except BaseException as error:  # handed to the actor's thread, which raises it
                self._error = error
            self._settled.set()

    def _settle(self) -> None:
        self._settled.wait()
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def run(self, call: Callable[[], None]) -> None:
        if self.waiting_for is not None:
            raise RuntimeError("a call is waiting for its evaluation; resume it first")
        self._settled.clear()
        self._calls.put(call)
        self._settle()

    def resume(self, rates: np.ndarray) -> None:
        self._settled.clear()
        self._rates, self.waiting_for = rates, None
        self._answered.set()
        self._settle()

    def evaluate(self, episodes: int) -> np.ndarray:
        """On the curriculum's thread: wait for ``episodes`` evaluation episodes and return their rates."""
        self._answered.clear()
        self.waiting_for = episodes
        self._settled.set()  # the call is suspended here: the actor goes on
        self._answered.wait()
        assert self._rates is not None
        rates, self._rates = self._rates, None
        return rates


class WorkerEvaluator:
    """Syllabus's ``Evaluator`` interface as ``Learnability`` uses it (``evaluate_agent``), answered with episodes
    the training workers play for it."""

    def __init__(self, calls: _Suspendable) -> None:
        self.calls = calls

    def evaluate_agent(self, num_episodes: int = 100, verbose: bool = False) -> tuple[list[float], Any, Any, dict]:
        rates = self.calls.evaluate(int(num_episodes))
        # (returns, success rates, success rates at episodes' ends, step data): with continuous_progress, as the
        # example sets it, Learnability reads the third; a level's success is 0 or 1 at its episode's end.
        return [], rates, rates, {}


class _Learnability:
    """Syllabus's Learnability top-10 as its example sets it up, its evaluator played by the workers."""

    def __init__(self, levels: int, interval_steps: int, evaluation_episodes: int) -> None:
        from syllabus.curricula import Learnability
        from syllabus.task_space import DiscreteTaskSpace

        self.levels = levels
        self.calls = _Suspendable()
        self.curriculum = Learnability(
            WorkerEvaluator(self.calls),
            DiscreteTaskSpace(levels),
            eval_interval_steps=interval_steps,
            eval_eps=evaluation_episodes,
            **LEARNABILITY_EXAMPLE,
        )
        self.drawn: list[int] = []
        """Training draws made and not yet handed out (a draw that waited for an evaluation lands here)."""
        self.deferred: list[Result] = []
        """Training results that came in during an evaluation, fed to Syllabus once it is over."""
        self.evaluations = 0
        self.next_in_turn = 0
        """The evaluator's place in its round of the levels, kept from one evaluation to the next."""
        self.successes = np.zeros(levels)
        self.episodes = np.zeros(levels)
        self.evaluation_episodes = 0
        self.dropped = 0

    @property
    def evaluating(self) -> bool:
        return self.calls.waiting_for is not None

    def _run(self, call: Callable[[], None]) -> None:
        self.calls.run(call)
        self._begin_if_asked()

    def _begin_if_asked(self) -> None:
        if self.evaluating:
            self.evaluations += 1
            self.successes[:] = 0.0
            self.episodes[:] = 0.0

    def _draw(self, count: int) -> None:
        # Curriculum.sample's own draw (its comparison with [] fails on numpy 2): the distribution asks for the
        # first evaluation when there is none yet.
        levels = np.random.choice(self.levels, size=count, p=self.curriculum._sample_distribution())
        self.drawn.extend(int(level) for level in levels)

    def sample(self, count: int) -> list[tuple[int, int]]:
        tasks: list[tuple[int, int]] = []
        while len(tasks) < count:
            if self.evaluating:
                tasks.append((self.next_in_turn, self.evaluations))
                self.next_in_turn = (self.next_in_turn + 1) % self.levels
            elif self.drawn:
                tasks.append((self.drawn.pop(0), 0))
            else:
                self._run(functools.partial(self._draw, count - len(tasks)))
        return tasks

    def report(self, results: Sequence[Result]) -> None:
        for result in results:
            level, episode_return, length, success, _, evaluation = result
            if evaluation == 0 and self.evaluating:
                self.deferred.append(result)
            elif evaluation == 0:
                self._run(functools.partial(self._update, level, episode_return, length, success))
            elif self.evaluating and evaluation == self.evaluations:
                self.successes[level] += float(success)
                self.episodes[level] += 1.0
                self.evaluation_episodes += 1
                if self.episodes.sum() >= (self.calls.waiting_for or 0):
                    self._finish_evaluation()
            else:
                self.dropped += 1

    def _update(self, level: int, episode_return: float, length: int, success: bool) -> None:
        self.curriculum.update_task_progress(level, success)
        self.curriculum.update_on_episode(episode_return, length, level, success)

    def _finish_evaluation(self) -> None:
        # As Syllabus's evaluator: successes over episodes, a level it did not play counted over one episode.
        self.calls.resume(self.successes / np.maximum(self.episodes, 1.0))
        self._begin_if_asked()
        while self.deferred and not self.evaluating:
            level, episode_return, length, success, _, _ = self.deferred.pop(0)
            self._run(functools.partial(self._update, level, episode_return, length, success))

    def distribution(self) -> list[float]:
        if self.curriculum.task_rates is None or self.evaluating:
            return [1.0 / self.levels] * self.levels
        return [float(p) for p in self.curriculum._sample_distribution()]

    def status(self) -> dict[str, Any]:
        return {
            "evaluations": self.evaluations,
            "evaluating": self.evaluating,
            "evaluation_episodes": self.evaluation_episodes,
            "evaluation_episodes_dropped": self.dropped,
        }


@ray.remote(num_cpus=0)
class SyllabusCurriculum:
    """One of Syllabus's curricula over the levels 0 to ``levels`` - 1, shared by a run's workers.
    ``batch_size`` is the run's (workers x environments x rollout length), which the example's intervals count
    in; ``evaluation_episodes`` replaces Learnability's 20 per level."""

    def __init__(
        self, kind: str, levels: int, seed: int, batch_size: int, evaluation_episodes: int | None = None
    ) -> None:
        np.random.seed(seed)  # Syllabus samples from numpy's global generator
        interval = EXAMPLE_INTERVAL_BATCHES * batch_size
        self.curriculum: _Plr | _LearningProgress | _Learnability
        if kind == "syllabus-plr":
            self.curriculum = _Plr(levels)
        elif kind == "syllabus-learning-progress":
            self.curriculum = _LearningProgress(levels, interval)
        elif kind == "syllabus-learnability":
            episodes = evaluation_episodes or EVALUATION_EPISODES_PER_LEVEL * levels
            self.curriculum = _Learnability(levels, interval, episodes)
        else:
            raise ValueError(f"unknown Syllabus kind {kind!r}; expected one of {', '.join(SYLLABUS_KINDS)}")

    def sample(self, count: int) -> list[tuple[int, int]]:
        """``count`` tasks as (level, evaluation): evaluation 0 is a training draw, k one of the k-th evaluation's
        episodes (score-only)."""
        return self.curriculum.sample(count)

    def report(self, results: Sequence[Result]) -> None:
        self.curriculum.report(results)

    def distribution(self) -> list[float]:
        """The probability of each level at the next training draw (for the results' diagnostics)."""
        return self.curriculum.distribution()

    def status(self) -> dict[str, Any]:
        """Where the curriculum stands: PLR's share of levels seen, learning progress's first update, or
        learnability's evaluations."""
        return self.curriculum.status()


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
        self.queued: list[tuple[int, int]] = []
        self.evaluation_of: dict[str, int] = {}
        self.unsent: list[Result] = []

    def next_task(self) -> Assignment:
        if not self.queued:
            drawn = ray.get(self.actor.sample.remote(BLOCK))
            self.queued = [(int(level), int(evaluation)) for level, evaluation in drawn]
        level, evaluation = self.queued.pop(0)
        task_id = next(self.ids)
        self.evaluation_of[task_id] = evaluation
        return Assignment(task_id, {"level": level}, score_only=evaluation > 0)

    def report(self, episode: EpisodeStats) -> None:
        level = int(episode.task["level"])
        evaluation = self.evaluation_of.pop(episode.task_id or "", 0)
        self.unsent.append((level, episode.reward, episode.length, episode.success, episode.score, evaluation))
        if len(self.unsent) >= BLOCK:
            self.actor.report.remote(self.unsent)  # fire and forget, as Syllabus's wrappers send updates
            self.unsent = []
