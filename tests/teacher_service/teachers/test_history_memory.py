"""Teachers that keep a history hold only a bounded tail of it once a store has released the rows
it wrote, and a teacher restored from that tail is the same teacher."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from scripted_student import run_student

from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.teachers import Teacher, make_teacher

RELEASE_EVERY = 1_000
"""How often the simulated store writes the new rows and releases them (KC_SNAPSHOT_EVERY)."""

BOUNDED: dict[str, tuple[dict[str, Any], int, int]] = {
    # kind: (params, results fed, most rows the teacher may hold)
    "alp-gmm": ({"fit_rate": 1000, "max_components": 3, "history_window": 10_000}, 50_000, 2 * (10_000 + 3_000)),
    "covar-gmm": ({"fit_rate": 1000, "max_components": 3}, 40_000, 2 * (10_000 + 2_000)),
    "riac": ({"max_region_size": 30, "max_regions": 40}, 20_000, 2 * 2 * RELEASE_EVERY),
    "currot": (
        {"particles": 20, "update_every": 50, "buffer_size": 100, "candidates": 4, "delta": 0.0},
        8_000,
        2 * (100 + 4 * 50 + 2 * RELEASE_EVERY),
    ),
    "learnability": ({"buffer_size": 300, "update_every": 50}, 8_000, 2 * (300 + 2 * RELEASE_EVERY)),
}


def feed_and_store(teacher: Teacher, results: int) -> np.ndarray:
    """Feed results; every RELEASE_EVERY, write the new history rows to a stand-in store and
    release them, as the service does with each snapshot. Returns the stored rows."""
    stored: list[np.ndarray] = []
    for _ in range(results // RELEASE_EVERY):
        run_student(teacher, RELEASE_EVERY, batch=10)
        stored.append(teacher.history(sum(len(rows) for rows in stored)))
        teacher.release_history(teacher.history_size)
    return np.concatenate(stored)


@pytest.mark.parametrize("kind", sorted(BOUNDED))
def test_released_history_leaves_memory_and_a_restore_from_the_tail_is_the_same_teacher(kind: str) -> None:
    params, results, most_held = BOUNDED[kind]
    original = make_teacher(kind, KUKA_TASK_SPACE, 5, params)
    stored = feed_and_store(original, results)
    assert original.history_size == results
    assert original.history_held <= most_held, f"{original.history_held} of {results} rows still held"

    snapshot = json.loads(json.dumps(original.snapshot(), allow_nan=False))
    kept_from = Teacher.history_kept_from(snapshot)
    assert kept_from > 0, "a restore needs only the tail"
    restored = make_teacher(kind, KUKA_TASK_SPACE, 5, params)
    restored.restore(snapshot, stored[kept_from:])
    assert restored.state() == original.state()
    assert run_student(restored, 1_500, batch=7) == run_student(original, 1_500, batch=7)
    assert restored.sample(20) == original.sample(20)


def test_rows_not_yet_released_stay_whatever_the_algorithm_needs() -> None:
    """A store that has not written the rows yet can still read every one of them."""
    params, results = BOUNDED["covar-gmm"][0], 10_000  # 20 fits, each the bulk of the cost
    most_held = 2 * (2 * params["fit_rate"] + 2 * RELEASE_EVERY)  # a released teacher's most, as BOUNDED's
    teacher = make_teacher("covar-gmm", KUKA_TASK_SPACE, 5, params)
    run_student(teacher, results, batch=10)
    assert teacher.history_held == results > most_held
    assert teacher.history(0).shape[0] == results
    teacher.release_history(results // 2)
    run_student(teacher, results, batch=10)  # the array fills up: rows before the release go
    assert teacher.history(results // 2).shape[0] == 2 * results - results // 2
    with pytest.raises(ValueError, match="not held"):
        teacher.history(0)
