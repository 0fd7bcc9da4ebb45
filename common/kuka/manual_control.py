"""Drive the grasp environment by hand, to see what its actions, observation and reward mean.

Two modes, after the book's ``manual_control_kuka.py`` (chapter 14):

- ``gym``: every step is the environment's own ``step``: you steer the gripper's x/y and the wrist,
  the environment lowers the arm and grasps when it touches the tray, and the episode's reward and
  outcome are the ones an agent would get.
- ``free``: the environment's rules are set aside and you also drive the height and the fingers,
  through the same arm controller (``KukaArm.apply``) at the same speeds. There is no episode, so no
  reward: the outcome is whether the block is held above the height at which a grasp counts.

The loop here is pure: it reads ``Controls`` from any ``ControlSource`` (``SliderPanel`` reads
pybullet's sliders; tests pass fixed values) and hands a ``Report`` per step to a callback. Free mode
goes around ``step``, so it uses the environment's arm, physics client and observation directly; it
lives beside the environment for that reason.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Protocol

import numpy as np

from common.kuka.bullet import pybullet
from common.kuka.env import (
    CAMERA_DISTANCE,
    CAMERA_PITCH,
    CAMERA_TARGET,
    CAMERA_YAW,
    FINGER_OPENING,
    SUCCESS_BLOCK_Z,
    YAW_PER_ACTION,
    KukaGraspEnv,
)

HEIGHT_PER_ACTION = 0.001
"""How far (metres) free mode's full height slider moves the gripper's target in one step: twice the
environment's own descent per step, so the arm can be raised as well as lowered at a useful pace."""
SLIDER_READ_SECONDS = 0.1
"""How often (wall-clock seconds) ``SliderPanel`` reads its sliders; between reads the last values hold. Each
read waits for the window's next frame, which would hold the physics far below real time if done every step."""


class Mode(str, Enum):
    GYM = "gym"
    FREE = "free"


@dataclass(frozen=True)
class Controls:
    """One reading of the controls. ``x``, ``y``, ``wrist`` and ``height`` are speeds in [-1, 1], as an
    action's entries are; ``fingers`` is the opening (0 closed to ``FINGER_OPENING`` open, the
    environment's). ``height`` and ``fingers`` act in free mode only."""

    x: float = 0.0
    y: float = 0.0
    wrist: float = 0.0
    height: float = 0.0
    fingers: float = FINGER_OPENING
    reset: bool = False


class ControlSource(Protocol):
    def read(self) -> Controls | None:
        """The controls now, or None once the user has closed the window."""
        ...


@dataclass(frozen=True)
class Report:
    """What one step did. ``reward`` is the environment's (gym mode; None in free mode). ``outcome`` is
    set when something ended: in gym mode the episode ('grasped', 'missed' or 'time limit', after which
    the environment is reset); in free mode 'lifted' while the block is above the success height."""

    episode: int
    step: int
    observation: np.ndarray
    reward: float | None
    outcome: str | None
    episode_return: float


class ManualControl:
    """One environment driven by controls in one mode, with its episode count and return."""

    def __init__(self, env: KukaGraspEnv, mode: Mode, seed: int | None = None) -> None:
        self.env = env
        self.mode = mode
        self.episode = 0
        self._step = 0
        self._return = 0.0
        self.observation, _ = env.reset(seed=seed)

    def reset(self) -> None:
        """A new episode: the block placed again by the task, the arm at its start pose."""
        self.observation, _ = self.env.reset()
        self.episode += 1
        self._step = 0
        self._return = 0.0

    def step(self, controls: Controls) -> Report:
        if controls.reset:
            self.reset()
        self._step += 1
        if self.mode is Mode.GYM:
            return self._gym_step(controls)
        return self._free_step(controls)

    def _gym_step(self, controls: Controls) -> Report:
        action = np.array([controls.x, controls.y, controls.wrist], dtype=np.float32)
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._return += reward
        outcome = None
        if terminated:
            outcome = "grasped" if info["is_success"] else "missed"
        elif truncated:
            outcome = "time limit"
        report = Report(self.episode, self._step, observation, reward, outcome, self._return)
        self.observation = observation
        if outcome is not None:
            self.reset()
        return report

    def _free_step(self, controls: Controls) -> Report:
        env = self.env
        move = env._move_per_action()
        opening = min(max(controls.fingers, 0.0), FINGER_OPENING)
        x, y, wrist, height = np.clip([controls.x, controls.y, controls.wrist, controls.height], -1.0, 1.0).tolist()
        env._arm.apply(x * move, y * move, height * HEIGHT_PER_ACTION, wrist * YAW_PER_ACTION, opening)
        env._step_simulation()
        self.observation, block_z = env._observe()
        outcome = "lifted" if block_z > SUCCESS_BLOCK_Z else None
        return Report(self.episode, self._step, self.observation, None, outcome, self._return)


