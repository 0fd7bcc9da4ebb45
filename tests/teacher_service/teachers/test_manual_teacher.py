"""The book's lesson plan: its step sizes, its threshold rule, and that it never falls back."""

from __future__ import annotations

from typing import Any

import pytest

from common.task_space import DEFAULT_JP2, DEFAULT_JP4, KUKA_TASK_SPACE, Parameter, TaskSpace
from teacher_service.teachers import EpisodeResult, Teacher, make_teacher


def book_increase_difficulty(lesson: dict[str, float]) -> dict[str, float]:
    """Chapter 14's ``increase_difficulty``, transcribed with its own arithmetic."""
    harder = dict(lesson)
    harder["jp2"] = max(lesson["jp2"] - 0.1, DEFAULT_JP2)
    harder["jp4"] = max(lesson["jp4"] - 0.1, DEFAULT_JP4)
    all_at_original_values = harder["jp2"] == DEFAULT_JP2 and harder["jp4"] == DEFAULT_JP4
    for name in ("rnd_obj_x", "rnd_obj_y", "rnd_obj_ang"):
        harder[name] = min(lesson[name] + 0.05, 1)
    if harder["rnd_obj_x"] == harder["rnd_obj_y"] == harder["rnd_obj_ang"] == 1 and all_at_original_values:
        harder["bias_obj_y"] = 0
    return harder


def manual(**params: Any) -> Teacher:
    return make_teacher("manual", KUKA_TASK_SPACE, 0, {"window": 10, "min_episodes": 4, **params})


def report(teacher: Teacher, rewards: list[float], task: dict[str, float] | None = None) -> None:
    for reward in rewards:
        teacher.observe(EpisodeResult(task or teacher.sample(1)[0], reward))


def test_lessons_from_easiest_to_hardest_follow_the_book_step_by_step() -> None:
    teacher = manual()
    book_lesson = KUKA_TASK_SPACE.easiest()
    assert teacher.sample(1)[0] == book_lesson
    lessons = 1
    while book_lesson != KUKA_TASK_SPACE.hardest():
        report(teacher, [6.0] * 4)
        book_lesson = book_increase_difficulty(book_lesson)
        lessons += 1
        assert teacher.sample(1)[0] == pytest.approx(book_lesson, abs=1e-12)
        assert teacher.state()["lesson"] == lessons - 1
    assert lessons == 21
    assert teacher.state()["final_lesson"]
    report(teacher, [9.0] * 20)
    assert teacher.sample(1)[0] == KUKA_TASK_SPACE.hardest()


def test_bias_drops_only_once_everything_else_is_hardest() -> None:
    teacher = manual()
    seen = []
    while not teacher.state()["final_lesson"]:
        seen.append(teacher.sample(1)[0])
        report(teacher, [6.0] * 4)
    assert all(lesson["bias_obj_y"] == 0.04 for lesson in seen)
    assert seen[-1]["rnd_obj_x"] == pytest.approx(0.95)


def test_advances_only_when_the_recent_mean_exceeds_the_threshold() -> None:
    teacher = manual(window=4, min_episodes=2)
    report(teacher, [6.0])
    assert teacher.state()["lesson"] == 0, "one episode is below min_episodes"
    report(teacher, [5.0])
    assert teacher.state()["lesson"] == 0, "mean 5.5 does not exceed 5.5"
    report(teacher, [0.0, 10.0])
    assert teacher.state()["lesson"] == 0, "window mean (6 + 5 + 0 + 10) / 4 = 5.25"
    report(teacher, [10.0])
    assert teacher.state()["lesson"] == 1, "window mean (5 + 0 + 10 + 10) / 4 = 6.25"
    assert teacher.state()["lesson_episodes"] == 0
    assert teacher.state()["advanced_at_results"] == [5]


def test_never_falls_back() -> None:
    teacher = manual()
    report(teacher, [8.0] * 4)
    lesson = teacher.sample(1)[0]
    report(teacher, [-10.0] * 50)
    assert teacher.state()["lesson"] == 1
    assert teacher.sample(1)[0] == lesson


def test_results_of_an_earlier_lesson_do_not_count_toward_the_current_one() -> None:
    teacher = manual()
    first_lesson = teacher.sample(1)[0]
    report(teacher, [8.0] * 4)
    report(teacher, [8.0] * 4, task=first_lesson)
    state = teacher.state()
    assert state["lesson"] == 1
    assert state["stale_results"] == 4
    assert state["lesson_episodes"] == 0


def test_starts_where_asked_and_describes_the_lesson() -> None:
    start = {**KUKA_TASK_SPACE.hardest(), "rnd_obj_x": 0.9, "bias_obj_y": 0.02}
    teacher = manual(start=start, threshold=1.0)
    state = teacher.state()
    assert state["lesson_params"] == start
    assert state["lessons"] == 3
    report(teacher, [2.0] * 4)
    assert teacher.sample(1)[0] == {**start, "rnd_obj_x": pytest.approx(0.95)}
    report(teacher, [2.0] * 4)
    assert teacher.state()["lesson_params"] == KUKA_TASK_SPACE.hardest()


def test_rejects_a_space_without_the_books_parameters() -> None:
    space = TaskSpace([Parameter("difficulty", 0.0, 1.0, hardest=1.0, easiest=0.0)])
    with pytest.raises(ValueError, match="needs exactly the parameters"):
        make_teacher("manual", space, 0)


def _kuka_space_with(name: str, **anchors: float) -> TaskSpace:
    """The KUKA space with one parameter's bounds and anchors replaced."""
    return TaskSpace(Parameter(p.name, **anchors) if p.name == name else p for p in KUKA_TASK_SPACE.parameters)


@pytest.mark.timeout(5)
@pytest.mark.parametrize(
    ("anchors", "message"),
    [
        ({"low": 0.0, "high": 1e6, "easiest": 0.0, "hardest": 1e6}, "would have 20000001 lessons, more than 1000"),
        ({"low": 1e15, "high": 1e15 + 1, "easiest": 1e15, "hardest": 1e15 + 1}, "lost to rounding"),
    ],
)
def test_a_plan_too_long_or_that_never_arrives_is_refused_at_once(anchors: dict[str, float], message: str) -> None:
    space = _kuka_space_with("rnd_obj_x", **anchors)
    with pytest.raises(ValueError, match=message):
        make_teacher("manual", space, 0)


def test_the_longest_allowed_plan_is_built() -> None:
    space = _kuka_space_with("rnd_obj_x", low=0.0, high=49.95, easiest=0.0, hardest=49.95)
    assert make_teacher("manual", space, 0).state()["lessons"] == 1000
