"""``kuka-curriculum tune`` with real parts: a real teacher service, a real Ray cluster, the real training loop.

One tune of 2 tiny trials is interrupted (SIGINT) once its first trial has a checkpoint and then
finished with ``--resume``; its outputs serve several tests, and its best.json feeds ``train
--config``. A second tune whose every trial raises shows a failure is recorded and the tune goes
on. The budgets are two batches of 512 steps and episodes end within 150 steps, so the trials are short.
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from common.kuka.task_space import KUKA_TASK_SPACE
from kuka_curriculum import main
from learner.commands.config_file import read_config_file
from learner.core.checkpoint import latest_checkpoint, load_checkpoint
from learner.experiments.run_archive import metrics_records, resume_files, write_up_files
from learner.experiments.tune_space import SearchSpaceError, parse_search_space
from learner.job.teacher_probe import TeacherProbe, teacher_probe

TRIAL_FLAGS = ["--workers", "1", "--envs-per-worker", "2", "--ppo", "rollout_length=256", "--eval-episodes", "1"]
TOTAL_STEPS = 1024
TRIALS = 2
SEARCH_SPACE = {
    "learning_rate": {"loguniform": [1e-4, 1e-3]},
    "fit_rate": {"choice": [100, 250]},
    "max_episode_steps": {"randint": [100, 150]},
}
TIMEOUT_S = 300


@pytest.fixture(scope="module")
def probe() -> Iterator[TeacherProbe]:
    """A throwaway teacher service, which says what each kind takes."""
    with teacher_probe() as probe:
        yield probe


def _tune_command(out: Path, space: Path, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "kuka_curriculum",
        "tune",
        "--env",
        "KukaGrasp-v0",
        "--teacher",
        "alp-gmm",
        "--search-space",
        str(space),
        "--out",
        str(out),
        *TRIAL_FLAGS,
        *extra,
    ]


def _run(command: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT_S)


@pytest.fixture(scope="module")
def tuned(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """A 2-trial tune, interrupted after its first checkpoint, then resumed to its end: the first trial
    resumes from its checkpoint and the second starts afresh."""
    root = tmp_path_factory.mktemp("tune")
    space = root / "space.json"
    space.write_text(json.dumps(SEARCH_SPACE), encoding="utf-8")
    out = root / "out"
    budget = ("--trials", str(TRIALS), "--total-steps", str(TOTAL_STEPS), "--max-concurrent", "1")
    command = _tune_command(out, space, *budget)
    interrupted = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + TIMEOUT_S
    while not list(out.glob("runs/*/checkpoints/step_*.pt")):
        if interrupted.poll() is not None:
            pytest.fail(f"the tune ended before its first checkpoint:\n{interrupted.communicate()[0]}")
        assert time.monotonic() < deadline, "no trial wrote a checkpoint"
        time.sleep(0.2)
    checkpoints_at_interrupt = sorted(path.name for path in out.glob("runs/*/checkpoints/step_*.pt"))
    interrupted.send_signal(signal.SIGINT)
    first_output, _ = interrupted.communicate(timeout=TIMEOUT_S)
    resumed = _run(_tune_command(out, space, "--resume"))
    return {
        "out": out,
        "first": (interrupted.returncode, first_output),
        "checkpoints_at_interrupt": checkpoints_at_interrupt,
        "resumed": resumed,
    }


def test_an_interrupted_tune_says_how_to_resume(tuned):
    code, output = tuned["first"]
    assert tuned["checkpoints_at_interrupt"], "the interrupt came after a trial's first checkpoint"
    assert code == 130, output
    assert "--resume continues them" in output
    assert "dashboard:" in output and "running" in output  # the progress display


def test_the_resumed_tune_writes_every_trial_and_the_best(tuned):
    resumed, out = tuned["resumed"], tuned["out"]
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    report = json.loads((out / "trials.json").read_text(encoding="utf-8"))
    assert len(report["trials"]) == TRIALS
    assert report["searched"] == ["ppo.learning_rate", "teacher.fit_rate", "env.max_episode_steps"]
    statuses = {entry["status"] for entry in report["trials"]}
    assert statuses <= {"finished", "stopped early"} and "finished" in statuses
    for entry in report["trials"]:
        config = entry["config"]
        assert 1e-4 <= config["ppo.learning_rate"] <= 1e-3
        assert config["teacher.fit_rate"] in (100, 250)
        assert 100 <= config["env.max_episode_steps"] <= 150
        curve = entry["curve"]
        assert curve and all(0.0 <= point["success"] <= 1.0 for point in curve)
        assert [point["steps"] for point in curve] == sorted({point["steps"] for point in curve})
        if entry["status"] == "finished":
            assert entry["final"]["steps"] >= TOTAL_STEPS
        # Each trial trained its own run, with the settings it drew.
        trained = load_checkpoint(latest_checkpoint(out / entry["run_dir"])).config
        assert trained.ppo.learning_rate == config["ppo.learning_rate"]
        assert trained.teacher_params["fit_rate"] == config["teacher.fit_rate"]
        assert trained.max_episode_steps == config["env.max_episode_steps"]
    assert (out / "curves.png").read_bytes()[:4] == b"\x89PNG"

    best = json.loads((out / "best.json").read_text(encoding="utf-8"))
    chosen = next(entry for entry in report["trials"] if entry["trial"] == report["best"])
    assert chosen["status"] == "finished"
    assert best["ppo"] == {"rollout_length": 256, "learning_rate": chosen["config"]["ppo.learning_rate"]}
    assert best["teacher_params"] == {"fit_rate": chosen["config"]["teacher.fit_rate"]}
    assert best["max_episode_steps"] == chosen["config"]["env.max_episode_steps"]
    finished = [entry for entry in report["trials"] if entry["status"] == "finished"]
    assert chosen["final"]["success"] == max(entry["final"]["success"] for entry in finished)


def test_resume_continues_the_interrupted_trial_from_its_checkpoint(tuned):
    """A trial restarted from nothing would log its first iteration twice."""
    run_dirs = sorted(tuned["out"].glob("runs/*"))
    assert len(run_dirs) == TRIALS
    for run_dir in run_dirs:
        steps = [record["step"] for record in metrics_records(run_dir)]
        assert steps and steps.count(steps[0]) == 1, run_dir


def test_the_finished_tune_archives_its_trials_to_what_the_report_reads(tuned):
    """Metrics compressed, the final checkpoint alone; the rest stays on disk, out of git."""
    for run_dir in sorted(tuned["out"].glob("runs/*")):
        names = {path.name for path in run_dir.iterdir()}
        assert names & set(write_up_files()) == {"checkpoints", "metrics.jsonl.xz"}, run_dir
        assert names - set(write_up_files()) <= set(resume_files()), run_dir
        assert len(list((run_dir / "checkpoints").iterdir())) == 1, run_dir


def test_every_trial_had_its_curriculum_on_the_one_service(tuned):
    """The service the tune started kept its curricula in the tune directory: one per trial, as drawn."""
    import httpx

    from teacher_service.process import ServiceProcess

    out = tuned["out"]
    report = json.loads((out / "trials.json").read_text(encoding="utf-8"))
    service = ServiceProcess(out / "teacher.sqlite", log_path=out / "teacher-after.log").start(60)
    try:
        listed = httpx.get(f"{service.url}/api/v1/curricula", timeout=10).json()["curricula"]
    finally:
        service.stop(15)
    registered = {curriculum["name"]: curriculum["config"] for curriculum in listed}
    for entry in report["trials"]:
        config = registered[f"out-{entry['trial']}"]
        assert config["teacher"] == "alp-gmm"
        assert config["params"]["fit_rate"] == entry["config"]["teacher.fit_rate"]


def test_train_accepts_the_best_settings_and_flags_override_them(tuned, tmp_path):
    best_path = tuned["out"] / "best.json"
    best = read_config_file(best_path)
    run_dir = tmp_path / "run"
    trained = _run(
        [
            sys.executable,
            "-m",
            "kuka_curriculum",
            "train",
            "--config",
            str(best_path),
            "--total-steps",
            "512",
            "--eval-every",
            "0",
            "--ppo",
            "entropy_coef=0.01",
            "--envs-per-worker",
            "1",
            "--run-dir",
            str(run_dir),
        ]
    )
    assert trained.returncode == 0, trained.stdout + trained.stderr
    config = load_checkpoint(latest_checkpoint(run_dir)).config
    assert config.ppo.learning_rate == best.ppo["learning_rate"]
    assert config.teacher_params["fit_rate"] == best.teacher_params["fit_rate"]
    assert config.ppo.entropy_coef == 0.01 and config.envs_per_worker == 1


def test_a_trial_that_raises_is_recorded_failed_and_the_tune_goes_on(tmp_path):
    """0.9 is within random_task_ratio's bounds, but with the KUKA default target_task_ratio (0.2) the
    two add up to more than 1, which the service refuses when the trial registers its curriculum."""
    space = tmp_path / "space.yaml"
    space.write_text("random_task_ratio:\n  choice: [0.9]\n", encoding="utf-8")
    out = tmp_path / "out"
    result = _run(_tune_command(out, space, "--trials", "2", "--total-steps", "512", "--max-concurrent", "1"))
    assert result.returncode == 1, result.stdout + result.stderr
    report = json.loads((out / "trials.json").read_text(encoding="utf-8"))
    assert [entry["status"] for entry in report["trials"]] == ["failed", "failed"]
    assert all("random_task_ratio" in entry["error"] for entry in report["trials"])
    assert "no trial finished" in result.stdout
    assert not (out / "best.json").exists()


@pytest.mark.parametrize(
    ("space", "message"),
    [
        ({"learning_rat": {"uniform": [0.1, 0.2]}}, "learning_rat: no such setting"),
        ({"fit_rate": {"choice": [1, 100]}}, "fit_rate: cannot be 1: Input should be greater than or equal to 2"),
        ({"gamma": {"uniform": [0.9, 1.5]}}, "gamma: cannot be 1.5: gamma must be in [0, 1]"),
        ({"update_epochs": {"uniform": [2, 8]}}, "update_epochs: cannot be 2.0"),
        ({"max_episode_steps": {"randint": [0, 10]}}, "max_episode_steps: cannot be 0"),
        ({"learning_rate": {"loguniform": [0, 1e-3]}}, "learning_rate: loguniform needs low > 0"),
        ({"learning_rate": {"normal": [0, 1]}}, "learning_rate: unknown distribution 'normal'"),
        ({"teacher.gamma": {"choice": [0.5]}}, "teacher.gamma: no such setting; known parameters of alp-gmm"),
        # Two numbers within bounds, as a JSON schema sees them: only the service's validator refuses them.
        (
            {"reward_range": {"choice": [[0, 10], [10, 0]]}},
            "reward_range: cannot be (10, 0): Value error, reward_range must have low < high",
        ),
        ({"gamma": {"grid": [0.9, 1.5]}}, "gamma: cannot be 1.5: gamma must be in [0, 1]"),
        ({"gamma": {"grid": []}}, "gamma: grid takes a list of 1 to 100 values"),
    ],
)
def test_a_bad_search_space_names_the_setting(space, message, probe):
    with pytest.raises(SearchSpaceError) as refused:
        parse_search_space(space, probe.parameters("alp-gmm", KUKA_TASK_SPACE))
    assert message in str(refused.value)


def test_a_grid_runs_each_value_once_per_sample(probe):
    space = parse_search_space(
        {
            "lr_final_fraction": {"grid": [0.0, 0.3]},
            "state_dependent_std": {"grid": [False, True]},
            "learning_rate": {"loguniform": [1e-4, 1e-3]},
            "delta": {"grid": [0.5, 1.0]},
        },
        probe.parameters("currot", KUKA_TASK_SPACE),
    )
    assert space.grid_size == 8 and space.teacher == "currot"
    tune_space = space.param_space()
    assert tune_space["ppo.lr_final_fraction"] == {"grid_search": [0.0, 0.3]}
    assert tune_space["ppo.state_dependent_std"] == {"grid_search": [False, True]}
    assert tune_space["teacher.delta"] == {"grid_search": [0.5, 1.0]}


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--trials", "600"], "600 trials × 2 grid points is more than 1000 trials"),
        (["--total-steps", "4096", "--grace-steps", "8192"], "--grace-steps 8192 is beyond --total-steps 4096"),
    ],
)
def test_an_unbounded_or_impossible_schedule_is_refused_before_anything_trains(tmp_path, capsys, flags, message):
    space = tmp_path / "space.json"
    space.write_text(json.dumps({"fit_rate": {"grid": [100, 250]}}), encoding="utf-8")
    out = tmp_path / "out"
    assert main(["tune", "--search-space", str(space), "--out", str(out), *flags]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_a_refused_search_space_stops_the_command_before_anything_trains(tmp_path, capsys):
    space = tmp_path / "space.json"
    space.write_text(json.dumps({"fit_rate": {"randint": [100, 100_000_000]}}), encoding="utf-8")
    out = tmp_path / "out"
    assert main(["tune", "--search-space", str(space), "--out", str(out), "--trials", "2"]) == 2
    error = capsys.readouterr().err
    assert "fit_rate: cannot be 100000000: Input should be less than or equal to" in error and str(space) in error
    assert not out.exists()


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--teacher-param", "fit_rate=1"], "--teacher-param for alp-gmm: fit_rate: Input should be greater than or"),
        (["--teacher", "plr"], "plr on KukaGrasp-v0: Value error, parameter 'rnd_obj_x' is a float parameter"),
    ],
)
def test_a_curriculum_the_service_refuses_stops_the_tune_before_anything_trains(tmp_path, capsys, flags, message):
    """The fixed teacher parameters and the kind, on the family's task space, as the service judges them."""
    space = tmp_path / "space.json"
    space.write_text(json.dumps({"learning_rate": {"choice": [1e-4]}}), encoding="utf-8")
    out = tmp_path / "out"
    assert main(["tune", "--search-space", str(space), "--out", str(out), *flags]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1, error
    assert not out.exists()


def test_bakeoff_takes_the_settings_file_and_flags_override_it(tmp_path):
    from learner.experiments import bakeoff

    settings = tmp_path / "best.json"
    settings.write_text(
        json.dumps(
            {
                "teacher": "alp-gmm",
                "env": "KukaGraspHard-v1",
                "workers": 3,
                "envs_per_worker": 2,
                "ppo": {"rollout_length": 256, "learning_rate": 2e-4},
                "teacher_params": {"fit_rate": 100},
                "tune": {"trial": "x"},
            }
        ),
        encoding="utf-8",
    )
    parser = argparse.ArgumentParser()
    bakeoff.add_arguments(parser)
    args = parser.parse_args(["--config", str(settings), "--workers", "1", "--ppo", "learning_rate=5e-4"])
    assert (args.env, args.workers, args.envs_per_worker, args.rollout_length) == ("KukaGraspHard-v1", 1, 2, 256)
    assert dict(args.ppo) == {"learning_rate": 5e-4}  # the flag's pair comes later and wins
    assert args.teacher_params == [("alp-gmm.fit_rate", 100)]  # that teacher's only


def test_a_settings_file_with_an_unknown_key_is_refused_by_name(tmp_path, capsys):
    settings = tmp_path / "best.json"
    settings.write_text(json.dumps({"ppo": {"learning_rate": 1e-4}, "learning_rate": 1e-4}), encoding="utf-8")
    assert main(["train", "--config", str(settings), "--run-dir", str(tmp_path / "run")]) == 2
    assert "unknown key(s) learning_rate" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_the_progress_line_shows_trial_states_the_best_and_the_steps_trained(capsys, monkeypatch):
    from types import SimpleNamespace

    from learner.experiments import tune_report

    clock = [100.0]
    monkeypatch.setattr(tune_report.time, "monotonic", lambda: clock[0])
    progress = tune_report.TuneProgress("success", trials=2, total_steps=1000)
    first, second = SimpleNamespace(trial_id="a", status="RUNNING"), SimpleNamespace(trial_id="b", status="PENDING")
    progress.on_trial_result(0, [first, second], first, {"success": 0.25, "steps": 300.0})
    assert capsys.readouterr().out.strip() == (
        "[tune      0s] 1 running, 1 pending, 0 finished, 0 failed of 2 | best success so far: 0.25 (a at 300 steps)"
        " | 300 of at most 2_000 steps trained"
    )
    progress.on_trial_result(0, [first, second], first, {"success": 0.0, "steps": 400.0})
    assert capsys.readouterr().out == "", "nothing new to say, and not a minute since the last line"
    clock[0] += tune_report.PROGRESS_EVERY_S
    progress.on_trial_result(0, [first, second], first, {"success": 0.0, "steps": 500.0})
    assert capsys.readouterr().out.strip().endswith("| 500 of at most 2_000 steps trained")


def test_a_trial_that_trained_its_budget_is_finished_though_its_last_evaluation_came_earlier(tmp_path):
    from types import SimpleNamespace

    from learner.experiments.tune_report import FINISHED, trial_entry
    from learner.experiments.tune_settings import TuneSettings

    run_dir = tmp_path / "runs" / "t0"
    run_dir.mkdir(parents=True)
    records = [
        {"step": 4096, "eval/success_rate": 0.5, "eval/return": 1.0},
        {"step": 8192, "eval/success_rate": None},
    ]
    (run_dir / "metrics.jsonl").write_text("".join(json.dumps(record) + "\n" for record in records), encoding="utf-8")
    trial = SimpleNamespace(
        trial_id="t0", status="TERMINATED", last_result={"done": True, "steps": 8192.0}, config={}, error_file=None
    )
    entry = trial_entry(trial, TuneSettings(search_space={}, total_steps=8000), tmp_path / "runs", tmp_path)
    assert entry["status"] == FINISHED and entry["final"]["steps"] == 4096
