"""A MiniGrid level family as the workers step it: the level is the reset seed, the observation the
agent's view as 147 floats, success a positive return, and the task space one integer parameter."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

from common.client.task_space import MAX_LEVELS
from common.families.base import HELD_OUT_FIRST_SEED, held_out_seeds
from common.levels import LEVEL_ENV_IDS, level_task_space
from common.levels.env import make_level_env


@pytest.mark.parametrize("env_id", LEVEL_ENV_IDS)
def test_the_level_is_the_reset_seed(env_id):
    env = make_level_env(env_id)
    first, _ = env.reset(options={"task": {"level": 7}})
    layout = env.unwrapped.grid.encode().copy()
    env.reset(options={"task": {"level": 8}})
    other_layout = env.unwrapped.grid.encode().copy()
    again, _ = env.reset(seed=123, options={"task": {"level": 7}})  # the task's level wins over a seed
    assert np.array_equal(first, again) and np.array_equal(env.unwrapped.grid.encode(), layout)
    assert not np.array_equal(layout, other_layout)
    seeded, _ = env.reset(seed=7, options={"task": {}})  # no level: the seed given (held-out evaluation)
    assert np.array_equal(seeded, first)
    assert env.observation_space == gymnasium.spaces.Box(0.0, 255.0, (147,), np.float32)
    assert first.dtype == np.float32 and first.shape == (147,)
    assert env.action_space == gymnasium.spaces.Discrete(7)
    env.close()


def test_success_is_reaching_the_goal_and_a_timeout_is_no_success():
    env = make_level_env("MiniGrid-DoorKey-5x5-v0", max_steps=5)
    env.reset(options={"task": {"level": 0}})
    for _ in range(4):
        _, reward, terminated, truncated, info = env.step(np.int64(0))  # turning on the spot
        assert not (terminated or truncated) and "is_success" not in info
    _, reward, terminated, truncated, info = env.step(np.int64(0))
    assert truncated and not terminated and info["is_success"] is False and reward == 0

    # Put the agent in front of the goal, facing it: one step forward reaches it.
    env.reset(options={"task": {"level": 0}})
    grid = env.unwrapped.grid
    goal = next(
        (x, y) for x in range(grid.width) for y in range(grid.height) if (c := grid.get(x, y)) and c.type == "goal"
    )
    env.unwrapped.agent_pos, env.unwrapped.agent_dir = (goal[0] - 1, goal[1]), 0
    _, reward, terminated, _, info = env.step(np.int64(2))
    assert terminated and reward > 0 and info["is_success"] is True
    env.close()


def test_minigrid_keeps_its_own_step_limit_unless_ours_is_lower():
    env = make_level_env("MiniGrid-DoorKey-5x5-v0", max_steps=1000)
    env.reset(options={"task": {"level": 3}})
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.int64(0))
        steps, done = steps + 1, terminated or truncated
    assert steps == env.unwrapped.max_steps == 250
    env.close()


def test_the_task_space_is_one_integer_parameter_of_the_training_levels():
    space = level_task_space(200)
    assert [(p.name, p.type, p.low, p.high) for p in space.parameters] == [("level", "integer", 0, 199)]
    with pytest.raises(ValueError, match="levels must be between 1 and 10,000"):
        level_task_space(MAX_LEVELS + 1)
    assert held_out_seeds(3) == [HELD_OUT_FIRST_SEED, HELD_OUT_FIRST_SEED + 1, HELD_OUT_FIRST_SEED + 2]
    assert HELD_OUT_FIRST_SEED > MAX_LEVELS


def test_an_unknown_family_is_refused_by_name():
    with pytest.raises(ValueError, match="unknown level environment 'MiniGrid-Empty-5x5-v0'"):
        make_level_env("MiniGrid-Empty-5x5-v0")
