"""ALP-GMM against uniform sampling on a synthetic student: the paper's argument in miniature.

The rules below were fixed before any result was looked at, and not tuned afterwards:

- Tasks live in [0, 1]^D, cut into B equal bins per dimension: D=2 with B=10 (100 cells) and
  D=6 with B=3 (729 cells).
- A cell is learnable when its bin indices sum to at most (B-1)*D/2 (the easier half of the box);
  the others can never be learned.
- The corner cell (0, ..., 0) is learnable from the start. Any other learnable cell can be learned
  only once a face neighbour (one index differing by one) has competence above 0.5.
- An episode on a task returns the competence of its cell plus Gaussian noise (sd 0.02); then, if
  the cell can be learned, practice moves its competence 5% of the way toward 1.
- A cell is mastered at competence 0.9 (about 45 practice episodes; it unlocks its neighbours
  after 14). Each teacher gets 20,000 episodes per run, one task at a time, every result reported
  at once; 5 seeds. ALP-GMM runs with the kind's defaults (fit_rate 250, random_task_ratio 0.2,
  k = 2..10, tasks rescaled, raw rewards).

The table gives the cells mastered after each quarter of the budget (mean over seeds), the final
count per seed, and the share of episodes spent on cells where progress was possible (learnable,
unlocked, not yet mastered).

Usage: .venv/bin/python bench/teacher_toy.py [--episodes 20000] [--seeds 5]
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import time
import warnings
from dataclasses import dataclass

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from tqdm import tqdm

from common.task_space import Parameter, Task, TaskSpace
from teacher_service.teachers import EpisodeResult, make_teacher

UNLOCK_AT = 0.5
MASTERED_AT = 0.9
LEARNING_RATE = 0.05
NOISE_SD = 0.02
QUARTERS = 4
WORLDS = {2: 10, 6: 3}
"""Dimensions to bins per dimension."""


class ToyStudent:
    """Competence per cell of a grid over the task box, learned under the rules above."""

    def __init__(self, dims: int, bins: int, seed: int) -> None:
        self.dims, self.bins = dims, bins
        self.names = [f"x{i}" for i in range(dims)]
        self.competence = np.zeros((bins,) * dims)
        index_sums = np.indices(self.competence.shape).sum(axis=0)
        self.learnable = index_sums <= (bins - 1) * dims / 2
        self.noise = np.random.default_rng(seed)

    @property
    def space(self) -> TaskSpace:
        return TaskSpace(Parameter(name, 0.0, 1.0) for name in self.names)

    def cell(self, task: Task) -> tuple[int, ...]:
        return tuple(min(int(task[name] * self.bins), self.bins - 1) for name in self.names)

    def can_learn(self, cell: tuple[int, ...]) -> bool:
        if not self.learnable[cell]:
            return False
        if not any(cell):
            return True
        for axis, step in itertools.product(range(self.dims), (-1, 1)):
            neighbour = list(cell)
            neighbour[axis] += step
            if 0 <= neighbour[axis] < self.bins and self.competence[tuple(neighbour)] > UNLOCK_AT:
                return True
        return False

    def episode(self, task: Task) -> tuple[float, bool]:
        """The reward, and whether the episode was spent where progress was possible."""
        cell = self.cell(task)
        reward = float(self.competence[cell] + self.noise.normal(0.0, NOISE_SD))
        learning = self.can_learn(cell)
        progressing = learning and self.competence[cell] < MASTERED_AT
        if learning:
            self.competence[cell] += LEARNING_RATE * (1.0 - self.competence[cell])
        return reward, progressing

    def mastered(self) -> int:
        return int(np.sum(self.competence >= MASTERED_AT))


@dataclass(frozen=True)
class Outcome:
    mastered: list[int]
    """Cells mastered after each quarter of the budget."""
    progress_share: float
    seconds: float


def run(dims: int, kind: str, seed: int, episodes: int) -> Outcome:
    student = ToyStudent(dims, WORLDS[dims], seed)
    teacher = make_teacher(kind, student.space, seed)
    checkpoints = {episodes * quarter // QUARTERS for quarter in range(1, QUARTERS + 1)}
    progressing, mastered = 0, []
    start = time.perf_counter()
    for episode in range(1, episodes + 1):
        task = teacher.sample(1)[0]
        reward, useful = student.episode(task)
        progressing += useful
        teacher.observe(EpisodeResult(task, reward))
        if episode in checkpoints:
            mastered.append(student.mastered())
    return Outcome(mastered, progressing / episodes, time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20_000, help="episodes per run")
    parser.add_argument("--seeds", type=int, default=5, help="runs per teacher and dimension")
    args = parser.parse_args()
    # Duplicate-heavy early fits make scikit-learn warn; the warnings say nothing about the result.
    warnings.filterwarnings("ignore", category=ConvergenceWarning)

    runs = [(dims, kind, seed) for dims in WORLDS for kind in ("alp-gmm", "random") for seed in range(args.seeds)]
    outcomes = {key: run(*key, args.episodes) for key in tqdm(runs, desc="toy runs")}

    quarters = ", ".join(f"{args.episodes * q // QUARTERS}" for q in range(1, QUARTERS + 1))
    print(f"\n{args.episodes} episodes per run, seeds 0..{args.seeds - 1}; mastered cells after {quarters} episodes")
    print(
        f"{'dims':>4} {'cells':>5} {'learnable':>9}  {'teacher':<8} {'mastered (mean)':<24} "
        f"{'final mean ± sd':>15}  {'final per seed':<24} {'progress share':>14} {'s/run':>6}"
    )
    for dims, bins in WORLDS.items():
        learnable = int(ToyStudent(dims, bins, 0).learnable.sum())
        for kind in ("alp-gmm", "random"):
            results = [outcomes[(dims, kind, seed)] for seed in range(args.seeds)]
            curve = " ".join(f"{statistics.fmean(r.mastered[q] for r in results):5.1f}" for q in range(QUARTERS))
            final = [result.mastered[-1] for result in results]
            spread = statistics.stdev(final) if len(final) > 1 else 0.0
            print(
                f"{dims:>4} {bins**dims:>5} {learnable:>9}  {kind:<8} {curve:<24} "
                f"{statistics.fmean(final):>7.1f} ± {spread:<5.1f}  {str(final):<24} "
                f"{statistics.fmean(r.progress_share for r in results):>14.2f} "
                f"{statistics.fmean(r.seconds for r in results):>6.1f}"
            )


if __name__ == "__main__":
    main()
