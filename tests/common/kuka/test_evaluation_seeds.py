"""The in-run evaluation's seeds (issue 59): a KUKA family's stratified set is fixed, lies apart from the final
evaluation's seeds and from training's, and spreads its blocks over the placement bands as the final
evaluation's episodes do, where the old consecutive seeds did not."""

from __future__ import annotations

import numpy as np
import pytest

from bench.success_by_turn import turn_sense
from common.families import family_for
from common.families.base import HELD_OUT_FIRST_SEED
from common.kuka import ENV_ID, HARD_V1_ENV_ID
from common.kuka.diagnostics import EpisodeDiagnostics, beyond_clamp
from common.kuka.evaluation_seeds import (
    CANDIDATES_PER_EPISODE,
    EVALUATION_SEED_OFFSET,
    FINAL_EVALUATION_SEED,
    MAX_STRATIFIED_EPISODES,
    candidate_placements,
    clockwise,
    stratified_seeds,
)
from common.levels import DEFAULT_LEVELS, LEVEL_ENV_IDS
from learner.core.config import TrainConfig
from learner.evaluation.episode_diagnostics import BAND_LABELS, band_of

FINAL_EPISODES = 500
"""The coming bake-off's final evaluation: 500 episodes from seed 100,000 (issue 59)."""
V1_CURVE_SEEDS = [
    10939, 10066, 10295, 10478, 10712, 10403, 10907, 10091, 10615, 10170,
    10592, 10173, 10508, 10443, 10284, 10307, 10287, 10423, 10528, 10925,
]  # fmt: skip
"""The 20 curve episodes of a KukaGraspHard-v1 bake-off with --curve-episodes 20, as the rule first picked them."""


def evaluation_seeds(episodes: int, env_id: str, scheme: str = "consecutive") -> list[int]:
    """A run's in-run evaluation seeds on ``env_id``, as its family picks them."""
    return family_for(env_id).evaluation_seeds(env_id, DEFAULT_LEVELS, episodes, scheme)  # type: ignore[arg-type]


def band_counts(env_id: str, seeds: list[int]) -> np.ndarray:
    """Episodes per placement band (``placement_bands``' columns, without the straight-ahead one)."""
    bands = [
        band_of(EpisodeDiagnostics(x, 0.0, yaw, None, None, None)) for x, yaw in candidate_placements(env_id, seeds)
    ]
    return np.bincount(bands, minlength=len(BAND_LABELS))


def test_the_stratified_seeds_are_fixed_by_the_rule_alone():
    stratified_seeds.cache_clear()
    first = evaluation_seeds(20, HARD_V1_ENV_ID, "stratified")
    stratified_seeds.cache_clear()
    assert evaluation_seeds(20, HARD_V1_ENV_ID, "stratified") == first == V1_CURVE_SEEDS
    assert len(set(first)) == 20


@pytest.mark.parametrize("episodes", [1, 20, MAX_STRATIFIED_EPISODES])
def test_the_candidates_lie_below_the_final_evaluation_and_apart_from_the_consecutive_ones_start(episodes):
    last_candidate = EVALUATION_SEED_OFFSET + episodes * CANDIDATES_PER_EPISODE - 1
    assert EVALUATION_SEED_OFFSET <= last_candidate < FINAL_EVALUATION_SEED
    assert TrainConfig(eval_episodes=episodes).eval_seeds == "stratified"


def test_more_episodes_than_the_candidates_below_the_final_evaluation_allow_are_refused():
    with pytest.raises(ValueError, match="1 to 1,800 episodes"):
        stratified_seeds(HARD_V1_ENV_ID, MAX_STRATIFIED_EPISODES + 1)
    with pytest.raises(ValueError, match="at most 1,800 eval_episodes"):
        TrainConfig(env=HARD_V1_ENV_ID, eval_episodes=MAX_STRATIFIED_EPISODES + 1)
    assert TrainConfig(eval_episodes=MAX_STRATIFIED_EPISODES + 1, eval_seeds="consecutive").eval_episodes == 1801


