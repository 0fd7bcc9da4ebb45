"""PointReach-v0: a point robot on a square table must reach a goal while a steady wind pushes it.

The task sets three things, each harder toward its ``hardest`` end:

- ``goal_distance`` (0.3 to 0.9): how far from the start the goal lies, in a direction drawn from the
  reset's seed. A far goal takes more steps, and the only reward is for reaching it, so a policy that has
  not learnt to head for the goal rarely finds a far one by chance.
- ``goal_radius`` (0.2 to 0.05): how close counts as reached. A full step moves 0.05 per axis, so at
  0.05 the robot must aim, not just pass by.
- ``wind`` (0 to 0.6): a steady push in a direction drawn from the seed, as a share of the robot's top
  speed. The robot does not see the wind, only its own velocity, so it must learn to lean into it.

The reward is 1 when the robot reaches the goal, which ends the episode, and 0 on every other step;
an episode that has not reached the goal after 50 steps is cut short. ``info["is_success"]`` says at the
end of every episode whether the goal was reached. A reset without a task plays the hardest task, the
one a run is evaluated on.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

TASK_SPACE: list[dict[str, Any]] = [
    {"name": "goal_distance", "low": 0.3, "high": 0.9, "easiest": 0.3, "hardest": 0.9},
    {"name": "goal_radius", "low": 0.05, "high": 0.2, "easiest": 0.2, "hardest": 0.05},
    {"name": "wind", "low": 0.0, "high": 0.6, "easiest": 0.0, "hardest": 0.6},
]
"""The task space in the JSON form the teacher service registers; the environment needs nothing else."""

HARDEST_TASK = {parameter["name"]: parameter["hardest"] for parameter in TASK_SPACE}

EPISODE_STEPS = 50
STEP_SIZE = 0.05
"""How far a full action moves the robot along each axis in one step."""
TABLE = 1.0
"""The robot stays inside [-TABLE, TABLE] on both axes; it starts at the centre."""

FRAME_PIXELS = 96
BACKGROUND = np.array([245, 245, 240], dtype=np.uint8)
GOAL_COLOUR = np.array([40, 170, 70], dtype=np.uint8)
ROBOT_COLOUR = np.array([30, 90, 220], dtype=np.uint8)
ROBOT_DRAWN_RADIUS = 0.04


def read_task(task: dict[str, Any]) -> dict[str, float]:
    """The task's values, or a ``ValueError`` naming what is missing, unknown or out of bounds (a curriculum
    whose task space does not fit this environment is refused at its first reset, not silently ignored)."""
    names = [parameter["name"] for parameter in TASK_SPACE]
    unknown = sorted(set(task) - set(names))
    missing = [name for name in names if name not in task]
    if unknown or missing:
        raise ValueError(f"PointReach tasks have exactly {names}; unknown {unknown}, missing {missing}")
    values = {}
    for parameter in TASK_SPACE:
        value = float(task[parameter["name"]])
        if not parameter["low"] <= value <= parameter["high"]:
            raise ValueError(f"{parameter['name']}={value} is outside [{parameter['low']}, {parameter['high']}]")
        values[parameter["name"]] = value
    return values


def _direction(angle: float) -> np.ndarray:
    return np.array([np.cos(angle), np.sin(angle)])


class PointReachEnv(gymnasium.Env[np.ndarray, np.ndarray]):
    """Observation: the robot's position, the goal's offset from it and the robot's last velocity (in full
    steps), six floats. Action: the push along x and y, each in [-1, 1]."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}
    task_space = TASK_SPACE

    def __init__(self, render_mode: str | None = None) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"PointReach renders only rgb_array frames, not {render_mode!r}")
        self.render_mode = render_mode
        bound = np.array([TABLE, TABLE, 2 * TABLE, 2 * TABLE, 2.0, 2.0], dtype=np.float32)
        self.observation_space = gymnasium.spaces.Box(-bound, bound, dtype=np.float32)
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.task = dict(HARDEST_TASK)
        self.position = np.zeros(2)
        self.velocity = np.zeros(2)
        self.goal = np.zeros(2)
        self.wind = np.zeros(2)
        self.steps = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        task = (options or {}).get("task")
        self.task = read_task(task) if task is not None else dict(HARDEST_TASK)
        goal_angle, wind_angle = self.np_random.uniform(0.0, 2 * np.pi, size=2)
        self.position = np.zeros(2)
        self.velocity = np.zeros(2)
        self.goal = self.task["goal_distance"] * _direction(goal_angle)
        self.wind = self.task["wind"] * STEP_SIZE * _direction(wind_angle)
        self.steps = 0
        return self._observation(), {"task": dict(self.task)}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        push = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0) * STEP_SIZE
        moved_to = np.clip(self.position + push + self.wind, -TABLE, TABLE)
        self.velocity = (moved_to - self.position) / STEP_SIZE
        self.position = moved_to
        self.steps += 1
        reached = bool(np.linalg.norm(self.goal - self.position) <= self.task["goal_radius"])
        truncated = not reached and self.steps >= EPISODE_STEPS
        info = {"is_success": reached} if reached or truncated else {}
        return self._observation(), float(reached), reached, truncated, info

    def render(self) -> np.ndarray | None:
        """A top view of the table: the goal's reach as a green disc, the robot as a blue dot."""
        if self.render_mode != "rgb_array":
            return None
        centres = (np.arange(FRAME_PIXELS) + 0.5) / FRAME_PIXELS * 2 * TABLE - TABLE
        x, y = np.meshgrid(centres, centres[::-1])  # the frame's first row is the table's far edge
        frame = np.broadcast_to(BACKGROUND, (FRAME_PIXELS, FRAME_PIXELS, 3)).copy()
        frame[np.hypot(x - self.goal[0], y - self.goal[1]) <= self.task["goal_radius"]] = GOAL_COLOUR
        frame[np.hypot(x - self.position[0], y - self.position[1]) <= ROBOT_DRAWN_RADIUS] = ROBOT_COLOUR
        return frame

    def _observation(self) -> np.ndarray:
        return np.concatenate([self.position, self.goal - self.position, self.velocity]).astype(np.float32)
