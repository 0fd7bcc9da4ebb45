"""examples/own_env: two environments that know nothing of this project meet the contract ``train --env
module:Id`` relies on: a ``task_space`` in the registration's JSON form, tasks through ``reset(options=...)``,
``is_success`` at every episode's end, rgb_array frames, determinism given the seed and the task, and ids
that ``gymnasium.make("examples.own_env:Id")`` finds from the repository root."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import deque
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from common.client.schemas import ParameterSpec
from common.client.task_space import Parameter, TaskSpace
from examples.own_env import grid_levels, point_reach

ROOT = Path(__file__).resolve().parents[2]
POINT_REACH = "examples.own_env:PointReach-v0"
GRID_LEVELS = "examples.own_env:GridLevels-v0"
PROJECT_PACKAGES = {"common", "kuka_curriculum", "learner", "rollout_worker", "teacher_service"}


def make(env_id: str) -> gymnasium.Env:
    return gymnasium.make(env_id, render_mode="rgb_array")


def play(env: gymnasium.Env, actions: Iterable[Any]) -> tuple[list[np.ndarray], list[float], dict]:
    """Steps through ``actions`` (an iterable, possibly endless) until the episode ends: the observations,
    the rewards and the last step's info."""
    observations, rewards = [], []
    for action in actions:
        observation, reward, terminated, truncated, info = env.step(action)
        observations.append(observation)
        rewards.append(float(reward))
        if terminated or truncated:
            return observations, rewards, info
    raise AssertionError("the episode did not end")


def point_task(**values: float) -> dict[str, float]:
    return {**point_reach.HARDEST_TASK, **values}


def test_both_ids_make_from_the_repository_root_without_importing_the_project():
    script = (
        "import json, sys, gymnasium\n"
        f"for env_id in ({POINT_REACH!r}, {GRID_LEVELS!r}):\n"
        "    gymnasium.make(env_id, render_mode='rgb_array').reset(seed=0)\n"
        "print(json.dumps(sorted({name.split('.')[0] for name in sys.modules})))\n"
    )
    made = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert made.returncode == 0, made.stderr
    assert not PROJECT_PACKAGES & set(json.loads(made.stdout)), "an example environment imports kuka-curriculum"


@pytest.mark.parametrize("env_id", [POINT_REACH, GRID_LEVELS])
def test_the_task_space_is_what_the_teacher_service_registers(env_id):
    space = make(env_id).unwrapped.task_space
    assert TaskSpace(ParameterSpec.model_validate(parameter).to_parameter() for parameter in space)
    assert TaskSpace(Parameter(**parameter) for parameter in space)


def test_point_reach_is_a_box_of_floats_with_the_hardest_task_as_its_evaluation():
    space = TaskSpace(Parameter(**parameter) for parameter in make(POINT_REACH).unwrapped.task_space)
    assert space.types == {"float"}
    assert space.hardest() == {"goal_distance": 0.9, "goal_radius": 0.05, "wind": 0.6}
    assert space.easiest() == {"goal_distance": 0.3, "goal_radius": 0.2, "wind": 0.0}
    env = make(POINT_REACH)
    assert env.reset(seed=0)[1]["task"] == space.hardest(), "a reset without a task plays the hardest"


def test_grid_levels_is_one_integer_level_among_200():
    space = TaskSpace(Parameter(**parameter) for parameter in make(GRID_LEVELS).unwrapped.task_space)
    assert space.types == {"integer"}
    assert space.names == ("level",)
    assert space.level_count() == 200


@pytest.mark.parametrize("env_id", [POINT_REACH, GRID_LEVELS])
def test_gymnasiums_own_checker_passes(env_id):
    check_env(make(env_id).unwrapped, skip_render_check=False)


def test_point_reach_puts_the_goal_at_the_tasks_distance_and_blows_the_tasks_wind():
    env = make(POINT_REACH)
    for distance, wind in ((0.3, 0.0), (0.9, 0.6), (0.6, 0.3)):
        observation, _ = env.reset(seed=1, options={"task": point_task(goal_distance=distance, wind=wind)})
        assert np.linalg.norm(observation[2:4]) == pytest.approx(distance, rel=1e-6)
        observation, *_ = env.step(np.zeros(2, dtype=np.float32))  # idle: only the wind moves the robot
        assert np.linalg.norm(observation[4:6]) == pytest.approx(wind, abs=1e-6)
        assert np.linalg.norm(observation[:2]) == pytest.approx(wind * point_reach.STEP_SIZE, abs=1e-6)


