"""Per-episode diagnostics read from the simulator: where the block lay, how far beyond the arm's reach,
and how the gripper met it at touchdown; the scripted controller that the policies are read against."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.kuka import HARD_V1_ENV_ID
from common.kuka.arm import TARGET_X_RANGE
from common.kuka.diagnostics import EpisodeDiagnostics, beyond_clamp, play_episode
from common.kuka.env import FAR_CENTRE, FAR_MIN_DISTANCE, FAR_X_RANGE, FAR_Y_RANGE, YAW_PER_ACTION, make_kuka_env
from common.kuka.scripted import scripted_action
from common.kuka.task_space import task_space_for


@pytest.fixture(scope="module")
def env():
    env = make_kuka_env(HARD_V1_ENV_ID)
    yield env
    env.close()


HARDEST = task_space_for(HARD_V1_ENV_ID).hardest()


def test_beyond_clamp_is_signed_distance_outside_the_ik_targets_x_range():
    low, high = TARGET_X_RANGE
    assert beyond_clamp(high) == 0.0 and beyond_clamp(low) == 0.0
    assert beyond_clamp(high + 0.03) == pytest.approx(0.03)
    assert beyond_clamp(low - 0.02) == pytest.approx(0.02)
    # Inside: minus the distance to the nearer edge.
    assert beyond_clamp(low + 0.01) == pytest.approx(-0.01)
    assert beyond_clamp((low + high) / 2) == pytest.approx(-(high - low) / 2)


def test_the_placement_is_the_blocks_pose_in_the_world_after_the_reset(env):
    for seed in range(100000, 100004):
        observation, _ = env.reset(seed=seed, options={"task": HARDEST})
        x, y, yaw = env.block_pose()
        # The hardest point puts every block far from where the gripper starts, inside the tray's far box.
        assert FAR_X_RANGE[0] <= x <= FAR_X_RANGE[1] and FAR_Y_RANGE[0] <= y <= FAR_Y_RANGE[1]
        assert math.hypot(x - FAR_CENTRE[0], y - FAR_CENTRE[1]) >= FAR_MIN_DISTANCE - 1e-9
        # The observation sees the same block from the gripper, which points down: its offset, turned by the
        # gripper's yaw (as the scripted controller turns it), leads from the gripper to the placement.
        gripper_x, gripper_y, gripper_yaw = (float(observation[index]) for index in (0, 1, 5))
        block_x, block_y = (float(value) for value in observation[6:8])
        cos, sin = math.cos(gripper_yaw), math.sin(gripper_yaw)
        seen = (gripper_x + cos * block_x + sin * block_y, gripper_y + sin * block_x - cos * block_y)
        assert seen == pytest.approx((x, y), abs=0.01)
        assert -math.pi <= yaw <= math.pi


def test_an_episode_records_its_placement_and_touchdown_as_played(env):
    recorded = play_episode(env, HARDEST, scripted_action, seed=100003)
    diagnostics = recorded.diagnostics
    # The same seed places the block in the same place, whoever plays.
    env.reset(seed=100003, options={"task": HARDEST})
    assert (diagnostics.block_x, diagnostics.block_y, diagnostics.block_yaw) == env.block_pose()

    # Replayed by hand: the touchdown figures are the last observation's block offset and the step's angle.
    observation, _ = env.reset(seed=100003, options={"task": HARDEST})
    total, length, yaw_actions = 0.0, 0, []
    while True:
        seen = observation
        action = scripted_action(observation)
        observation, reward, terminated, truncated, info = env.step(action)
        total, length = total + reward, length + 1
        yaw_actions.append(float(action[2]))
        if terminated or truncated:
            break
    assert terminated and recorded.success == info["is_success"]
    assert (recorded.reward, recorded.length) == (pytest.approx(total), length)
    assert (diagnostics.touchdown_block_x, diagnostics.touchdown_block_y) == tuple(float(v) for v in seen[6:8])
    # The wrist's turn one step before touchdown: every yaw action but the last, summed.
    wrist_turn = math.degrees(YAW_PER_ACTION * sum(yaw_actions[:-1]))
    assert abs(wrist_turn) > 5.0  # the block lies turned from the fingers' start, so the script turned them
    assert diagnostics.touchdown_wrist_turn_degrees == pytest.approx(wrist_turn, abs=1e-6)
    assert diagnostics.off_square_degrees == info["off_square_degrees"]
    assert diagnostics.touchdown_offset == pytest.approx(math.hypot(*seen[6:8]))


def test_the_scripted_controller_reaches_a_block_in_reach_and_hangs_over_one_beyond_it(env):
    """Inside the clamp it touches down over the block and square to it; beyond the far edge of the clamp
    the gripper stops at the edge, so it touches down as far from the block as the block lies beyond."""
    inside = beyond = None
    for seed in range(100000, 100040):
        episode = play_episode(env, HARDEST, scripted_action, seed)
        if episode.diagnostics.beyond_clamp < -0.02 and inside is None:
            inside = episode
        if episode.diagnostics.block_x > TARGET_X_RANGE[1] + 0.03 and beyond is None:
            beyond = episode
        if inside and beyond:
            break
    assert inside is not None and beyond is not None, "40 hardest placements hold both kinds"
    assert inside.success and inside.diagnostics.touchdown_offset < 0.005
    assert inside.diagnostics.off_square_degrees < 1.0
    offset = beyond.diagnostics.touchdown_offset
    assert offset == pytest.approx(beyond.diagnostics.beyond_clamp, abs=0.01)


def test_an_episode_cut_at_the_step_limit_never_touched_down():
    env = make_kuka_env(HARD_V1_ENV_ID, max_steps=5)
    try:
        episode = play_episode(env, HARDEST, lambda observation: np.zeros(3, dtype=np.float32), seed=3)
    finally:
        env.close()
    assert episode.length == 5 and not episode.success
    diagnostics = episode.diagnostics
    assert diagnostics.touchdown_block_x is None and diagnostics.touchdown_offset is None
    assert diagnostics.off_square_degrees is None and diagnostics.touchdown_wrist_turn_degrees is None


def test_diagnostics_survive_a_round_trip_through_their_dict():
    touched = EpisodeDiagnostics(0.68, 0.01, 2.0, -0.03, 0.002, 1.5, -40.0)
    untouched = EpisodeDiagnostics(0.55, -0.1, -1.0, None, None, None)
    for diagnostics in (touched, untouched):
        written = diagnostics.to_dict()
        assert EpisodeDiagnostics.from_dict(written) == diagnostics
    # Results written before the wrist's turn was recorded lack the key.
    older = {key: value for key, value in touched.to_dict().items() if key != "touchdown_wrist_turn_degrees"}
    assert EpisodeDiagnostics.from_dict(older).touchdown_wrist_turn_degrees is None
    assert touched.to_dict()["beyond_clamp"] == pytest.approx(0.03)
    assert touched.to_dict()["touchdown_offset"] == pytest.approx(math.hypot(0.03, 0.002))
