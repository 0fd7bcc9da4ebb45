"""``kuka-curriculum train`` refuses bad input and unreachable services at once, with a clear message."""

from __future__ import annotations

import contextlib
import json
import time

import pytest

from common.kuka import ENV_ID
from common.kuka.task_space import KUKA_TASK_SPACE
from kuka_curriculum import main
from learner.core.checkpoint import Counters, save_checkpoint
from learner.core.config import TrainConfig
from learner.core.policy import policy_spec_for
from learner.core.ppo import PPOLearner
from teacher_service.process import free_port


def test_a_bad_flag_is_refused_by_name(capsys):
    with pytest.raises(SystemExit) as stopped:
        main(["train", "--envs-per-worker", "0"])
    assert stopped.value.code == 2
    assert "--envs-per-worker: must be at least 1" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("flag", "message"),
    [
        ("--teacher-url", "cannot reach the teacher service at http://127.0.0.1:{port}"),
        ("--ray-address", "cannot reach Ray at '127.0.0.1:{port}'"),
    ],
)
def test_an_unreachable_service_fails_fast(tmp_path, capsys, flag, message):
    port = free_port()
    address = f"http://127.0.0.1:{port}" if flag == "--teacher-url" else f"127.0.0.1:{port}"
    started = time.monotonic()
    assert main(["train", flag, address, "--run-dir", str(tmp_path / "run")]) == 2
    assert time.monotonic() - started < 15
    assert message.format(port=port) in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_resume_needs_a_checkpoint_and_a_finished_run_is_not_overwritten(tmp_path, capsys):
    run_dir = tmp_path / "run"
    assert main(["train", "--resume", "--run-dir", str(run_dir)]) == 2
    assert "no checkpoint" in capsys.readouterr().err

    config = TrainConfig()
    learner = PPOLearner(policy_spec_for(ENV_ID, config.ppo), config.ppo, seed=0)
    save_checkpoint(run_dir, learner.state_dict(), Counters(iteration=1, steps=10), config)
    assert main(["train", "--run-dir", str(run_dir)]) == 2
    assert "pass --resume" in capsys.readouterr().err


def test_resume_if_exists_starts_a_new_run_or_continues_an_existing_one(tmp_path, capsys):
    run_dir = tmp_path / "run"
    unreachable_ray = ["--ray-address", f"127.0.0.1:{free_port()}"]  # stops the run right after the run-dir checks
    assert main(["train", "--resume-if-exists", "--run-dir", str(run_dir), *unreachable_ray]) == 2
    assert "cannot reach Ray" in capsys.readouterr().err

    config = TrainConfig(teacher="manual")
    learner = PPOLearner(policy_spec_for(ENV_ID, config.ppo), config.ppo, seed=0)
    save_checkpoint(run_dir, learner.state_dict(), Counters(iteration=1, steps=10), config)
    assert main(["train", "--resume-if-exists", "--run-dir", str(run_dir), *unreachable_ray]) == 2
    assert "cannot reach Ray" in capsys.readouterr().err

    with pytest.raises(SystemExit):
        main(["train", "--resume", "--resume-if-exists", "--run-dir", str(run_dir)])
    assert "not allowed with argument" in capsys.readouterr().err


@pytest.mark.parametrize("flag", ["--resume", "--resume-if-exists"])
def test_resuming_needs_the_run_directory(flag, capsys):
    assert main(["train", flag]) == 2
    assert f"{flag} needs --run-dir" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--ppo", "entropy=0.01"], "unknown PPO hyperparameter(s) entropy; known: rollout_length"),
        (["--ppo", "update_epochs=many"], "PPO hyperparameter update_epochs cannot be 'many'"),
        (["--ppo", "entropy_coef"], "expected NAME=VALUE, got 'entropy_coef'"),
        (["--edge-placement-share", "2"], "--edge-placement-share: must be between 0 and 1, got 2.0"),
        (["--edge-placement-share", "0.5"], "edge_placement_share needs a hard KUKA family"),
    ],
)
def test_a_bad_setting_is_refused_by_name(tmp_path, capsys, flags, message):
    with contextlib.suppress(SystemExit):
        assert main(["train", "--run-dir", str(tmp_path / "run"), *flags]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_a_teacher_parameter_the_teacher_refuses_is_reported_before_training(tmp_path, capsys):
    assert main(["train", "--teacher-param", "fit_rate=1", "--run-dir", str(tmp_path / "run")]) == 2
    error = capsys.readouterr().err
    assert "cannot register curriculum 'run'" in error and "fit_rate" in error


@pytest.mark.parametrize(("token", "reason"), [("change-me", "placeholder"), ("0123456789", "too few to be secret")])
def test_a_guessable_teacher_token_is_refused_before_anything_starts(tmp_path, capsys, monkeypatch, token, reason):
    monkeypatch.setenv("KC_TEACHER_TOKEN", token)
    assert main(["train", "--run-dir", str(tmp_path / "run")]) == 2
    error = capsys.readouterr().err
    assert error.startswith("kuka-curriculum train: error: KC_TEACHER_TOKEN ") and reason in error
    assert "secrets.token_urlsafe(32)" in error
    assert not (tmp_path / "run").exists(), "the refusal came after the run started"


def test_an_unknown_environment_is_refused_by_name(capsys):
    with pytest.raises(SystemExit) as stopped:
        main(["train", "--env", "KukaGrasp-v9"])
    assert stopped.value.code == 2
    assert "--env: unknown environment 'KukaGrasp-v9'; expected one of KukaGrasp-v0" in capsys.readouterr().err


def test_a_run_keeps_its_environment_when_resumed(tmp_path, capsys):
    run_dir = tmp_path / "run"
    config = TrainConfig()
    learner = PPOLearner(policy_spec_for(ENV_ID, config.ppo), config.ppo, seed=0)
    save_checkpoint(run_dir, learner.state_dict(), Counters(iteration=1, steps=10), config)
    assert main(["train", "--resume-if-exists", "--run-dir", str(run_dir), "--env", "KukaGraspHard-v0"]) == 2
    assert "trains on KukaGrasp-v0; choose another --run-dir for a run on KukaGraspHard-v0" in capsys.readouterr().err


def test_the_hard_family_registers_its_own_task_space(tmp_path, capsys):
    """The teacher sees all ten parameters: a fixed point given in the book's six is refused for lacking the rest."""
    run_dir = tmp_path / "run"
    book_point = json.dumps(KUKA_TASK_SPACE.hardest())
    flags = ["--env", "KukaGraspHard-v0", "--teacher", "fixed", "--teacher-param", f"point={book_point}"]
    assert main(["train", *flags, "--run-dir", str(run_dir)]) == 2
    error = capsys.readouterr().err
    assert "cannot register curriculum 'run'" in error
    assert all(name in error for name in ("obj_far", "shaping", "move_scale", "align_margin"))


def test_a_kind_the_service_does_not_know_is_refused_with_its_message_before_ray_starts(tmp_path, capsys):
    assert main(["train", "--teacher", "curious", "--run-dir", str(tmp_path / "run"), "--total-steps", "1"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("kuka-curriculum train: error: cannot register curriculum 'run'")
    assert "'curious'" in error and len(error.splitlines()) == 1
