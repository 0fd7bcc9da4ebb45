"""The level-replay family's samplers, checked against their definitions computed by hand."""

from __future__ import annotations

import numpy as np
import pytest

from common.client.task_space import MAX_LEVELS
from teacher_service.teachers.algorithms.levels import LearningProgress, LevelReplay, pick, rank_weights


def test_rank_weights_follow_one_over_rank_to_the_inverse_temperature() -> None:
    weights = rank_weights(np.array([0.2, 0.9, 0.5]), temperature=0.5)
    np.testing.assert_allclose(weights, [(1 / 3) ** 2, 1.0, (1 / 2) ** 2])


def test_rank_ties_keep_level_order() -> None:
    np.testing.assert_allclose(rank_weights(np.array([1.0, 1.0, 0.0]), temperature=1.0), [1.0, 1 / 2, 1 / 3])


def test_pick_lands_in_proportion_to_the_weights() -> None:
    weights = np.array([1.0, 0.0, 3.0])
    assert [pick(weights, u) for u in (0.0, 0.2499, 0.25, 0.999)] == [0, 0, 2, 2]


def sampler(levels: int = 4, **overrides: float | str) -> LevelReplay:
    settings = {"temperature": 1.0, "staleness_coef": 0.0, "replay_prob": 1.0, "min_seen_share": 0.0}
    return LevelReplay(levels, **{**settings, **overrides})


def test_a_fresh_sampler_explores_until_a_level_has_a_score() -> None:
    plr = sampler()
    level, replay = plr.draw(np.array([0.0, 0.0, 0.6]))
    assert (level, replay) == (2, False)
    assert plr.last_drawn[2] == 1 and plr.draws == 1


def test_the_replay_chance_is_the_seen_share_capped_by_replay_prob() -> None:
    plr = sampler(replay_prob=0.4)
    plr.record(0, 1.0)
    assert plr.draw(np.array([0.24, 0.0, 0.0]))[1] is True  # seen share 1/4 < 0.4
    assert plr.draw(np.array([0.26, 0.0, 0.0]))[1] is False
    plr.record(1, 1.0)
    plr.record(2, 1.0)  # seen share 3/4, capped at 0.4
    assert plr.draw(np.array([0.39, 0.0, 0.0]))[1] is True
    assert plr.draw(np.array([0.41, 0.0, 0.0]))[1] is False
    plr.record(3, 1.0)
    assert plr.draw(np.array([0.41, 0.0, 0.0]))[1] is False, "every level scored: still replay_prob"


def test_the_fixed_schedule_replays_at_replay_prob_once_a_level_has_a_score() -> None:
    plr = sampler(replay_prob=0.5, schedule="fixed")
    assert plr.replay_chance() == 0.0
    plr.record(0, 1.0)  # seen share 1/4
    assert plr.replay_chance() == 0.5
    assert plr.draw(np.array([0.49, 0.0, 0.0]))[1] is True


def test_no_replay_before_the_min_seen_share() -> None:
    plr = sampler(min_seen_share=0.5)
    plr.record(0, 1.0)
    assert plr.draw(np.array([0.0, 0.0, 0.0]))[1] is False


def test_replays_pick_by_score_rank_among_scored_levels() -> None:
    plr = sampler(temperature=1.0)
    for level, score in ((0, 0.1), (1, 0.9), (3, 0.5)):
        plr.record(level, score)
    # ranks: level 1 first (1), level 3 second (1/2), level 0 third (1/3); total 11/6
    replays = np.array([1 / 3, 1.0, 0.0, 1 / 2]) / (11 / 6)
    np.testing.assert_allclose(plr.replay_probabilities(), replays)
    # three of four levels scored: a draw replays with chance 3/4, else explores level 2
    np.testing.assert_allclose(plr.probabilities(), 0.75 * replays + [0, 0, 0.25, 0])
    assert plr.draw(np.array([0.0, 0.5, 0.5]))[0] == 1  # 0.5 of the way: inside level 1's 6/11


def test_staleness_favours_levels_not_drawn_for_longest() -> None:
    plr = sampler(staleness_coef=1.0)
    plr.record(0, 0.0)
    plr.record(1, 0.0)
    plr.draws = 10
    plr.last_drawn[:] = [9, 1, 0, 0]
    # staleness over scored levels, draws since each was last drawn: level 0: 10 - 9 = 1, level 1: 10 - 1 = 9
    np.testing.assert_allclose(plr.replay_probabilities()[:2], [1 / 10, 9 / 10])
    level, replay = plr.draw(np.array([0.0, 0.0, 0.5]))
    assert (level, replay) == (1, True)


