"""The KUKA grasp environment: gymnasium contract, determinism, tasks and the book's rules."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import common.kuka
from common.kuka.env import KukaGraspEnv
from common.kuka.task_space import KUKA_TASK_SPACE

EASIEST = KUKA_TASK_SPACE.easiest()
HARDEST = KUKA_TASK_SPACE.hardest()


def random_actions(seed: int, count: int = 1000) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, size=(count, 3)).astype(np.float32)


def rollout(env: KukaGraspEnv, actions: np.ndarray) -> list[tuple]:
    """Step until the episode ends or the actions run out; every output of every step."""
    trajectory = []
    for action in actions:
        observation, reward, terminated, truncated, info = env.step(action)
        trajectory.append((observation.tobytes(), reward, terminated, truncated, info["is_success"]))
        if terminated or truncated:
            break
    return trajectory


def zero_action_episodes(env: KukaGraspEnv, task: dict[str, float], seeds: range) -> list[tuple[int, bool]]:
    """(length, success) of each episode in which the agent does nothing."""
    results = []
    for seed in seeds:
        env.reset(seed=seed, options={"task": task})
        for length in range(1, env.max_steps + 1):  # noqa: B007  read after the loop: the episode's length
            _, _, terminated, truncated, info = env.step(np.zeros(3, dtype=np.float32))
            if terminated or truncated:
                break
        results.append((length, info["is_success"]))
    return results


@pytest.fixture
def env():
    environment = KukaGraspEnv()
    yield environment
    environment.close()


def test_passes_gymnasium_env_checker():
    check_env(gymnasium.make("KukaGrasp-v0", render_mode="rgb_array").unwrapped)


def test_registered_on_import_and_made_with_arguments():
    env = gymnasium.make(common.kuka.ENV_ID, max_steps=3)
    env.reset(seed=0)
    ends = [env.step(env.action_space.sample())[3] for _ in range(3)]
    assert ends == [False, False, True]
    env.close()


def test_importing_common_kuka_registers_the_ids_without_loading_pybullet():
    check = (
        "import sys, common.kuka, gymnasium\n"
        "assert common.kuka.ENV_ID in gymnasium.registry\n"
        "assert 'pybullet' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", check], check=True, cwd=Path(__file__).resolve().parents[3])


def test_same_seed_same_placement_and_trajectory():
    actions = random_actions(1, count=300)
    first, second = KukaGraspEnv(), KukaGraspEnv()
    observation_a, _ = first.reset(seed=42)
    observation_b, _ = second.reset(seed=42)
    assert np.array_equal(observation_a, observation_b)
    assert rollout(first, actions) == rollout(second, actions)

    observation_c, _ = first.reset(seed=43)
    assert not np.array_equal(observation_a[6:], observation_c[6:]), "another seed should move the block"


def test_two_envs_in_one_process_do_not_disturb_each_other():
    seeds, actions = (3, 4), (random_actions(3), random_actions(4))
    separate = []
    for seed, episode_actions in zip(seeds, actions, strict=True):
        env = KukaGraspEnv(task=EASIEST)
        env.reset(seed=seed)
        separate.append(rollout(env, episode_actions))
        env.close()

    envs = [KukaGraspEnv(task=EASIEST) for _ in seeds]
    for env, seed in zip(envs, seeds, strict=True):
        env.reset(seed=seed)
    interleaved: list[list[tuple]] = [[], []]
    running = [True, True]
    for step in range(len(actions[0])):
        for index, env in enumerate(envs):
            if running[index]:
                interleaved[index] += rollout(env, actions[index][step : step + 1])
                _, _, terminated, truncated, _ = interleaved[index][-1]
                running[index] = not (terminated or truncated)
    assert interleaved == separate
    assert all(trajectory[-1][2] for trajectory in separate), "both episodes should end in a grasp"


def test_restored_reset_matches_a_fresh_load():
    reused = KukaGraspEnv(task=EASIEST)
    reused.reset(seed=1)
    dirty = rollout(reused, np.zeros((200, 3), dtype=np.float32))
    assert dirty[-1][4], "leave the block lifted and moving, with contacts and motor commands behind"
    fresh = KukaGraspEnv(task=EASIEST, reload_on_reset=True)

    restored_start, _ = reused.reset(seed=7)
    reloaded_start, _ = fresh.reset(seed=7)
    assert np.array_equal(restored_start, reloaded_start)
    actions = random_actions(9)
    restored, reloaded = rollout(reused, actions), rollout(fresh, actions)
    assert restored == reloaded
    assert reloaded[-1][2], "the episode should end in a grasp"


@pytest.mark.parametrize(
    ("bad_task", "named"),
    [
        ({**HARDEST, "gravity": 1.0}, "gravity"),
        ({name: value for name, value in HARDEST.items() if name != "jp2"}, "jp2"),
        ({**HARDEST, "rnd_obj_x": 1.5}, "rnd_obj_x"),
        ({**HARDEST, "bias_obj_y": -0.01}, "bias_obj_y"),
        ({**HARDEST, "jp4": math.nan}, "jp4"),
        ({**HARDEST, "rnd_obj_ang": math.inf}, "rnd_obj_ang"),
    ],
)
def test_bad_task_is_rejected_naming_the_parameter(env, bad_task, named):
    env.reset(options={"task": EASIEST})
    with pytest.raises(ValueError, match=named):
        env.reset(options={"task": bad_task})
    assert env.task == EASIEST, "a rejected task must not replace the current one"
    with pytest.raises(ValueError, match=named):
        KukaGraspEnv(task=bad_task)


def test_unknown_reset_option_is_rejected(env):
    with pytest.raises(ValueError, match="difficulty"):
        env.reset(options={"difficulty": 1})


def test_task_defaults_to_hardest_and_is_kept_until_replaced(env):
    _, info = env.reset(seed=0)
    assert info["task"] == HARDEST == env.task
    _, info = env.reset(seed=0, options={"task": EASIEST})
    assert info["task"] == EASIEST
    _, info = env.reset(seed=1)
    assert info["task"] == EASIEST == env.task


def test_task_sets_block_placement(env):
    fixed_block = {**EASIEST, "bias_obj_y": 0.02}
    placements = {env.reset(seed=seed, options={"task": fixed_block})[0][6:].tobytes() for seed in range(3)}
    assert len(placements) == 1, "with every rnd_* at 0 the block does not move between seeds"
    placements = {env.reset(seed=seed, options={"task": HARDEST})[0][6:].tobytes() for seed in range(3)}
    assert len(placements) == 3


def test_lower_start_pose_stays_low(env):
    """The fixed defect: the IK target starts at the gripper, so a raised jp2 is not pulled back up."""
    high_start_z = env.reset(seed=0, options={"task": HARDEST})[0][2]
    low_start_z = env.reset(seed=0, options={"task": EASIEST})[0][2]
    assert low_start_z < high_start_z - 0.2
    for _ in range(90):
        observation, _, terminated, _, _ = env.step(np.zeros(3, dtype=np.float32))
        assert not terminated
    assert observation[2] < low_start_z, "the gripper should have descended from where it started"


def test_easiest_task_with_zero_actions_usually_grasps(env):
    results = zero_action_episodes(env, EASIEST, range(20))
    assert max(length for length, _ in results) <= 150
    assert sum(success for _, success in results) >= 18


def test_hardest_task_with_zero_actions_rarely_grasps(env):
    results = zero_action_episodes(env, HARDEST, range(20))
    assert min(length for length, _ in results) > 500, "a long descent from the default start"
    assert sum(success for _, success in results) <= 2


def test_success_pays_about_ten_on_the_last_step_only(env):
    env.reset(seed=0, options={"task": EASIEST})
    rewards, successes = [], []
    while True:
        _, reward, terminated, truncated, info = env.step(np.zeros(3, dtype=np.float32))
        rewards.append(reward)
        successes.append(info["is_success"])
        if terminated or truncated:
            break
    assert terminated and successes[-1] and not any(successes[:-1])
    assert 9.0 < rewards[-1] <= 10.0
    assert all(-1.0 < reward < 0.0 for reward in rewards[:-1])


def test_truncates_at_max_steps():
    env = KukaGraspEnv(max_steps=4)
    env.reset(seed=0)
    flags = [env.step(np.zeros(3, dtype=np.float32))[2:4] for _ in range(4)]
    assert flags == [(False, False)] * 3 + [(False, True)]
    env.close()


def test_render_returns_an_rgb_image():
    env = KukaGraspEnv(render_mode="rgb_array", render_width=64, render_height=48)
    env.reset(seed=0)
    image = env.render()
    assert image.shape == (48, 64, 3) and image.dtype == np.uint8
    assert image.std() > 10, "the scene, not a blank frame"
    env.close()
    assert KukaGraspEnv().render() is None
