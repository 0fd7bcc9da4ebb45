"""Manual control's loop, in both modes, on a real environment without a window."""

from __future__ import annotations

import numpy as np
import pytest

from common.kuka.env import KukaGraspEnv
from common.kuka.manual_control import Controls, ManualControl, Mode, Report, describe, drive
from common.kuka.task_space import KUKA_TASK_SPACE


class Script:
    """A control source that plays a list of controls, then closes as a window would."""

    def __init__(self, *controls: Controls) -> None:
        self._controls = list(controls)

    def read(self) -> Controls | None:
        return self._controls.pop(0) if self._controls else None


@pytest.fixture
def easiest_env():
    env = KukaGraspEnv(task=KUKA_TASK_SPACE.easiest())
    yield env
    env.close()


def test_gym_mode_plays_the_environments_episode_and_starts_the_next(easiest_env):
    control = ManualControl(easiest_env, Mode.GYM, seed=0)
    reports: list[Report] = []
    done = drive(control, Script(*[Controls()] * 300), reports.append)

    assert done == 300
    ended = [report for report in reports if report.outcome is not None]
    assert ended, "untouched sliders on the easiest task lower the arm onto the block"
    first = ended[0]
    assert first.outcome == "grasped" and first.episode == 0
    assert all(report.reward is not None for report in reports)
    assert first.episode_return == pytest.approx(sum(r.reward for r in reports[: reports.index(first) + 1]))
    assert first.episode_return > 5.0, "a grasp pays the success bonus"
    after = reports[reports.index(first) + 1]
    assert after.episode == 1 and after.step == 1, "the environment was reset after the outcome"
    assert "-> grasped (return +" in describe(first)


def test_gym_mode_steers_x_and_y_with_the_sliders_while_the_environment_descends():
    env = KukaGraspEnv()  # the hardest task starts high: 100 steps stay far above the tray
    try:
        ends = {}
        for name, controls in {"still": Controls(), "y+": Controls(y=1.0), "x-": Controls(x=-1.0)}.items():
            control = ManualControl(env, Mode.GYM, seed=0)
            start = control.observation.copy()
            drive(control, Script(*[controls] * 100), lambda report: None)
            ends[name] = control.observation
    finally:
        env.close()
    assert ends["y+"][1] > ends["still"][1] + 0.05, "y speed +1 moves the gripper left"
    assert ends["x-"][0] < ends["still"][0] - 0.02, "x speed -1 moves the gripper back"
    assert ends["still"][2] < start[2] - 0.02, "the environment lowers the arm meanwhile"


def test_free_mode_descends_grasps_and_lifts_the_block_by_hand(easiest_env):
    control = ManualControl(easiest_env, Mode.FREE, seed=0)
    start_z = float(control.observation[2])
    reports: list[Report] = []
    down = [Controls(height=-0.5)] * 96
    close = [Controls(fingers=0.0)] * 100
    lift = [Controls(height=1.0, fingers=0.0)] * 800
    drive(control, Script(*down, *close, *lift), reports.append)

    assert all(report.reward is None for report in reports), "free mode has no reward"
    assert reports[95].observation[2] < start_z - 0.02, "height -0.5 lowers the gripper"
    lifted = [report for report in reports if report.outcome == "lifted"]
    assert lifted, "closed fingers raised with the height slider carry the block up"
    assert lifted[0].step > len(down) + len(close)
    assert "reward" not in describe(lifted[0]) and describe(lifted[0]).endswith("-> lifted")


def test_reset_restarts_the_episode_and_a_closed_source_stops(easiest_env):
    control = ManualControl(easiest_env, Mode.GYM, seed=0)
    start = control.observation.copy()
    reports: list[Report] = []
    done = drive(control, Script(*[Controls(x=1.0)] * 30, Controls(reset=True)), reports.append)

    assert done == 31
    assert reports[-1].episode == 1 and reports[-1].step == 1
    np.testing.assert_allclose(reports[-1].observation[:3], start[:3], atol=0.01)
