"""ADR: the box starts at the easiest task, widens at boundaries the student masters, narrows at
boundaries it fails, never past the space or back past the start, and reaches the hardest task."""

from __future__ import annotations

import json
from typing import Any

import pytest
from reach_student import SQUARE, ReachStudent, practise

from common.client.task_space import Parameter, TaskSpace
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.teachers import EpisodeResult, Teacher, make_teacher


def adr(space: TaskSpace = SQUARE, **params: Any) -> Teacher:
    return make_teacher("adr", space, 5, {"queue_length": 5, **params})


def box(teacher: Teacher) -> tuple[list[float], list[float]]:
    bounds = teacher.state()["bounds"]
    return list(bounds["low"].values()), list(bounds["high"].values())


def test_starts_at_the_easiest_point_and_every_result_there_fills_every_queue() -> None:
    teacher = make_teacher("adr", SQUARE, 0, {"queue_length": 5, "start": {"x": 0.5, "y": 0.0}})
    assert teacher.sample(3) == [{"x": 0.5, "y": 0.0}] * 3
    practise(teacher, ReachStudent(1.0), 4)
    assert box(teacher) == ([0.5, 0.0], [0.5, 0.0]), "four results are not a full queue"
    practise(teacher, ReachStudent(1.0), 1)
    low, high = box(teacher)
    assert low == pytest.approx([0.4, -0.4]) and high == pytest.approx([0.6, 0.4]), "step 0.1 of each range"
    assert teacher.state()["widened"] == 4
    assert all(entry["queued"] == 0 for entry in teacher.state()["bounds"]["boundaries"])


def test_a_mastering_student_widens_the_box_to_the_hardest_task() -> None:
    teacher = adr()
    assert box(teacher) == ([0.0, -2.0], [0.0, -2.0])
    student = ReachStudent(0.05, growth=0.01)
    for _ in range(40):
        practise(teacher, student, 50)
        if teacher.state()["full_space"]:
            break
    state = teacher.state()
    assert state["full_space"] and box(teacher) == ([0.0, -2.0], [1.0, 2.0])
    assert state["bounds"]["high"] == SQUARE.hardest()
    assert state["widened"] - state["narrowed"] == 20, "ten steps of 0.1 for each of the two high bounds"
    for move in state["moves"]:
        before = move["from"][move["parameter"]]
        after = move["to"][move["parameter"]]
        width = 1.0 if move["parameter"] == "x" else 4.0
        assert abs(after - before) == pytest.approx(0.1 * width) or after in (1.0, 2.0)
        assert move["why"].startswith("widened" if after > before else "narrowed")


def test_a_stuck_student_holds_the_box_near_its_reach_by_narrowing() -> None:
    teacher = adr()
    student = ReachStudent(0.3)
    highest = 0.0
    for _ in range(30):
        practise(teacher, student, 50)
        highest = max(highest, box(teacher)[1][0])
    state = teacher.state()
    assert state["narrowed"] >= 2
    assert 0.3 <= highest <= 0.4 + 1e-9, "a bound past the reach fails and steps back"
    narrowed = [move for move in state["moves"] if move["why"].startswith("narrowed")]
    assert all(move["performance"] <= 0.2 for move in narrowed)
    assert all(
        move["side"] == "high" and move["to"][move["parameter"]] < move["from"][move["parameter"]] for move in narrowed
    )


def test_never_narrows_past_the_start() -> None:
    start = {"x": 0.5, "y": 0.0}
    teacher = adr(start=start, initial_width=0.2)
    low, high = box(teacher)
    assert low == pytest.approx([0.4, -0.4]) and high == pytest.approx([0.6, 0.4])
    practise(teacher, ReachStudent(0.0), 500)
    assert box(teacher) == (low, high)
    assert teacher.state()["narrowed"] == 0 and teacher.state()["moves"] == []


def test_between_the_thresholds_a_full_queue_is_dropped_without_a_move() -> None:
    teacher = adr(reward_range=[0.0, 10.0])
    for _ in range(12):
        teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], reward=5.0))
    state = teacher.state()
    assert state["moves"] == [] and box(teacher) == ([0.0, -2.0], [0.0, -2.0])
    assert {entry["queued"] for entry in state["bounds"]["boundaries"]} == {2}, "12 results: two queues emptied"


def test_returns_count_through_the_reward_range_and_success_wins_over_the_return() -> None:
    scaled = adr(reward_range=[0.0, 10.0])
    for _ in range(5):
        scaled.learn_and_fit(EpisodeResult(scaled.sample(1)[0], reward=8.0))
    assert scaled.state()["widened"] == 2, "8 of [0, 10] is 0.8, at the upper threshold"
    failed = adr(reward_range=[0.0, 10.0])
    for _ in range(5):
        failed.learn_and_fit(EpisodeResult(failed.sample(1)[0], reward=10.0, success=False))
    assert failed.state()["widened"] == 0