def drive(
    control: ManualControl,
    source: ControlSource,
    on_step: Callable[[Report], None],
    steps: int | None = None,
    seconds_per_step: float = 0.0,
) -> int:
    """Step ``control`` with what ``source`` reads until it has done ``steps`` steps (None: until the
    source closes), paced to at least ``seconds_per_step`` each (the environment's ``TIME_STEP`` plays in real time).
    Returns the number of steps done."""
    done = 0
    next_time = time.perf_counter()
    while steps is None or done < steps:
        controls = source.read()
        if controls is None:
            break
        on_step(control.step(controls))
        done += 1
        next_time += seconds_per_step
        pause = next_time - time.perf_counter()
        if pause > 0:
            time.sleep(pause)
        else:  # behind (a grasp runs ~1,100 physics steps in one): catch up from now, not in a burst
            next_time = time.perf_counter()
    return done


class SliderPanel:
    """pybullet's window as a ``ControlSource``: its sliders for the controls of ``mode`` and a reset
    button, with the camera aimed as the environment's ``rgb_array`` frames are. The sliders are read every
    ``SLIDER_READ_SECONDS``; a click on reset counts once."""

    def __init__(self, env: KukaGraspEnv, mode: Mode) -> None:
        client = self._client = env._client
        client.resetDebugVisualizerCamera(CAMERA_DISTANCE, CAMERA_YAW, CAMERA_PITCH, CAMERA_TARGET)
        self._sliders = {
            "x": client.addUserDebugParameter("x speed", -1.0, 1.0, 0.0),
            "y": client.addUserDebugParameter("y speed", -1.0, 1.0, 0.0),
            "wrist": client.addUserDebugParameter("wrist speed", -1.0, 1.0, 0.0),
        }
        if mode is Mode.FREE:
            self._sliders["height"] = client.addUserDebugParameter("height speed", -1.0, 1.0, 0.0)
            opening = FINGER_OPENING
            self._sliders["fingers"] = client.addUserDebugParameter("fingers opening", 0.0, opening, opening)
        # A parameter whose minimum exceeds its maximum is a button; reading it gives its click count.
        self._reset_button = client.addUserDebugParameter("reset", 1.0, 0.0, 0.0)
        self._clicks = 0.0
        self._controls = Controls()
        self._read_at = -math.inf

    def read(self) -> Controls | None:
        now = time.perf_counter()
        if now - self._read_at < SLIDER_READ_SECONDS:
            return self._controls
        self._read_at = now
        if not self._client.isConnected():
            return None
        try:
            values = {name: self._client.readUserDebugParameter(uid) for name, uid in self._sliders.items()}
            clicks = self._client.readUserDebugParameter(self._reset_button)
        except pybullet.error:  # the window closed between the two calls
            return None
        reset = clicks > self._clicks
        self._clicks = clicks
        self._controls = Controls(**values)
        return Controls(**values, reset=reset)


def describe(report: Report) -> str:
    """One line: the step, the observation by meaning, the reward and any outcome."""
    o = report.observation.tolist()
    line = (
        f"episode {report.episode} step {report.step:4d}  gripper xyz {o[0]:+.3f} {o[1]:+.3f} {o[2]:+.3f} m"
        f"  rpy {o[3]:+.2f} {o[4]:+.2f} {o[5]:+.2f} rad  block in gripper xy {o[6]:+.3f} {o[7]:+.3f} m"
        f" yaw {o[8]:+.2f} rad"
    )
    if report.reward is not None:
        line += f"  reward {report.reward:+.4f}"
    if report.outcome is not None:
        line += f"  -> {report.outcome}"
        if report.reward is not None:
            line += f" (return {report.episode_return:+.3f})"
    return line
