"""Issue 79's review of the level kinds, each departure pinned: learnability's unplayed levels are not the
most learnable, ``plr`` replays every draw after its sweep as the PLR paper and Syllabus do (the hybrid is
``replay_prob`` below 1, and a curriculum stored with it keeps it), and each score is named as it is."""

from __future__ import annotations

import json
import warnings
from collections import Counter

import pytest

from common.client.schemas import ParameterSpec
from common.client.task_space import Parameter, TaskSpace
from teacher_service.curriculum_spec import SPEC_CLASSES, stored_spec
from teacher_service.teachers import EpisodeResult, make_teacher

TEN = TaskSpace([Parameter("level", 0, 9, type="integer")])
FORTY = TaskSpace([Parameter("level", 0, 39, type="integer")])


def test_an_unplayed_level_is_not_the_most_learnable() -> None:
    teacher = make_teacher("learnability", FORTY, 0, {"update_every": 4, "top_k": 5, "fresh_share": 0.0})
    for level, success in ((0, True), (1, False), (2, True), (2, False)):
        teacher.learn(EpisodeResult({"level": level}, 0.0, success=success))
    rows = {row["level"]: row for row in teacher.state()["levels"]}
    assert rows[39]["learnability"] is None and rows[39]["success"] is None, "no results: no estimate"
    assert rows[0]["learnability"] == pytest.approx(0.1875), "1 of 1 with the prior: p = 0.75"
    assert rows[2]["learnability"] == pytest.approx(0.25), "1 of 2 with the prior: p = 0.5"
    drawn = Counter(task["level"] for task in teacher.sample(300))
    assert set(drawn) == {0, 1, 2}, "replays go to the played levels alone, not to a sweep of unplayed ones"
    assert drawn.most_common(1)[0][0] == 2


def test_learnability_reaches_unplayed_levels_through_its_fresh_share() -> None:
    teacher = make_teacher("learnability", FORTY, 0, {"update_every": 2, "top_k": 5, "fresh_share": 0.5})
    teacher.learn(EpisodeResult({"level": 0}, 0.0, success=True))
    teacher.learn(EpisodeResult({"level": 0}, 0.0, success=False))
    drawn = Counter(task["level"] for task in teacher.sample(2000))
    assert drawn[0] / 2000 == pytest.approx(0.5 + 0.5 / 40, abs=0.04), "every replay, plus its fresh share"
    assert len(drawn) == 40, "the fresh draws reach every level"


def test_without_a_prior_a_level_scores_its_own_success_rate_and_unplayed_ones_none() -> None:
    teacher = make_teacher("learnability", FORTY, 0, {"update_every": 3, "prior_weight": 0.0, "fresh_share": 0.0})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no 0 / 0 for the levels without results
        for level, success in ((5, True), (5, False), (6, True)):
            teacher.learn(EpisodeResult({"level": level}, 0.0, success=success))
    rows = {row["level"]: row for row in teacher.state()["levels"]}
    assert rows[5]["learnability"] == 0.25 and rows[6]["learnability"] == 0.0 and rows[7]["learnability"] is None
    assert {task["level"] for task in teacher.sample(50)} == {5}


def sweep(teacher_params: dict[str, object]) -> Counter[int]:
    """Score every level of ``TEN`` once (level 3 highest), then count 2,000 draws."""
    teacher = make_teacher("plr", TEN, 0, teacher_params)
    for _ in range(10):
        level = teacher.sample(1)[0]["level"]
        teacher.learn(EpisodeResult({"level": level}, 0.0, score=1.0 if level == 3 else 0.0))
    return Counter(task["level"] for task in teacher.sample(2000))


def test_plr_replays_every_draw_after_its_sweep_by_default() -> None:
    teacher = make_teacher("plr", TEN, 0)
    for level in range(10):
        teacher.learn(EpisodeResult({"level": level}, 0.0, score=level / 10))
    assert teacher.state()["replay_chance"] == 1.0, "the authors' and Syllabus's: only replays after the sweep"
    # β = 0.1 and ρ = 0.1: rank 1 gets 0.9 / Σ (1/r)^10 by score plus 0.1 of the staleness share.
    assert sweep({})[3] / 2000 > 0.85


def test_the_hybrid_is_replay_prob_below_one() -> None:
    counts = sweep({"replay_prob": 0.5})
    assert counts[3] / 2000 == pytest.approx(0.5 * 0.9 + 0.5 / 10, abs=0.05), "half the draws uniform"


def test_robust_plr_keeps_dcd_s_replay_probability() -> None:
    teacher = make_teacher("plr", FORTY, 0, {"robust": True})
    teacher.learn(EpisodeResult({"level": 0}, 1.0, score=1.0))
    assert teacher.state()["replay_chance"] == 0.5


def test_a_curriculum_stored_with_the_old_default_keeps_its_hybrid() -> None:
    space = [ParameterSpec.from_parameter(p).model_dump() for p in TEN.parameters]
    old_params = {"temperature": 0.1, "staleness_coef": 0.1, "replay_prob": 0.5, "replay_schedule": None}
    old = {
        "space": space,
        "seed": 0,
        "teacher": "plr",
        "params": {**old_params, "min_seen_share": None, "robust": False},
    }
    restored = stored_spec(json.dumps(old))  # every field, as the service stored a spec before the change
    assert sweep(restored.params.model_dump())[3] / 2000 == pytest.approx(0.5 * 0.9 + 0.5 / 10, abs=0.05)
    new = SPEC_CLASSES["plr"](teacher="plr", space=space).model_dump_json()
    assert json.loads(new)["params"]["replay_prob"] is None, "a new curriculum stores the default unresolved"
    assert sweep(stored_spec(new).params.model_dump())[3] / 2000 > 0.85
