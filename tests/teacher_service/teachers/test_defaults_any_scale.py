"""Every kind, built with nothing but its defaults, moves on a task whose returns lie in [0, 1] and
carry no ``success`` (issue 48): no kind may assume the KUKA returns' units in silence.

The student is the ALP-GMM paper's toy in small: a 10 x 10 grid of cubes over [0, 1]^2, where
practising an open cube raises its competence by 1 (up to 100), the corner cube is open, and a cube
opens once a lower neighbour reaches 75; the return is the cube's competence / 100. A kind "moves"
when the cubes its tasks fall in after those results differ from the cubes before them (total
variation between the two histograms of a few thousand draws), well beyond the difference between
two batches of draws from one distribution (about 0.1 here).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from common.client.task_space import Parameter, TaskSpace
from teacher_service.teachers import TEACHER_KINDS, EpisodeResult, Teacher, make_teacher

UNIT_SQUARE = TaskSpace([Parameter(name, 0.0, 1.0, easiest=0.0, hardest=1.0) for name in ("x0", "x1")])
CUBES = 10
LEVEL_GRID = TaskSpace([Parameter(name, 0, CUBES - 1, type="integer") for name in ("x0", "x1")])
"""The same toy over levels, one level per cube, for the kinds that teach levels only."""
EPISODES = 1000
DRAWS = 4000
MOVED = 0.25
"""Least total variation that counts as a move."""
STATIC = {"random", "fixed"}
"""Kinds that by design never change what they hand out."""


class Toy:
    def __init__(self) -> None:
        self.competence = np.zeros((CUBES, CUBES), dtype=np.int64)

    def episode(self, task: dict[str, float]) -> float:
        cube = cube_of(task)
        lower = [c for c in itertools.product(*[{i, max(i - 1, 0)} for i in cube]) if c != cube]
        if cube == (0, 0) or any(self.competence[c] >= 75 for c in lower):
            self.competence[cube] = min(self.competence[cube] + 1, 100)
        return float(self.competence[cube]) / 100


def cube_of(task: dict[str, float]) -> tuple[int, int]:
    x0, x1 = (
        value if isinstance(value := task[name], int) else min(int(value * CUBES), CUBES - 1) for name in ("x0", "x1")
    )
    return x0, x1


def histogram(teacher: Teacher) -> np.ndarray:
    counts = np.zeros((CUBES, CUBES))
    for task in teacher.sample(DRAWS):
        counts[cube_of(task)] += 1
    return counts / DRAWS


def moved(kind: str) -> float:
    """Total variation between the cubes drawn before and after ``EPISODES`` toy results."""
    space = UNIT_SQUARE if "float" in TEACHER_KINDS[kind].parameter_types else LEVEL_GRID
    teacher = make_teacher(kind, space, seed=1)
    before = histogram(teacher)
    toy = Toy()
    for _ in range(EPISODES):
        task = teacher.sample(1)[0]
        teacher.learn_and_fit(EpisodeResult(task, reward=toy.episode(task)))
    return float(np.abs(histogram(teacher) - before).sum() / 2)


@pytest.mark.parametrize("kind", sorted(set(TEACHER_KINDS) - STATIC))
def test_every_adaptive_kind_moves_with_its_defaults_on_returns_in_0_1(kind: str) -> None:
    assert moved(kind) > MOVED, f"{kind} with its defaults hands out the same tasks after {EPISODES} results"


@pytest.mark.parametrize("kind", sorted(STATIC))
def test_the_static_kinds_do_not_move_and_the_measure_says_so(kind: str) -> None:
    assert moved(kind) < MOVED / 2