def test_the_seeds_are_disjoint_from_the_final_evaluation_and_from_training():
    seeds = set(evaluation_seeds(20, HARD_V1_ENV_ID, "stratified"))
    assert not seeds & set(range(FINAL_EVALUATION_SEED, FINAL_EVALUATION_SEED + FINAL_EPISODES))
    # Training resets each environment once with a seed, as rollout_worker's pool and sampler draw it: per run
    # seed, worker slot and incarnation a worker seed, and from it one 32-bit seed per environment. The
    # bake-offs' seeds 0 to 9 and the screens' 100 to 119, up to 8 workers restarted twice, 16 envs each.
    training = {
        int(env_seed)
        for run_seed in (*range(10), *range(100, 120))
        for slot in range(8)
        for incarnation in range(3)
        for env_seed in np.random.SeedSequence(
            int(np.random.SeedSequence([run_seed, slot, incarnation]).generate_state(1)[0])
        ).generate_state(16)
    }
    assert len(training) == 30 * 8 * 3 * 16
    assert not seeds & training


@pytest.mark.parametrize("episodes", [10, 20])
def test_each_placement_band_holds_the_final_evaluations_share(episodes):
    """Within 1.5 episodes of the share the final 500 episodes give each band: the rule's rounding (one
    episode at a band's edge) plus the final set's own sampling noise, about 2 points of a share."""
    final = band_counts(HARD_V1_ENV_ID, list(range(FINAL_EVALUATION_SEED, FINAL_EVALUATION_SEED + FINAL_EPISODES)))
    expected = episodes * final / FINAL_EPISODES
    stratified = band_counts(HARD_V1_ENV_ID, evaluation_seeds(episodes, HARD_V1_ENV_ID, "stratified"))
    assert np.all(np.abs(stratified - expected) <= 1.5), (stratified, expected)
    if episodes == 20:
        # The old in-run seeds, which the issue found easier: 10 of 20 inside the clamp, 2 at 2 to 4 cm out.
        consecutive = band_counts(HARD_V1_ENV_ID, evaluation_seeds(episodes, HARD_V1_ENV_ID))
        assert consecutive.tolist() == [10, 2, 2, 6]
        assert np.any(np.abs(consecutive - expected) > 1.5)


@pytest.mark.parametrize("episodes", [10, 20])
def test_half_the_blocks_lie_turned_each_way(episodes):
    placed = candidate_placements(HARD_V1_ENV_ID, evaluation_seeds(episodes, HARD_V1_ENV_ID, "stratified"))
    assert sum(clockwise(yaw) for _, yaw in placed) == episodes // 2
    # The same sense as the turn table's.
    for yaw in (-3.0, -1.0, -0.1, 0.0, 0.4, 1.5, 2.0, 3.1, 4.0, 6.0):
        assert clockwise(yaw) == (turn_sense(yaw) == "clockwise")


def test_the_seeds_run_from_the_nearest_block_to_the_farthest():
    placed = candidate_placements(HARD_V1_ENV_ID, V1_CURVE_SEEDS)
    beyond = [beyond_clamp(x) for x, _ in placed]
    assert beyond == sorted(beyond)


def test_consecutive_seeds_and_level_families_are_as_before():
    assert evaluation_seeds(2, ENV_ID, "consecutive") == [10_000, 10_001]
    assert evaluation_seeds(3, LEVEL_ENV_IDS[0], "stratified") == [HELD_OUT_FIRST_SEED + k for k in range(3)]


def test_a_run_saved_before_the_stratified_seeds_resumes_on_its_consecutive_seeds():
    saved = TrainConfig(env=HARD_V1_ENV_ID).to_dict()
    assert saved["eval_seeds"] == "stratified" == TrainConfig.from_dict(saved).eval_seeds
    del saved["eval_seeds"]
    assert TrainConfig.from_dict(saved).eval_seeds == "consecutive"
    with pytest.raises(ValueError, match="eval_seeds must be one of"):
        TrainConfig(eval_seeds="random")  # type: ignore[arg-type]
