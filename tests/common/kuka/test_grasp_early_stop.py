"""The scripted grasp stops once its outcome is decided, and the episode's rewards and success do not change.

A filmed environment (``render_mode="rgb_array"``) always runs the whole grasp, so it is the reference: the
same seeded episodes, played with the same actions, must give the same rewards, lengths and success flags.
"""

from __future__ import annotations

import numpy as np
import pytest

from common.kuka import ENV_ID, HARD_V1_ENV_ID
from common.kuka.env import make_kuka_env
from common.kuka.scripted import scripted_action
from common.kuka.task_space import ALIGN_MARGIN_ANY, KUKA_HARD_V1_TASK_SPACE

HARDEST_V1 = KUKA_HARD_V1_TASK_SPACE.hardest()
ANY_ANGLE_V1 = {**HARDEST_V1, "align_margin": ALIGN_MARGIN_ANY}
"""Every touchdown may count, so the fingers always close and the contact test decides."""
GRIPPER_Z = 2


def play(
    env_id: str, task: dict[str, float], seed: int, policy: str, filmed: bool
) -> tuple[list[float], bool, np.ndarray]:
    """One episode: its rewards, its success flag and its last observation."""
    env = make_kuka_env(env_id, render_mode="rgb_array" if filmed else None, task=task or None)
    rng = np.random.default_rng(seed)
    observation, _ = env.reset(seed=seed)
    rewards = []
    while True:
        action = scripted_action(observation) if policy == "scripted" else rng.uniform(-1.0, 1.0, 3).astype(np.float32)
        observation, reward, terminated, truncated, info = env.step(action)
        rewards.append(reward)
        if terminated or truncated:
            env.close()
            return rewards, bool(info["is_success"]), observation


@pytest.mark.parametrize(
    ("task", "policy", "seeds"),
    [(HARDEST_V1, "random", range(2)), (HARDEST_V1, "scripted", range(2)), (ANY_ANGLE_V1, "random", range(2))],
    ids=["off-square touchdowns", "lifts", "fingers closing on nothing"],
)
def test_unshaped_episodes_keep_their_rewards_and_success_while_failed_grasps_stop_early(task, policy, seeds):
    for seed in seeds:
        rewards, success, last = play(HARD_V1_ENV_ID, task, seed, policy, filmed=False)
        full_rewards, full_success, full_last = play(HARD_V1_ENV_ID, task, seed, policy, filmed=True)
        assert (rewards, success) == (full_rewards, full_success)
        if success:  # a lift runs to its end either way
            assert np.array_equal(last, full_last)
        else:  # the gripper did not rise with the grasp's lift
            assert last[GRIPPER_Z] < full_last[GRIPPER_Z] - 0.1
    assert policy == "random" or success, "the scripted controller should lift the block on these seeds"


def test_a_reward_that_measures_the_final_distance_gets_the_whole_grasp():
    rewards, success, last = play(ENV_ID, {}, 0, "random", filmed=False)
    full_rewards, full_success, full_last = play(ENV_ID, {}, 0, "random", filmed=True)
    assert (rewards, success) == (full_rewards, full_success)
    assert np.array_equal(last, full_last)
