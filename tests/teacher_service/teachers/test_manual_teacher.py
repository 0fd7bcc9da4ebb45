"""The lesson plan: the book's step sizes and threshold rule over the KUKA space (it never falls back
by default), interpolated and listed plans over any space, the success metric, and stepping back."""

from __future__ import annotations

import json
from typing import Any

import pytest

from common.client.task_space import Parameter, TaskSpace
from common.families.kuka import KUKA_TEACHER_PARAMS
from common.kuka.task_space import DEFAULT_JP2, DEFAULT_JP4, KUKA_TASK_SPACE
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
    """The book's plan with what ``train`` registers it with over the KUKA space (mean reward 5.5)."""
    kuka = KUKA_TEACHER_PARAMS["manual"]
    return make_teacher("manual", KUKA_TASK_SPACE, 0, {"window": 10, "min_episodes": 4, **kuka, **params})


def report(teacher: Teacher, rewards: list[float], task: dict[str, float] | None = None) -> None:
    for reward in rewards:
        teacher.learn_and_fit(EpisodeResult(task or teacher.sample(1)[0], reward))


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


DIFFICULTY = TaskSpace(
    [
        Parameter("gravity", 2.0, 12.0, hardest=12.0, easiest=2.0),
        Parameter("mass", 0.5, 1.5, hardest=1.5, easiest=0.5),
    ]
)


def test_a_space_that_is_not_the_books_gets_lessons_interpolated_to_the_hardest_point() -> None:
    teacher = make_teacher("manual", DIFFICULTY, 0, {"window": 3, "min_episodes": 3, "threshold": 0.0})
    assert teacher.state()["lessons"] == 10
    seen = []
    while not teacher.state()["final_lesson"]:
        seen.append(teacher.sample(1)[0])
        report(teacher, [1.0] * 3)
    seen.append(teacher.sample(1)[0])
    assert seen[0] == DIFFICULTY.easiest() and seen[-1] == DIFFICULTY.hardest()
    gravity = [lesson["gravity"] for lesson in seen]
    assert gravity == pytest.approx([2.0 + 10.0 * k / 9 for k in range(10)])
    assert [lesson["mass"] for lesson in seen] == pytest.approx([0.5 + k / 9 for k in range(10)])


def test_lessons_given_as_a_list_are_handed_out_in_order() -> None:
    plan = [{"gravity": 2.0, "mass": 1.5}, {"gravity": 12.0, "mass": 0.5}, {"gravity": 7.0, "mass": 1.0}]
    teacher = make_teacher("manual", DIFFICULTY, 0, {"lessons": plan, "window": 2, "min_episodes": 2, "threshold": 5.5})
    for lesson in plan:
        assert teacher.sample(3) == [lesson] * 3
        report(teacher, [6.0] * 2)
    assert teacher.state()["plan"] == plan


def test_steps_over_the_kuka_space_replace_the_books_plan() -> None:
    teacher = manual(steps=3, threshold=0.0)
    halfway = teacher.state()["plan"][1]
    easiest, hardest = KUKA_TASK_SPACE.easiest(), KUKA_TASK_SPACE.hardest()
    assert halfway == pytest.approx({name: (easiest[name] + hardest[name]) / 2 for name in easiest})


def test_a_student_that_gets_worse_makes_it_step_back() -> None:
    teacher = make_teacher(
        "manual", DIFFICULTY, 0, {"steps": 4, "window": 4, "min_episodes": 4, "threshold": 5.0, "step_back_below": 1.0}
    )
    plan = teacher.state()["plan"]
    report(teacher, [6.0] * 4)
    report(teacher, [6.0] * 4)
    assert teacher.state()["lesson"] == 2
    report(teacher, [0.5] * 3)
    assert teacher.state()["lesson"] == 2, "three episodes are below min_episodes"
    report(teacher, [0.5])
    state = teacher.state()
    assert state["lesson"] == 1
    assert teacher.sample(1)[0] == plan[1]
    assert [(m["at_results"], m["from"], m["to"]) for m in state["moves"]] == [(4, 0, 1), (8, 1, 2), (12, 2, 1)]
    assert state["moves"][-1]["why"] == "mean reward 0.5 over 4 episodes < 1.0"
    assert state["advanced_at_results"] == [4, 8]
    report(teacher, [0.0] * 4)
    report(teacher, [0.0] * 40)
    assert teacher.state()["lesson"] == 0, "never before the first lesson"