def test_exploring_draws_pick_uniformly_among_levels_without_a_score() -> None:
    plr = sampler(replay_prob=0.0)
    plr.record(1, 1.0)
    assert [plr.draw(np.array([0.99, 0.0, u]))[0] for u in (0.0, 0.34, 0.67)] == [0, 2, 3]


def test_the_level_count_is_bounded() -> None:
    with pytest.raises(ValueError, match=f"1 to {MAX_LEVELS:,} levels"):
        LevelReplay(MAX_LEVELS + 1, 0.1, 0.1, 1.0, 0.0)
    with pytest.raises(ValueError, match=f"1 to {MAX_LEVELS:,} levels"):
        LearningProgress(0, 0.1, 0.1, 0.0)


def reweight(rate: float, theta: float = 0.1) -> float:
    return rate * (1 - theta) / (rate + theta * (1 - 2 * rate))


def test_learning_progress_starts_uniform_and_moves_its_averages_per_update() -> None:
    lp = LearningProgress(3, ema_rate=0.5, reweight_theta=0.1, uniform_share=0.0)
    np.testing.assert_allclose(lp.probabilities(), [1 / 3] * 3)
    for success in (1, 1, 0, 1):
        lp.record(0, success)
    lp.record(1, 0)
    lp.update()
    assert lp.fast[0] == lp.slow[0] == 0.0, "the first update measures the baseline; the averages start above it"
    assert lp.true_rate[0] == 0.75
    for success in (1, 1):
        lp.record(0, success)
    lp.record(1, 1)
    lp.update()
    assert lp.fast[0] == pytest.approx(0.5), "the rate above the baseline: (1 - 0.75) / (1 - 0.75), folded at 0.5"
    assert lp.slow[0] == pytest.approx(0.25), "the slow average follows the fast one"
    assert lp.fast[1] == pytest.approx(0.5), "a level that starts to succeed opens a gap at once"
    unplayed = "a level without episodes since the last update keeps its averages"
    assert lp.fast[2] == 0.0 and lp.true_rate[2] == 0.0, unplayed
    assert lp.progress()[0] == pytest.approx(abs(reweight(0.5) - reweight(0.25)))
    lp.record(0, 0)
    lp.update()
    assert lp.fast[0] == pytest.approx(0.25), "a rate below the baseline counts as 0"


def test_learning_progress_caps_the_baseline_so_a_passed_level_can_still_progress() -> None:
    lp = LearningProgress(1, ema_rate=1.0, reweight_theta=0.1, uniform_share=0.0)
    lp.record(0, 1)
    lp.update()
    assert lp.baseline[0] == LearningProgress.BASELINE_CAP
    assert lp.fast[0] == lp.slow[0] == 1.0, "as Syllabus: the averages start at the rate above the cap"
    lp.record(0, 0)
    lp.update()
    assert lp.fast[0] == 0.0


def test_learning_progress_samples_active_levels_by_sigmoid_of_z_scored_progress() -> None:
    lp = LearningProgress(4, ema_rate=0.5, reweight_theta=0.1, uniform_share=0.2)
    lp.fast[:] = [0.5, 0.2, 0.0, 0.9]
    lp.slow[:] = [0.1, 0.2, 0.0, 0.5]
    lp.true_rate[:] = [0.5, 0.2, 0.0, 0.0]
    progress = lp.progress()
    active = np.array([True, True, False, True])
    chosen = progress[active]
    sigmoid = 1 / (1 + np.exp(-(chosen - chosen.mean()) / chosen.std()))
    expected = np.zeros(4)
    expected[active] = sigmoid / sigmoid.sum()
    np.testing.assert_allclose(lp.probabilities(), 0.8 * expected + 0.2 / 4)
    assert lp.probabilities()[2] == pytest.approx(0.05), "a level with no progress keeps only its uniform share"


def test_once_every_level_has_a_score_plr_still_draws_uniformly_unless_robust() -> None:
    plr = sampler(levels=4, replay_prob=0.25)
    for level in range(4):
        plr.record(level, float(level == 0))
    assert plr.replay_chance() == 0.25, "Syllabus's decision: replay_prob of the draws replay"
    replays = plr.replay_probabilities()
    np.testing.assert_allclose(plr.probabilities(), 0.25 * replays + 0.75 / 4)
    robust = sampler(levels=4, replay_prob=0.25, replay_when_all_scored=True)
    for level in range(4):
        robust.record(level, 1.0)
    assert robust.replay_chance() == 1.0, "robust PLR trains on replays alone"