def test_pins_the_given_share_of_tasks_at_open_boundaries_only() -> None:
    teacher = adr(start={"x": 1.0, "y": 0.0}, initial_width=0.4)
    low, high = box(teacher)
    assert low == pytest.approx([0.8, -0.8]) and high == pytest.approx([1.0, 0.8]), "x's high bound at the limit"
    tasks = teacher.sample(4000)
    on_low = [sum(task[name] == low[d] for task in tasks) for d, name in enumerate(SQUARE.names)]
    on_high = [sum(task[name] == high[d] for task in tasks) for d, name in enumerate(SQUARE.names)]
    assert on_high[0] == 0, "a bound at the space's limit is not pinned"
    assert sum(on_low) + on_high[1] == pytest.approx(0.7 * 4000, rel=0.05)
    assert min(on_low[0], on_low[1], on_high[1]) == pytest.approx(0.7 * 4000 / 3, rel=0.15)
    assert all(low[d] <= task[name] <= high[d] for task in tasks for d, name in enumerate(SQUARE.names))


def test_a_restored_teacher_continues_the_same_run() -> None:
    original = adr()
    student = ReachStudent(0.05, growth=0.01)
    practise(original, student, 137)
    assert original.state()["widened"] >= 3
    restored = adr()
    restored.restore(json.loads(json.dumps(original.snapshot())), original.history(0))
    assert restored.state() == original.state()
    twin = ReachStudent(student.reach, student.growth)
    practise(original, student, 300)
    practise(restored, twin, 300)
    assert restored.state() == original.state()
    assert restored.sample(20) == original.sample(20)


def test_kuka_defaults_start_at_the_easiest_task() -> None:
    teacher = make_teacher("adr", KUKA_TASK_SPACE, 0)
    assert teacher.sample(5) == [KUKA_TASK_SPACE.easiest()] * 5
    assert teacher.state()["bounds"]["low"] == KUKA_TASK_SPACE.easiest()


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"boundary_prob": 1.5}, r"boundary_prob\n  Input should be less than or equal to 1"),
        ({"step": 0.0}, r"step\n  Input should be greater than 0"),
        ({"queue_length": 0}, r"queue_length\n  Input should be greater than or equal to 1"),
        ({"queue_length": 10**6}, r"queue_length\n  Input should be less than or equal to 1000"),
        ({"upper_threshold": 0.3, "lower_threshold": 0.3}, r"lower_threshold \(0.3\) must be below upper_threshold"),
        ({"reward_range": [1.0, 0.0]}, "reward_range must have low < high"),
        ({"reward_range": [0.0, 1e300]}, r"reward_range.1\n  Input should be less than or equal to 1000000000"),
        ({"initial_width": -0.1}, r"initial_width\n  Input should be greater than or equal to 0"),
        ({"start": {"x": 2.0, "y": 0.0}}, "start: task parameter 'x'"),
    ],
)
def test_bad_parameters_are_rejected_by_name(params: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make_teacher("adr", SQUARE, 0, params)


def test_needs_a_start() -> None:
    with pytest.raises(ValueError, match="start: none given"):
        make_teacher("adr", TaskSpace([Parameter("x", 0.0, 1.0)]), 0)


def test_without_a_reward_range_a_queue_is_judged_between_the_lowest_and_highest_return_seen() -> None:
    teacher = adr()
    for reward in (0.0, 0.1, 0.2, 0.3, 0.4):
        teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], reward=reward))
    assert teacher.state()["moves"] == [], "a rising queue averages half way between 0 and 0.4"
    assert teacher.state()["reward_scale"] == {"source": "learned from the returns seen", "range": [0.0, 0.4]}
    for _ in range(4):
        teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], reward=0.4))
    restored = adr()
    restored.restore(json.loads(json.dumps(teacher.snapshot())), teacher.history(0))
    for copy in (teacher, restored):
        copy.learn_and_fit(EpisodeResult(copy.sample(1)[0], reward=0.4))
        assert copy.state()["widened"] == 2, "five returns at the best seen: both open boundaries widen"
        assert [move["performance"] for move in copy.state()["moves"]] == [1.0, 1.0]


def test_returns_that_never_differ_score_nothing_until_they_do() -> None:
    teacher = adr()
    for _ in range(5):
        teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], reward=3.0))
    assert teacher.state()["widened"] == 0 and teacher.state()["reward_scale"]["range"] == [3.0, 3.0]
