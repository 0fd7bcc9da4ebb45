"""The level kinds as a learner meets them: which levels they draw, what scores them, what robust PLR
marks for scoring only, and which spaces each refuses."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from common.client.task_space import MAX_LEVELS, Parameter, TaskSpace
from teacher_service.teachers import EpisodeResult, make_teacher

TEN = TaskSpace([Parameter("level", 0, 9, type="integer")])


def test_robust_plr_marks_its_exploring_draws_for_scoring_only_and_trains_on_replays() -> None:
    teacher = make_teacher("plr", TEN, 0, {"robust": True})
    tasks, score_only = teacher.sample_marked(1)
    assert score_only == [True], "nothing is scored yet: the first draw explores"
    explored: set[int] = set()
    while len(explored) < 10:
        tasks, score_only = teacher.sample_marked(1)
        level = tasks[0]["level"]
        if score_only[0]:
            assert level not in explored, "an exploring draw picks a level without a score"
            explored.add(level)
        teacher.learn(EpisodeResult(tasks[0], 0.0, score=float(level)))
    tasks, score_only = teacher.sample_marked(50)
    assert not any(score_only), "every level has a score: every draw replays and trains"


def test_robust_plr_trains_on_half_its_draws_from_the_first_score() -> None:
    thousand = TaskSpace([Parameter("level", 0, 999, type="integer")])
    teacher = make_teacher("plr", thousand, 0, {"robust": True})
    teacher.learn(EpisodeResult({"level": 0}, 1.0, score=1.0))
    score_only = teacher.sample_marked(400)[1]
    assert 0.4 < score_only.count(False) / 400 < 0.6, "the fixed schedule: replay_prob of the draws replay"
    proportionate = make_teacher("plr", thousand, 0, {"robust": True, "replay_schedule": "proportionate"})
    proportionate.learn(EpisodeResult({"level": 0}, 1.0, score=1.0))
    assert proportionate.sample_marked(400)[1].count(False) < 20, "one level of 1,000 scored: almost no replay"


def test_plain_plr_plays_every_level_once_before_any_replay() -> None:
    teacher = make_teacher("plr", TEN, 0)
    first_pass = []
    for _ in range(10):
        level = teacher.sample(1)[0]["level"]
        first_pass.append(level)
        teacher.learn(EpisodeResult({"level": level}, 0.0, score=1.0 if level == 3 else 0.0))
    assert sorted(first_pass) == list(range(10)), "the authors' rho of 1: a sweep without repeats first"
    assert Counter(task["level"] for task in teacher.sample(200)).most_common(1)[0][0] == 3, "then replays"


def test_plain_plr_marks_nothing() -> None:
    teacher = make_teacher("plr", TEN, 0)
    assert teacher.sample_marked(30)[1] == [False] * 30


def test_plr_replays_the_levels_with_the_highest_scores_most() -> None:
    teacher = make_teacher("plr", TEN, 0)
    for level in range(10):
        teacher.learn(EpisodeResult({"level": level}, 0.0, score=level / 10))
    counts = Counter(task["level"] for task in teacher.sample(2000))
    assert counts.most_common(1)[0][0] == 9
    # Every draw replays; β = 0.1 gives rank 1 (1 - ρ) * 1 / Σ (1/r)^10 ≈ 0.9 by score, ρ = 0.1 by staleness.
    assert counts[9] / 2000 == pytest.approx(0.9, abs=0.03), "its staleness stays near 0"
    assert set(counts) == set(range(10)), "staleness brings every level back"


def test_plr_scores_by_the_return_gap_when_no_score_comes() -> None:
    teacher = make_teacher("plr", TEN, 0)
    teacher.learn(EpisodeResult({"level": 3}, 2.0))
    teacher.learn(EpisodeResult({"level": 5}, 0.5))
    teacher.learn(EpisodeResult({"level": 3}, 1.5))
    table = {row["level"]: row["score"] for row in teacher.state()["levels"]}
    assert table[3] == pytest.approx(0.5), "against the level's previous return, 2.0"
    assert table[5] == pytest.approx(1.5), "a level's first result: against the mean over scored levels, 2.0"


def test_learning_progress_draws_the_level_that_is_being_learnt() -> None:
    teacher = make_teacher("learning-progress", TEN, 0, {"update_every": 10, "uniform_share": 0.1})
    for round_ in range(20):
        for level in range(10):
            success = level == 4 and round_ >= 10 or level == 7  # level 4 starts to succeed, 7 always does
            teacher.learn(EpisodeResult({"level": level}, 0.0, success=success))
    counts = Counter(task["level"] for task in teacher.sample(3000))
    assert counts.most_common(1)[0][0] == 4, counts
    assert counts[7] < counts[4] / 2, "a level always solved makes no progress"


def test_learnability_over_levels_scores_each_level_from_its_own_results() -> None:
    teacher = make_teacher("learnability", TEN, 0, {"update_every": 40, "prior_weight": 1.0, "top_k": None})
    for round_ in range(4):
        for level in range(10):
            success = {2: round_ % 2 == 0, 6: True}.get(level, False)  # level 2: half the time
            teacher.learn(EpisodeResult({"level": level}, 0.0, success=success))
    rows = {row["level"]: row for row in teacher.state()["levels"]}
    assert rows[2]["success"] == pytest.approx((2 + 0.5) / (4 + 1))
    assert rows[6]["success"] == pytest.approx((4 + 0.5) / 5) and rows[0]["success"] == pytest.approx(0.5 / 5)
    counts = Counter(task["level"] for task in teacher.sample(2000))
    assert counts.most_common(1)[0][0] == 2


@pytest.mark.parametrize("kind", ["plr", "learning-progress", "learnability"])
def test_a_space_over_the_level_cap_is_refused_naming_the_cap(kind: str) -> None:
    wide = TaskSpace([Parameter("seed", 0, MAX_LEVELS, type="integer")])
    with pytest.raises(ValueError, match=f"holds {MAX_LEVELS + 1:,} levels.*at most {MAX_LEVELS:,}"):
        make_teacher(kind, wide, 0)


@pytest.mark.parametrize("kind", ["plr", "learning-progress"])
def test_a_level_kind_refuses_a_float_parameter_by_name(kind: str) -> None:
    space = TaskSpace([Parameter("level", 0, 9, type="integer"), Parameter("friction", 0.5, 1.5)])
    with pytest.raises(ValueError, match=f"'friction' is a float parameter: the {kind} teacher takes integer"):
        make_teacher(kind, space, 0)


def test_learnability_takes_a_box_or_levels_but_not_both() -> None:
    space = TaskSpace([Parameter("friction", 0.5, 1.5), Parameter("level", 0, 9, type="integer")])
    with pytest.raises(ValueError, match="'level' is an integer parameter among float ones"):
        make_teacher("learnability", space, 0)


def test_the_dashboard_table_is_bounded_and_sorted_by_probability() -> None:
    teacher = make_teacher("plr", TaskSpace([Parameter("level", 0, 999, type="integer")]), 0)
    for level in range(0, 1000, 3):
        teacher.learn(EpisodeResult({"level": level}, 0.0, score=float(level)))
    state = teacher.state()
    probabilities = [row["probability"] for row in state["levels"]]
    assert state["level_count"] == 1000 and len(probabilities) == 100
    assert probabilities == sorted(probabilities, reverse=True)
    assert np.isclose(sum(teacher.sampler.probabilities()), 1.0)
