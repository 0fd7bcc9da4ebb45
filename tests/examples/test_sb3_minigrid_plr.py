"""examples/sb3_minigrid_plr.py: SB3 PPO on MiniGrid levels chosen by PLR, with each episode's positive
value loss sent as its score by a callback, and without it the teacher's fallback."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from example_runner import curriculum_state, finish, start_example

pytest.importorskip("minigrid")

from examples.sb3_minigrid_plr import minigrid_env  # noqa: E402  # needs minigrid


def test_the_level_is_the_reset_seed() -> None:
    env = minigrid_env("MiniGrid-DoorKey-5x5-v0")
    first, _ = env.reset(options={"task": {"level": 7}})
    other, _ = env.reset(options={"task": {"level": 8}})
    again, _ = env.reset(options={"task": {"level": 7}})
    assert np.array_equal(first, again) and not np.array_equal(first, other)
    assert isinstance(env.observation_space, gymnasium.spaces.Box) and env.observation_space.shape == (147,)


@pytest.mark.parametrize("scores", [True, False])
def test_ppo_trains_on_plr_levels_and_each_result_carries_its_score(teacher, tmp_path, scores: bool) -> None:
    name = f"minigrid-{'scored' if scores else 'unscored'}"
    flags = ["--curriculum", name, "--levels", "50", "--total-steps", "3000", "--eval-episodes", "3"]
    flags += ["--log-dir", str(tmp_path), "--envs", "2"] + ([] if scores else ["--no-scores"])
    output = finish(start_example("sb3_minigrid_plr.py", "--teacher-url", teacher.url, *flags), timeout=300)
    assert "held-out success" in output

    state = curriculum_state(teacher, name)
    assert state["curriculum"]["config"]["teacher"] == "plr"
    assert state["curriculum"]["config"]["space"] == [
        {"name": "level", "type": "integer", "low": 0, "high": 49, "hardest": None, "easiest": None}
    ]
    results = state["recent_results"]
    assert results and all(isinstance(r["params"]["level"], int) for r in results)
    if scores:
        assert all(r["score"] is not None and r["score"] >= 0 for r in results), "every episode sent its score"
    else:
        assert all(r["score"] is None for r in results), "without the callback the teacher falls back"
    assert state["teacher"]["scored_levels"] > 0
