"""examples/sb3_pendulum_gravity.py: a classic-control environment that knows nothing of tasks.

The tasks reach the physics: two curricula hand out two different gravities and masses, and the
pendulum measurably swings and accelerates differently under each. Then the example trains SB3 PPO
on its own task space, registered over HTTP.
"""

from __future__ import annotations

import csv
import math

import gymnasium
import numpy as np
import pytest
from example_runner import TOKEN, curriculum_state, finish, start_example

from common.client.curriculum_wrapper import CurriculumRegistration, CurriculumWrapper
from common.client.task_space import Parameter, TaskSpace
from examples.sb3_pendulum_gravity import PENDULUM_TASK_SPACE, apply_pendulum_task

HORIZONTAL, BOTTOM = math.pi / 2, math.pi  # Pendulum-v1 measures its angle from upright


def fixed_task(gravity: float, mass: float) -> CurriculumRegistration:
    """A curriculum that always hands out this gravity and mass (the fixed teacher's hardest task)."""
    return CurriculumRegistration(
        "fixed",
        TaskSpace(
            [
                Parameter("gravity", 2.0, 12.0, hardest=gravity),
                Parameter("mass", 0.5, 1.5, hardest=mass),
            ]
        ),
    )


def quarter_swing_steps(env: gymnasium.Env) -> int:
    """Steps from rest at the horizontal, with no torque, until the pendulum passes the bottom."""
    env.unwrapped.state = np.array([HORIZONTAL, 0.0])
    for step in range(1, 200):
        env.step(np.zeros(1, dtype=np.float32))
        if env.unwrapped.state[0] >= BOTTOM:
            return step
    raise AssertionError("the pendulum never reached the bottom")


def spin_up_speed(env: gymnasium.Env) -> float:
    """Angular speed after one step of full torque from rest at the bottom (where gravity has no pull)."""
    env.unwrapped.state = np.array([BOTTOM, 0.0])
    env.step(np.full(1, 2.0, dtype=np.float32))
    return float(env.unwrapped.state[1])


def test_the_teachers_gravity_and_mass_change_the_pendulums_physics(teacher):
    measured = {}
    for gravity, mass in ((2.0, 0.5), (12.0, 1.5)):
        env = CurriculumWrapper(
            gymnasium.make("Pendulum-v1"),
            teacher.url,
            f"pendulum-g{gravity:g}",
            register=fixed_task(gravity, mass),
            apply_task=apply_pendulum_task,
            token=TOKEN,
        )
        _, info = env.reset(seed=0)
        assert info["task"] == {"gravity": gravity, "mass": mass}
        measured[gravity] = quarter_swing_steps(env), spin_up_speed(env)
        env.close()

    (low_g_steps, light_speed), (high_g_steps, heavy_speed) = measured[2.0], measured[12.0]
    # A pendulum's period goes as 1/sqrt(g): six times the gravity, 2.4 times faster.
    assert low_g_steps / high_g_steps == pytest.approx(math.sqrt(12.0 / 2.0), rel=0.25)
    # The same torque turns a mass three times lighter three times faster.
    assert light_speed / heavy_speed == pytest.approx(1.5 / 0.5, rel=0.01)


def test_sb3_ppo_trains_on_a_task_space_of_its_own(teacher, tmp_path):
    log_dir = tmp_path / "run"
    example = start_example(
        "sb3_pendulum_gravity.py",
        *("--teacher-url", teacher.url, "--total-steps", "4096", "--envs", "2", "--log-dir", str(log_dir)),
    )
    output = finish(example, timeout=300)
    assert f"watch the curriculum at {teacher.url}/curricula/pendulum-alp-gmm" in output

    episodes = []
    for path in sorted(log_dir.glob("env-*.monitor.csv")):
        with path.open() as file:
            next(file)
            episodes += list(csv.DictReader(file))
    assert len(episodes) == 4096 // 200, "Pendulum-v1's episodes last 200 steps"
    state = curriculum_state(teacher, "pendulum-alp-gmm")
    results = {result["task_id"]: result for result in state["recent_results"]}
    assert sorted(results) == sorted(episode["task_id"] for episode in episodes)
    for episode in episodes:
        assert results[episode["task_id"]]["reward"] == pytest.approx(float(episode["r"]), abs=1e-3)
    assert [p["name"] for p in state["curriculum"]["config"]["space"]] == list(PENDULUM_TASK_SPACE.names)
    gravities = [result["params"]["gravity"] for result in results.values()]
    assert max(gravities) - min(gravities) > 2.0, "the tasks vary"


def test_any_teacher_kind_with_its_own_parameters_drives_the_training(teacher, tmp_path):
    params = ("window=5", "min_episodes=5", "threshold=-2000", "steps=3")
    example = start_example(
        "sb3_pendulum_gravity.py",
        *("--teacher-url", teacher.url, "--total-steps", "1024", "--envs", "1", "--log-dir", str(tmp_path / "run")),
        *("--teacher", "manual", *[flag for param in params for flag in ("--teacher-param", param)]),
    )
    output = finish(example, timeout=300)
    assert f"watch the curriculum at {teacher.url}/curricula/pendulum-manual" in output

    state = curriculum_state(teacher, "pendulum-manual")
    assert state["curriculum"]["config"]["teacher"] == "manual"
    assert state["teacher"]["params"] | {"threshold": -2000.0, "window": 5, "steps": 3} == state["teacher"]["params"]
    assert state["curriculum"]["counters"]["results_received"] == 1024 // 200
    assert [(m["at_results"], m["from"], m["to"]) for m in state["teacher"]["moves"]] == [(5, 0, 1)], (
        "five episodes of the first lesson, all above -2000: the plan moves on"
    )
    assert {r["params"]["gravity"] for r in state["recent_results"]} == {PENDULUM_TASK_SPACE.easiest()["gravity"]}
