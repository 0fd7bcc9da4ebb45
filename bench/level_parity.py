"""Our level samplers beside Syllabus 0.7's, fed the same scores and outcomes: how far apart their
sampling distributions are (total variation, 0 identical, 1 disjoint), where our docstrings say they
agree and where they name a departure.

- PLR: Syllabus's ``TaskSampler`` (rank transform, staleness mix) against ``LevelReplay``'s replay
  distribution, both given the same scores, unseen levels and staleness.
- Learning progress: Syllabus's ``OnlineLearningProgress`` (its defaults: success normalised by the
  first interval's baseline) against ``LearningProgress``, fed the same episodes with the same update
  interval, once with every level played in each interval (where they should agree) and once with a
  random half (where Syllabus folds a rate of 0 into the levels not played and we leave them be).
- Learnability: Syllabus's ``Learnability`` with its defaults (top 1,000 levels by p(1 - p)) over the
  side-by-side's 500 levels, given success rates from a stand-in evaluator, against uniform sampling:
  with no more levels than its top-k it draws every level alike, whatever the rates.

    .venv/bin/python bench/level_parity.py [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from teacher_service.teachers.algorithms.levels import LearningProgress, LevelReplay  # noqa: E402

LEVELS = 50


def total_variation(first: np.ndarray, second: np.ndarray) -> float:
    return float(np.abs(first / first.sum() - second / second.sum()).sum() / 2)


def plr_case(
    rng: np.random.Generator, scores: np.ndarray, seen: np.ndarray, temperature: float, staleness_coef: float
) -> float:
    from syllabus.curricula.plr.task_sampler import TaskSampler
    from syllabus.task_space import DiscreteTaskSpace

    theirs = TaskSampler(
        list(range(LEVELS)), 1, action_space=gym.spaces.Discrete(3), task_space=DiscreteTaskSpace(LEVELS),
        strategy="value_l1", temperature=temperature, staleness_coef=staleness_coef,
    )  # fmt: skip
    ours = LevelReplay(LEVELS, temperature, staleness_coef, replay_prob=1.0, min_seen_share=0.0)
    staleness = rng.integers(0, 40, size=LEVELS)
    ours.draws = 100
    ours.last_drawn[:] = ours.draws - staleness
    theirs.task_staleness = staleness.astype(float)
    for level in np.flatnonzero(seen):
        ours.record(int(level), float(scores[level]))
        theirs.task_scores[level] = scores[level]
        theirs.unseen_task_weights[level] = 0.0
    return total_variation(np.asarray(theirs.sample_weights(), dtype=float), ours.replay_probabilities())


def learning_progress_case(rng: np.random.Generator, played_share: float, intervals: int = 30) -> float:
    from syllabus.curricula import OnlineLearningProgress
    from syllabus.task_space import DiscreteTaskSpace

    interval = 2 * LEVELS
    theirs = OnlineLearningProgress(DiscreteTaskSpace(LEVELS), update_interval=interval, uniform_prob=0.25)
    ours = LearningProgress(LEVELS, ema_rate=0.1, reweight_theta=0.1, uniform_share=0.25)
    skill = rng.uniform(0.0, 1.0, size=LEVELS)
    for round_ in range(intervals):
        played = np.flatnonzero(rng.random(LEVELS) < played_share) if played_share < 1 else np.arange(LEVELS)
        levels = rng.choice(played, size=interval) if len(played) else rng.integers(0, LEVELS, size=interval)
        if played_share == 1:
            levels = np.resize(np.arange(LEVELS), interval)
        for level in levels:
            success = bool(rng.random() < min(1.0, skill[level] * (round_ + 1) / intervals * 1.5))
            theirs.update_task_progress(int(level), success)
            theirs.update_on_episode(float(success), 10, int(level), success)
            ours.record(int(level), float(success))
        ours.update()
    return total_variation(np.asarray(theirs._sample_distribution(), dtype=float), ours.probabilities())


def learnability_case(rng: np.random.Generator, levels: int = 500) -> float:
    """Total variation between Syllabus's default ``Learnability`` over ``levels`` and uniform."""
    from syllabus.curricula import Learnability
    from syllabus.task_space import DiscreteTaskSpace

    rates = rng.uniform(0.0, 1.0, size=levels)

    class StandInEvaluator:  # what Learnability reads of an evaluation: each level's success rate
        def evaluate_agent(self, num_episodes: int, verbose: bool = False) -> tuple[None, np.ndarray, np.ndarray, None]:
            return None, rates, rates, None

    theirs = Learnability(StandInEvaluator(), DiscreteTaskSpace(levels))
    return total_variation(np.asarray(theirs._sample_distribution(), dtype=float), np.ones(levels))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="also write the figures here as JSON")
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    rng = np.random.default_rng(0)
    cases: dict[str, list[float]] = {name: [] for name in (
        "plr, distinct scores, 30 of 50 levels scored",
        "plr, distinct scores, no staleness share",
        "plr, a third of the scored levels at score 0 (ties with the unscored)",
        "learning progress, every level played each interval",
        "learning progress, a random half played each interval",
        "Syllabus learnability, its defaults over 500 levels, against uniform",
    )}  # fmt: skip
    names = list(cases)
    for _ in range(args.repeats):
        seen = np.zeros(LEVELS, dtype=bool)
        seen[rng.choice(LEVELS, 30, replace=False)] = True
        scores = rng.uniform(0.01, 1.0, size=LEVELS)
        cases[names[0]].append(plr_case(rng, scores, seen, 0.1, 0.1))
        cases[names[1]].append(plr_case(rng, scores, seen, 0.3, 0.0))
        zeroed = scores.copy()
        zeroed[np.flatnonzero(seen)[:10]] = 0.0
        cases[names[2]].append(plr_case(rng, zeroed, seen, 0.3, 0.0))
        cases[names[3]].append(learning_progress_case(rng, 1.0))
        cases[names[4]].append(learning_progress_case(rng, 0.5))
        cases[names[5]].append(learnability_case(rng))
    figures = {
        name: {"mean": round(float(np.mean(values)), 4), "max": round(float(np.max(values)), 4)}
        for name, values in cases.items()
    }
    print(f"{'case':<72}{'TV mean':>9}{'TV max':>9}")
    for name, figure in figures.items():
        print(f"{name:<72}{figure['mean']:>9.4f}{figure['max']:>9.4f}")
    if args.out:
        args.out.write_text(
            json.dumps({"levels": LEVELS, "repeats": args.repeats, "total_variation": figures}, indent=1) + "\n"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