def test_the_success_rate_can_decide_and_results_without_it_are_left_out() -> None:
    teacher = make_teacher(
        "manual",
        DIFFICULTY,
        0,
        {"metric": "success", "threshold": 0.7, "step_back_below": 0.3, "window": 4, "min_episodes": 4},
    )
    for success in (True, None, True, False):
        teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], 100.0, success=success))
    assert teacher.state()["lesson"] == 0, "three scored episodes are below min_episodes"
    assert teacher.state()["unscored_results"] == 1
    teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], -100.0, success=True))
    assert teacher.state()["lesson"] == 1, "success rate (1 + 1 + 0 + 1) / 4 = 0.75 > 0.7 whatever the reward"
    for _ in range(4):
        teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], 100.0, success=False))
    assert teacher.state()["lesson"] == 0
    assert teacher.state()["moves"][-1]["why"] == "success rate 0 over 4 episodes < 0.3"


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"lessons": [{"gravity": 2.0, "mass": 0.5}], "steps": 3}, "not both"),
        ({"metric": "success", "threshold": 5.5}, r"success-rate threshold lies in \[0, 1\)"),
        ({"threshold": 1.0, "step_back_below": 1.0}, "must be below threshold"),
        ({"lessons": [{"gravity": 20.0, "mass": 0.5}]}, r"lessons\[0\]: task parameter 'gravity'=20.0 is outside"),
        ({"start": DIFFICULTY.hardest()}, "lessons 0 and 1 of the plan are the same task"),
        (
            {"start": {"gravity": 1.0, "mass": 0.5}},
            r"^start: task parameter 'gravity'=1.0 is outside its bounds \[2.0, 12.0\]$",
        ),
        ({"steps": 1001}, "less than or equal to 1000"),
    ],
)
def test_inconsistent_plans_are_refused(params: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make_teacher("manual", DIFFICULTY, 0, params)


def test_a_computed_plan_needs_the_anchors() -> None:
    space = TaskSpace([Parameter("difficulty", 0.0, 1.0)])
    with pytest.raises(ValueError, match="needs the anchors, or give lessons"):
        make_teacher("manual", space, 0)
    assert make_teacher("manual", space, 0, {"lessons": [{"difficulty": 0.5}]}).sample(1) == [{"difficulty": 0.5}]


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


def test_a_restored_plan_keeps_its_lesson_window_and_moves() -> None:
    params = {"steps": 5, "window": 4, "min_episodes": 2, "threshold": 5.0, "step_back_below": 1.0}
    original = make_teacher("manual", DIFFICULTY, 0, params)
    report(original, [6.0] * 4 + [0.0] * 2 + [6.0] * 2 + [9.0])
    state = original.state()
    assert [(m["from"], m["to"]) for m in state["moves"]] == [(0, 1), (1, 2), (2, 1), (1, 2)]
    assert state["lesson_episodes"] == 1

    restored = make_teacher("manual", DIFFICULTY, 0, params)
    restored.restore(json.loads(json.dumps(original.snapshot())), original.history(0))
    assert restored.state() == state
    for teacher in (original, restored):
        report(teacher, [0.0, 6.0, 0.0, 0.0, 7.0, 7.0])
    assert restored.state() == original.state()
    assert restored.sample(3) == original.sample(3)


def test_without_a_threshold_it_moves_on_at_three_quarters_of_the_rewards_seen() -> None:
    teacher = make_teacher("manual", DIFFICULTY, 0, {"window": 4, "min_episodes": 4})
    report(teacher, [0.0, 0.0, 0.0, 0.0])
    assert teacher.state()["threshold"] is None, "no spread of rewards yet: nothing to compare with"
    report(teacher, [0.8, 0.8, 0.8])
    assert teacher.state()["lesson"] == 0, "mean 0.6 of a range [0, 0.8] is not past 0.6"
    report(teacher, [0.8])
    state = teacher.state()
    assert state["lesson"] == 1 and state["threshold_source"] == "learned"
    assert state["threshold"] == pytest.approx(0.6) and state["rewards_seen"] == [0.0, 0.8]
    assert "0.75 of the way from the lowest to the highest reward seen" in state["moves"][0]["why"]
    # The range learned on one lesson carries on: the next needs 0.6 in the same units.
    report(teacher, [0.5] * 4)
    assert teacher.state()["lesson"] == 1
    restored = make_teacher("manual", DIFFICULTY, 0, {"window": 4, "min_episodes": 4})
    restored.restore(json.loads(json.dumps(teacher.snapshot())), teacher.history(0))
    assert restored.state()["threshold"] == pytest.approx(0.6)


def test_success_metric_without_a_threshold_moves_on_at_three_quarters_success() -> None:
    teacher = make_teacher("manual", DIFFICULTY, 0, {"window": 8, "min_episodes": 4, "metric": "success"})
    for success in (True, True, False, True):
        teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], 0.0, success=success))
    assert teacher.state()["lesson"] == 0, "0.75 does not exceed 0.75"
    teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], 0.0, success=True))
    assert teacher.state()["lesson"] == 1, "4 successes in 5"


def test_stepping_back_needs_a_threshold_in_the_same_units() -> None:
    with pytest.raises(ValueError, match="step_back_below needs a threshold in the same units: give threshold"):
        make_teacher("manual", DIFFICULTY, 0, {"step_back_below": 0.0})
