"""A user's environment, which the project has never seen, trains, evaluates and renders from ``--env
module:EnvId`` (docs/own-environment.md): ``examples.own_env``'s box-task ``PointReach-v0`` (an MLP and a
Gaussian, under ALP-GMM) and its image-level ``GridLevels-v0`` (a CNN and a categorical head, under PLR), and an
environment that breaks the contract is refused in one line with exit code 2; a bake-off runs on one too.
PointReach's run also takes ``--policy-choice validated``, whose choice evaluate then plays."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import pytest

from kuka_curriculum import main
from learner.core.checkpoint import latest_checkpoint, load_checkpoint
from learner.core.policy import policy_spec_for
from learner.evaluation.selection import RECORD, recorded_choice

ROOT = Path(__file__).resolve().parents[2]
SMALL_RUN = ["--total-steps", "2048", "--workers", "1", "--envs-per-worker", "2", "--rollout-length", "256"]


@pytest.fixture(autouse=True)
def from_the_checkout(monkeypatch: pytest.MonkeyPatch) -> None:
    """A user runs the commands beside their module: here the checkout, which holds ``examples/``."""
    monkeypatch.chdir(ROOT)


VALIDATED = ["--policy-choice", "validated", "--checkpoint-every", "1"]
"""A checkpoint every iteration of 512 steps, so the second half of 2,048 holds two candidates."""


@pytest.mark.parametrize(
    ("env_id", "teacher", "task", "image", "categorical", "flags"),
    [
        ("examples.own_env:PointReach-v0", "alp-gmm", "hardest task", False, False, VALIDATED),
        ("examples.own_env:GridLevels-v0", "plr", "held-out levels", True, True, []),
    ],
)
def test_a_users_environment_trains_evaluates_and_renders(
    tmp_path, capsys, ray_cluster, env_id, teacher, task, image, categorical, flags
) -> None:
    run_dir = tmp_path / "run"
    command = [sys.executable, "-m", "kuka_curriculum", "train", "--env", env_id, "--teacher", teacher]
    command += ["--run-dir", str(run_dir), "--ray-address", ray_cluster, *SMALL_RUN, *flags]
    trained = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert trained.returncode == 0, trained.stderr[-3000:]
    checkpoint = load_checkpoint(latest_checkpoint(run_dir))
    assert checkpoint.config.env == env_id and checkpoint.counters.steps >= 2048
    spec = policy_spec_for(env_id, checkpoint.config.ppo)
    assert (spec.image_shape is not None, spec.categorical) == (image, categorical)
    chosen = recorded_choice(run_dir)
    if flags:  # the candidates: the first checkpoints at or after 1,024 and 1,194 steps (1,024 and 1,536), the last
        record = json.loads((run_dir / RECORD).read_text())
        assert [each["steps"] for each in record["candidates"]] == [1024, 1536, 2048]
        assert chosen is not None and f"validated policy: {chosen.path.name}" in trained.stdout
    else:
        assert chosen is None and not (run_dir / RECORD).exists()

    assert main(["evaluate", str(run_dir), "--episodes", "4", "--processes", "1"]) == 0
    evaluated = capsys.readouterr().out
    assert f"{env_id}, {task}, 4 episodes" in evaluated
    if chosen is not None:
        assert f"{chosen.path} (alp-gmm, {chosen.steps:_} steps, the run's validated policy)" in evaluated

    film = tmp_path / "policy.gif"
    assert main(["render", str(run_dir), "--out", str(film), "--episodes", "2"]) == 0
    frames = iio.imread(film, index=None)
    # each episode films its first frame and one per step; a GridLevels episode can end at its first step, in lava
    assert frames.shape[0] >= 2 * 2 and frames.shape[1] >= 240  # the small frames enlarged so the labels fit


@pytest.mark.parametrize(
    ("env_id", "message"),
    [
        ("no_such_module:Task-v0", "cannot import no_such_module (No module named 'no_such_module')"),
        ("examples.own_env:Unregistered-v0", "add gymnasium.register(id='Unregistered-v0', entry_point=...)"),
        ("gymnasium.envs.classic_control:CartPole-v1", "the environment has no task_space attribute; add one"),
    ],
)
def test_an_environment_that_breaks_the_contract_is_one_line_and_exit_2(tmp_path, capsys, env_id, message) -> None:
    assert main(["train", "--env", env_id, "--run-dir", str(tmp_path / "run")]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and len(captured.err.strip().splitlines()) == 1
    assert "Traceback" not in captured.err and not (tmp_path / "run").exists()


def test_a_kind_that_does_not_fit_the_space_is_refused_with_the_services_message(tmp_path, capsys) -> None:
    env_id = "examples.own_env:GridLevels-v0"
    assert main(["train", "--env", env_id, "--teacher", "covar-gmm", "--run-dir", str(tmp_path / "run")]) == 2
    assert "the covar-gmm teacher takes float parameters only" in capsys.readouterr().err


def test_a_setting_the_network_cannot_take_is_one_line_before_anything_starts(tmp_path, capsys) -> None:
    flags = ["--env", "examples.own_env:GridLevels-v0", "--teacher", "plr", "--ppo", "critic_task_inputs=true"]
    assert main(["train", *flags, "--run-dir", str(tmp_path / "run")]) == 2
    error = capsys.readouterr().err.strip()
    assert "a critic that reads the task needs a flat observation" in error and len(error.splitlines()) == 1
    assert not (tmp_path / "run").exists()


def test_a_bakeoff_runs_on_a_users_environment(tmp_path, ray_cluster) -> None:
    out = tmp_path / "bakeoff"
    flags = ["--teachers", "random", "--seeds", "1", "--total-steps", "512", "--workers", "1", "--envs-per-worker", "2"]
    flags += ["--rollout-length", "128", "--curve-episodes", "2", "--eval-episodes", "4", "--eval-processes", "1"]
    env_id = "examples.own_env:PointReach-v0"
    assert main(["bakeoff", "--out", str(out), "--ray-address", ray_cluster, "--env", env_id, *flags]) == 0
    results = json.loads((out / "results.json").read_text())
    assert results["evaluation"]["env"] == env_id and results["scripted"] is None
    assert results["teachers"][0]["teacher"] == "random" and (out / "results.md").exists()