def steer_to_goal(env: gymnasium.Env, observation: np.ndarray) -> tuple[list[float], dict]:
    """Plays full speed toward the goal, leaning into the wind (the last velocity less the last push): the
    rewards and the last step's info."""
    push, rewards = np.zeros(2), []
    while True:
        wind = observation[4:6] - push
        push = np.clip(observation[2:4] / np.linalg.norm(observation[2:4]) - wind, -1.0, 1.0)
        observation, reward, terminated, truncated, info = env.step(push.astype(np.float32))
        rewards.append(float(reward))
        if terminated or truncated:
            return rewards, info


def test_point_reach_pays_and_succeeds_only_at_the_goal_and_a_narrower_goal_takes_longer():
    env = make(POINT_REACH)
    steps = {}
    for radius in (0.2, 0.05):
        observation, _ = env.reset(seed=2, options={"task": point_task(goal_radius=radius)})
        rewards, info = steer_to_goal(env, observation)
        assert info["is_success"] is True
        assert rewards[-1] == 1.0 and sum(rewards) == 1.0
        steps[radius] = len(rewards)
    assert steps[0.2] < steps[0.05] < point_reach.EPISODE_STEPS

    env.reset(seed=2, options={"task": point_task()})
    observations, rewards, info = play(env, [np.zeros(2, dtype=np.float32)] * 100)
    assert info == {"is_success": False}
    assert len(observations) == point_reach.EPISODE_STEPS and sum(rewards) == 0.0


@pytest.mark.parametrize(
    "task",
    [
        {"goal_distance": 0.5, "goal_radius": 0.1},
        {**point_reach.HARDEST_TASK, "gravity": 9.8},
        point_task(wind=0.7),
        point_task(goal_distance=float("nan")),
    ],
)
def test_point_reach_refuses_a_task_that_does_not_fit(task):
    with pytest.raises(ValueError):
        make(POINT_REACH).reset(seed=0, options={"task": task})


def observations_of(env_id: str, seed: int, options: dict | None, actions) -> np.ndarray:
    env = make(env_id)
    first, _ = env.reset(seed=seed, options=options)
    return np.stack([first, *(env.step(action)[0] for action in actions)])


def test_point_reach_is_determined_by_its_seed_and_task():
    actions = [np.array([0.5, -1.0], dtype=np.float32)] * 10
    options = {"task": point_task(wind=0.3)}
    same = observations_of(POINT_REACH, 3, options, actions)
    assert np.array_equal(same, observations_of(POINT_REACH, 3, options, actions))
    assert not np.array_equal(same, observations_of(POINT_REACH, 4, options, actions))


def room(observation: np.ndarray) -> tuple[np.ndarray, tuple[int, int]]:
    """A GridLevels observation read back into its squares (the agent's as floor) and the agent's square."""
    kinds = {tuple(colour): kind for kind, colour in enumerate(grid_levels.COLOURS)}
    squares = np.array([[kinds[tuple(pixel)] for pixel in row] for row in observation])
    (agent,) = zip(*np.nonzero(squares == grid_levels.AGENT), strict=True)
    squares[agent] = grid_levels.FLOOR
    return squares, (int(agent[0]), int(agent[1]))


def moves_to_goal(observation: np.ndarray) -> list[int]:
    """The actions of a shortest walk to the goal around walls and lava, found afresh from the image."""
    squares, agent = room(observation)
    came_from = {agent: None}
    frontier = deque([agent])
    while frontier:
        square = frontier.popleft()
        if squares[square] == grid_levels.GOAL:
            actions = []
            while came_from[square] is not None:
                square, action = came_from[square]
                actions.append(action)
            return actions[::-1]
        for action, (row_change, column_change) in enumerate(grid_levels.MOVES):
            neighbour = (square[0] + row_change, square[1] + column_change)
            if neighbour not in came_from and squares[neighbour] in (grid_levels.FLOOR, grid_levels.GOAL):
                came_from[neighbour] = (square, action)
                frontier.append(neighbour)
    raise AssertionError("the room has no way to its goal")


