"""Sampling among a finite set of levels: the level-replay family's algorithms, pure and indexed.

A level is a number in ``[0, n)`` (an all-integer task space numbers its tasks: ``TaskSpace.level_task``).
Each class keeps a few array entries per level, so memory and the work of a draw or an update are
bounded by the level count, which the level kinds cap at ``MAX_LEVELS``. Draws take their uniforms
from the caller (a fixed-width row per draw), so a teacher addresses its randomness by task index as
every kind in this package does. Each class declares its ``state_fields`` for the teacher's snapshot.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from common.client.task_space import MAX_LEVELS
from teacher_service.teachers.state import ARRAY, INT, StateField


def rank_weights(scores: np.ndarray, temperature: float) -> np.ndarray:
    """PLR's rank prioritisation: weight ``(1 / rank) ** (1 / temperature)``, rank 1 the highest
    score, ties ranked in level order (a stable sort, the same on every machine). Not normalised."""
    order = np.argsort(-scores, kind="stable")
    ranks = np.empty(len(scores))
    ranks[order] = np.arange(1, len(scores) + 1)
    weights: np.ndarray = (1.0 / ranks) ** (1.0 / temperature)
    return weights


def pick(weights: np.ndarray, uniform: float) -> int:
    """The index a uniform in [0, 1) lands on, in proportion to ``weights`` (uniform when all are 0)."""
    cumulative = np.cumsum(weights)
    if cumulative[-1] <= 0:
        return min(int(uniform * len(weights)), len(weights) - 1)
    return int(min(np.searchsorted(cumulative, uniform * cumulative[-1], side="right"), len(weights) - 1))


def check_level_count(levels: int) -> None:
    if not 1 <= levels <= MAX_LEVELS:
        raise ValueError(f"a level sampler takes 1 to {MAX_LEVELS:,} levels, got {levels:,}")


class LevelReplay:
    """Prioritized Level Replay's sampler (Jiang, Grefenstette and Rocktäschel 2021).

    Each draw either replays a level already scored or explores one not scored yet. Once a
    ``min_seen_share`` of the levels has a score, a draw replays with probability
    ``min(seen share, replay_prob)`` (the authors' ``proportionate`` schedule) or ``replay_prob``
    (``fixed``). Once every level has one, a draw replays with ``replay_prob`` and otherwise picks a
    level uniformly among all: at ``replay_prob`` 1 every draw replays then, as in the authors' code and
    Syllabus's ``TaskSampler`` (which sends its non-replay draws to an evaluator, not to training); below
    1 it is our hybrid. With ``replay_when_all_scored`` it always replays then (robust PLR, whose uniform
    draws would be scoring only). A replay picks among the scored levels from the mixture
    ``(1 - staleness_coef) * P_S + staleness_coef * P_C``: ``P_S`` by rank of score with
    ``temperature``, ``P_C`` in proportion to the draws since the level was last drawn (staleness).
    An exploring draw picks uniformly among the levels without a score (among all once each has one).
    A new score replaces the old (the authors' default ``alpha`` of 1).
    """

    UNIFORMS_PER_DRAW = 3
    """Replay or explore, which half of the mixture, and which level."""
    state_fields: ClassVar[tuple[StateField, ...]] = (
        StateField("scores", ARRAY),
        StateField("seen", ARRAY),
        StateField("last_drawn", ARRAY),
        StateField("draws", INT),
    )

    def __init__(
        self,
        levels: int,
        temperature: float,
        staleness_coef: float,
        replay_prob: float,
        min_seen_share: float,
        schedule: str = "proportionate",
        replay_when_all_scored: bool = False,
    ) -> None:
        check_level_count(levels)
        if schedule not in ("proportionate", "fixed"):
            raise ValueError(f"schedule must be proportionate or fixed, got {schedule!r}")
        self.temperature = temperature
        self.staleness_coef = staleness_coef
        self.replay_prob = replay_prob
        self.min_seen_share = min_seen_share
        self.schedule = schedule
        self.replay_when_all_scored = replay_when_all_scored
        self.scores = np.zeros(levels)
        self.seen = np.zeros(levels, dtype=bool)
        self.last_drawn = np.zeros(levels, dtype=np.int64)
        """The draw count just after each level was last drawn (0 before its first draw)."""
        self.draws = 0
        self._score_weights: np.ndarray | None = None

    @property
    def levels(self) -> int:
        return len(self.scores)

    def draw(self, uniforms: np.ndarray) -> tuple[int, bool]:
        """The next level and whether it is a replay (else it explores: a level without a score, or any
        level once each has one)."""
        replay = self._replays(float(uniforms[0]))
        if replay:
            seen = np.flatnonzero(self.seen)
            if float(uniforms[1]) < self.staleness_coef:
                level = int(seen[pick(self._staleness(seen), float(uniforms[2]))])
            else:
                level = int(seen[pick(self._replay_score_weights(), float(uniforms[2]))])
        else:
            unseen = np.flatnonzero(~self.seen)
            candidates = unseen if len(unseen) else np.arange(self.levels)
            level = int(candidates[min(int(float(uniforms[2]) * len(candidates)), len(candidates) - 1)])
        self.draws += 1
        self.last_drawn[level] = self.draws
        return level, replay

    def _staleness(self, levels: np.ndarray) -> np.ndarray:
        """Draws since each of ``levels`` was last drawn (0 for the one just drawn)."""
        staleness: np.ndarray = (self.draws - self.last_drawn[levels]).astype(float)
        return staleness

    def replay_chance(self) -> float:
        """The chance that the next draw replays a scored level rather than exploring."""
        seen_share = float(self.seen.mean())
        if seen_share == 1.0:
            return 1.0 if self.replay_when_all_scored else self.replay_prob
        if seen_share == 0.0 or seen_share < self.min_seen_share:
            return 0.0
        return self.replay_prob if self.schedule == "fixed" else min(seen_share, self.replay_prob)

    def _replays(self, uniform: float) -> bool:
        return uniform < self.replay_chance()

    def _replay_score_weights(self) -> np.ndarray:
        """``P_S`` over the scored levels (in level order), cached until a score changes."""
        if self._score_weights is None:
            self._score_weights = rank_weights(self.scores[self.seen], self.temperature)
        return self._score_weights

    def record(self, level: int, score: float) -> None:
        """A finished episode's score for ``level``: it is now a replay candidate with this score."""
        self.scores[level] = score
        self.seen[level] = True
        self._score_weights = None

    def probabilities(self) -> np.ndarray:
        """Each level's chance of being the next draw, replay or exploration."""
        replay = self.replay_chance()
        unseen = ~self.seen
        result = self.replay_probabilities() * replay
        explored = unseen if unseen.any() else np.ones(self.levels, dtype=bool)
        result[explored] += (1.0 - replay) / explored.sum()
        return result

    def replay_probabilities(self) -> np.ndarray:
        """Each level's chance of being the next replay (zeros before any level has a score)."""
        result = np.zeros(self.levels)
        seen = np.flatnonzero(self.seen)
        if not len(seen):
            return result
        by_score = self._replay_score_weights()
        staleness = self._staleness(seen)
        result[seen] = (1 - self.staleness_coef) * by_score / by_score.sum()
        stale_total = staleness.sum()
        result[seen] += self.staleness_coef * (staleness / stale_total if stale_total else 1 / len(seen))
        return result

    def loaded(self) -> None:
        """Forget cached weights once the arrays were loaded from a snapshot."""
        self._score_weights = None


class LearningProgress:
    """Learning progress over levels (Kanitscheider et al. 2021), as Syllabus's online variant
    computes it: per level a fast and a slow moving average of the success rate, and a level's
    progress the gap between them after the reweighting that stretches rates near 0 and 1.

    Outcomes gather between updates. The first update measures the untrained student: each level's
    success rate then, capped at 0.75 so that no level is written off, is its baseline, and both
    averages start at the rate above it, ``max(rate - baseline, 0) / (1 - baseline)``: 0, except on a
    level already passed more often than the cap. Each later update folds each played level's rate
    above its baseline into its averages, so a level's first successes open a gap between them at
    once. Only the levels played since the last update move (Syllabus folds a rate of 0 into every
    level not played, which drags their averages down). Sampling: the levels
    with progress (or a success seen) get z-scored progress through a sigmoid, the rest nothing; that
    distribution is mixed with a ``uniform_share`` of uniform draws over all levels.
    """

    UNIFORMS_PER_DRAW = 1
    BASELINE_CAP = 0.75
    """The highest baseline a level gets, as Syllabus caps it: a level the untrained student already
    passes still has room to show progress."""
    state_fields: ClassVar[tuple[StateField, ...]] = (
        StateField("fast", ARRAY),
        StateField("slow", ARRAY),
        StateField("true_rate", ARRAY),
        StateField("baseline", ARRAY),
        StateField("updates", INT),
        StateField("successes", ARRAY),
        StateField("episodes", ARRAY),
    )

    def __init__(self, levels: int, ema_rate: float, reweight_theta: float, uniform_share: float) -> None:
        check_level_count(levels)
        self.ema_rate = ema_rate
        self.reweight_theta = reweight_theta
        self.uniform_share = uniform_share
        self.fast = np.zeros(levels)
        self.slow = np.zeros(levels)
        self.true_rate = np.zeros(levels)
        """Each level's success rate, averaged the same way but neither normalised nor reweighted: a
        level with any success seen stays among those sampled by progress."""
        self.baseline = np.zeros(levels)
        self.updates = 0
        self.successes = np.zeros(levels)
        self.episodes = np.zeros(levels, dtype=np.int64)
        self._distribution: np.ndarray | None = None

    @property
    def levels(self) -> int:
        return len(self.fast)

    def record(self, level: int, success: float) -> None:
        """One episode's outcome (1 or 0, or a share in [0, 1]) on ``level``, held until ``update``."""
        self.successes[level] += success
        self.episodes[level] += 1

    def update(self) -> None:
        """Fold the success rates since the last update into the moving averages (the first update
        sets the baselines and starts the averages)."""
        played = self.episodes > 0
        rate = np.zeros(self.levels)
        rate[played] = self.successes[played] / self.episodes[played]
        if self.updates == 0:
            self.baseline = np.minimum(rate, self.BASELINE_CAP)
        above = np.maximum(rate - self.baseline, 0.0) / (1.0 - self.baseline)
        if self.updates == 0:
            self.fast, self.slow, self.true_rate = above.copy(), above.copy(), rate
        else:
            alpha = self.ema_rate
            self.fast[played] = alpha * above[played] + (1 - alpha) * self.fast[played]
            # As Syllabus does: the slow average moves toward the new fast one, not toward the rate itself.
            self.slow[played] = alpha * self.fast[played] + (1 - alpha) * self.slow[played]
            self.true_rate[played] = alpha * rate[played] + (1 - alpha) * self.true_rate[played]
        self.updates += 1
        self.successes[:] = 0.0
        self.episodes[:] = 0
        self._distribution = None

    def _reweight(self, rate: np.ndarray) -> np.ndarray:
        theta = self.reweight_theta
        stretched: np.ndarray = rate * (1 - theta) / (rate + theta * (1 - 2 * rate))
        return stretched

    def progress(self) -> np.ndarray:
        """Each level's learning progress: |reweighted fast - reweighted slow|."""
        gap: np.ndarray = np.abs(self._reweight(self.fast) - self._reweight(self.slow))
        return gap

    def probabilities(self) -> np.ndarray:
        """The sampling distribution over levels, cached until the next update."""
        if self._distribution is None:
            progress = self.progress()
            active = (progress > 0) | (self.true_rate > 0)
            chosen = progress[active] if active.any() else progress
            spread = chosen.std()
            logits = (chosen - chosen.mean()) / (spread if spread else 1.0)
            weights = 1.0 / (1.0 + np.exp(-logits))
            weights /= weights.sum()
            distribution = np.zeros(self.levels)
            if active.any():
                distribution[active] = weights
            else:
                distribution = weights
            self._distribution = (1 - self.uniform_share) * distribution + self.uniform_share / self.levels
        return self._distribution

    def draw(self, uniforms: np.ndarray) -> int:
        return pick(self.probabilities(), float(uniforms[0]))

    def loaded(self) -> None:
        self._distribution = None
