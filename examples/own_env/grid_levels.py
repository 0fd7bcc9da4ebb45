"""GridLevels-v0: walk to the goal square of a small room strewn with walls and lava, one layout per level.

The task is one integer, ``level`` (0 to 199): the seed of the room's layout, so a teacher chooses among
200 fixed training rooms. Each level draws its own clutter, from an empty room to one nearly half full of
walls and lava; over the training rooms the shortest way to the goal takes from 1 to 14 moves. Levels are not
ordered by difficulty: which ones the student can learn from, and when, is for a level teacher to find
out. A reset without a task plays a room outside the training set, drawn from the reset's seed (a
held-out level, as an evaluation plays).

The observation is the whole room as a 9 x 9 RGB image, one pixel a square: grey walls, orange lava, the
green goal and the blue agent on black floor. The four actions move the agent up, right, down or left;
a wall blocks the move. Reaching the goal pays 1 - 0.9 x (steps taken / 50) and ends the episode, as
does stepping into lava, which pays nothing; after 50 steps the episode is cut short.
``info["is_success"]`` says at the end of every episode whether the goal was reached, and the reset's
``info`` holds the level played and its shortest path.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import gymnasium
import numpy as np

TRAINING_LEVELS = 200
TASK_SPACE: list[dict[str, Any]] = [{"name": "level", "low": 0, "high": TRAINING_LEVELS - 1, "type": "integer"}]
"""The task space in the JSON form the teacher service registers. Levels have no hardest or easiest
one: runs are evaluated on held-out levels, played by resets without a task."""

HELD_OUT_LEVELS = (TRAINING_LEVELS, 2**31 - 1)
"""The range a reset without a task draws its level from: never a training level."""

SIZE = 9
"""The room's side in squares, its outer wall included."""
EPISODE_STEPS = 50
MOST_WALLS = 16
MOST_LAVA = 6

FLOOR, WALL, LAVA, GOAL, AGENT = range(5)
COLOURS = np.array([[0, 0, 0], [128, 128, 128], [255, 110, 0], [0, 200, 60], [40, 110, 255]], dtype=np.uint8)
"""The pixel of each kind of square, indexed by the constants above."""
MOVES = ((-1, 0), (0, 1), (1, 0), (0, -1))
"""Row and column change of each action: up, right, down, left."""
RENDER_SCALE = 16
"""Pixels per square in a rendered frame (144 x 144); the observation keeps one pixel per square."""


def shortest_path(squares: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> int | None:
    """The fewest moves from start to goal that touch neither wall nor lava, or ``None`` if there is no way."""
    distances = {start: 0}
    frontier = deque([start])
    while frontier:
        row, column = frontier.popleft()
        if (row, column) == goal:
            return distances[goal]
        for row_change, column_change in MOVES:
            neighbour = (row + row_change, column + column_change)
            if neighbour not in distances and squares[neighbour] in (FLOOR, GOAL):
                distances[neighbour] = distances[(row, column)] + 1
                frontier.append(neighbour)
    return None


def generate_room(level: int) -> tuple[np.ndarray, tuple[int, int], int]:
    """The level's room (squares without the agent), the agent's start and the shortest path to the goal.

    The level seeds everything: how cluttered the room is, then where each wall, lava square, the goal and
    the agent go, redrawn until the goal can be reached."""
    rng = np.random.default_rng(level)
    clutter = rng.random()
    walls, lava = round(clutter * MOST_WALLS), round(clutter * MOST_LAVA)
    inside = [(row, column) for row in range(1, SIZE - 1) for column in range(1, SIZE - 1)]
    while True:
        squares = np.full((SIZE, SIZE), WALL, dtype=np.int8)
        squares[1:-1, 1:-1] = FLOOR
        chosen = [inside[index] for index in rng.choice(len(inside), size=2 + walls + lava, replace=False)]
        start, goal = chosen[0], chosen[1]
        squares[goal] = GOAL
        for square in chosen[2 : 2 + walls]:
            squares[square] = WALL
        for square in chosen[2 + walls :]:
            squares[square] = LAVA
        path = shortest_path(squares, start, goal)
        if path is not None:
            return squares, start, path


class GridLevelsEnv(gymnasium.Env[np.ndarray, np.int64]):
    """Observation: the room as a (9, 9, 3) uint8 image. Action: Discrete(4), up, right, down, left."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}
    task_space = TASK_SPACE

    def __init__(self, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"GridLevels renders only rgb_array frames, not {render_mode!r}")
        self.render_mode = render_mode
        self.observation_space = gymnasium.spaces.Box(0, 255, shape=(SIZE, SIZE, 3), dtype=np.uint8)
        self.action_space = gymnasium.spaces.Discrete(len(MOVES))
        self.squares, self.agent, _ = generate_room(0)
        self.steps = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        task = (options or {}).get("task")
        level = read_level(task) if task is not None else int(self.np_random.integers(*HELD_OUT_LEVELS))
        self.squares, self.agent, path = generate_room(level)
        self.steps = 0
        return self._observation(), {"level": level, "shortest_path": path}

    def step(self, action: np.int64) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        row_change, column_change = MOVES[int(action)]
        target = (self.agent[0] + row_change, self.agent[1] + column_change)
        if self.squares[target] != WALL:
            self.agent = target
        self.steps += 1
        reached = bool(self.squares[self.agent] == GOAL)
        terminated = reached or bool(self.squares[self.agent] == LAVA)
        truncated = not terminated and self.steps >= EPISODE_STEPS
        reward = 1.0 - 0.9 * self.steps / EPISODE_STEPS if reached else 0.0
        info = {"is_success": reached} if terminated or truncated else {}
        return self._observation(), reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """The observation enlarged to 16 pixels a square, big enough to watch in a GIF."""
        if self.render_mode != "rgb_array":
            return None
        return np.repeat(np.repeat(self._observation(), RENDER_SCALE, axis=0), RENDER_SCALE, axis=1)

    def _observation(self) -> np.ndarray:
        image = COLOURS[self.squares]
        image[self.agent] = COLOURS[AGENT]
        return image


def read_level(task: dict[str, Any]) -> int:
    """The task's level, or a ``ValueError`` if the task is not one whole number among the training levels."""
    if set(task) != {"level"}:
        raise ValueError(f"GridLevels tasks have exactly ['level'], got {sorted(task)}")
    level = task["level"]
    if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or not 0 <= level < TRAINING_LEVELS:
        raise ValueError(f"level must be a whole number from 0 to {TRAINING_LEVELS - 1}, got {level!r}")
    return int(level)