def test_every_training_level_can_be_won_in_its_shortest_path_and_pays_more_for_fewer_steps():
    env = make(GRID_LEVELS)
    paths = []
    for level in range(grid_levels.TRAINING_LEVELS):
        observation, info = env.reset(seed=0, options={"task": {"level": level}})
        assert info["level"] == level
        moves = moves_to_goal(observation)
        assert len(moves) == info["shortest_path"]
        _, rewards, end = play(env, moves)
        assert end == {"is_success": True}
        assert rewards[-1] == pytest.approx(1 - 0.9 * len(moves) / grid_levels.EPISODE_STEPS)
        paths.append(len(moves))
    assert min(paths) == 1 and max(paths) >= 12, "levels should range from trivial to long walks"


def neighbour_action(observation: np.ndarray, kind: int) -> int | None:
    """An action that moves the agent onto a square of this kind, if one lies next to it."""
    squares, (row, column) = room(observation)
    for action, (row_change, column_change) in enumerate(grid_levels.MOVES):
        if squares[row + row_change, column + column_change] == kind:
            return action
    return None


def first_level_with(kind: int) -> tuple[gymnasium.Env, int]:
    """A fresh episode on the first training level whose agent starts beside a square of this kind."""
    env = make(GRID_LEVELS)
    for level in range(grid_levels.TRAINING_LEVELS):
        observation, _ = env.reset(options={"task": {"level": level}})
        action = neighbour_action(observation, kind)
        if action is not None:
            return env, action
    raise AssertionError(f"no training level starts its agent beside a square of kind {kind}")


def test_grid_levels_lava_ends_the_episode_as_a_failure():
    env, into_lava = first_level_with(grid_levels.LAVA)
    observations, rewards, info = play(env, [into_lava])
    assert info == {"is_success": False} and rewards == [0.0]


def test_grid_levels_walls_block_and_an_episode_without_the_goal_is_cut_short_as_a_failure():
    env, into_wall = first_level_with(grid_levels.WALL)
    observations, rewards, info = play(env, [into_wall] * 100)
    assert info == {"is_success": False}
    assert len(observations) == grid_levels.EPISODE_STEPS and sum(rewards) == 0.0
    assert all(np.array_equal(observation, observations[0]) for observation in observations)


def test_a_grid_level_is_the_same_room_whatever_the_seed_and_a_reset_without_a_task_plays_a_held_out_one():
    level_7 = {"task": {"level": 7}}
    assert np.array_equal(observations_of(GRID_LEVELS, 1, level_7, []), observations_of(GRID_LEVELS, 2, level_7, []))
    assert not np.array_equal(
        observations_of(GRID_LEVELS, 1, level_7, []), observations_of(GRID_LEVELS, 1, {"task": {"level": 8}}, [])
    )
    env = make(GRID_LEVELS)
    held_out = [env.reset(seed=1_000_000 + index)[1]["level"] for index in range(20)]
    assert min(held_out) >= grid_levels.TRAINING_LEVELS and len(set(held_out)) == 20
    assert env.reset(seed=1_000_000)[1]["level"] == held_out[0]


@pytest.mark.parametrize("level", [200, -1, 3.0, True, "3"])
def test_grid_levels_refuses_a_level_outside_the_training_set(level):
    with pytest.raises(ValueError):
        make(GRID_LEVELS).reset(seed=0, options={"task": {"level": level}})


def test_frames_are_small_rgb_images():
    point = make(POINT_REACH)
    point.reset(seed=0)
    assert point.render().shape == (96, 96, 3) and point.render().dtype == np.uint8
    grid = make(GRID_LEVELS)
    observation, _ = grid.reset(seed=0)
    frame = grid.render()
    assert frame.shape == (144, 144, 3) and frame.dtype == np.uint8
    assert np.array_equal(frame[:: grid_levels.RENDER_SCALE, :: grid_levels.RENDER_SCALE], observation)
