"""The whole training job as a user runs it: real Ray, a real teacher service process, the CLI."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from common.client.schemas import API_PREFIX
from learner.core.checkpoint import latest_checkpoint, load_checkpoint
from learner.job.session import curriculum_name
from learner.job.teacher_process import local_teacher_service
from teacher_service.process import free_port

SMALL_RUN = [
    "--teacher",
    "random",
    "--workers",
    "2",
    "--envs-per-worker",
    "2",
    "--rollout-length",
    "250",
    "--max-episode-steps",
    "150",
    "--checkpoint-every",
    "2",
    "--eval-every",
    "2",
    "--eval-episodes",
    "2",
]
BATCH = 2 * 2 * 250
TIMEOUT_S = 240


def train_command(run_dir: Path, ray_address: str, *flags: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "kuka_curriculum",
        "train",
        *SMALL_RUN,
        "--run-dir",
        str(run_dir),
        "--ray-address",
        ray_address,
        *flags,
    ]


def train(run_dir: Path, ray_address: str, *flags: str) -> subprocess.CompletedProcess:
    command = train_command(run_dir, ray_address, *flags)
    done = subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT_S)
    assert done.returncode == 0, done.stdout + done.stderr
    return done


def metrics(run_dir: Path) -> list[dict]:
    path = run_dir / "metrics.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def results_received(teacher_url: str, run_dir: Path) -> int:
    info = httpx.get(f"{teacher_url}{API_PREFIX}/curricula/{curriculum_name(run_dir)}", timeout=10).json()
    return info["counters"]["results_received"]


def wait_for(condition, timeout_s: float = TIMEOUT_S, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.2)


def test_train_logs_checkpoints_reports_every_episode_resumes_and_stops_on_ctrl_c(tmp_path, ray_cluster):
    run_dir = tmp_path / "e2e"
    first = train(run_dir, ray_cluster, "--total-steps", "3000", "--resume-if-exists")  # nothing yet: a new run

    assert f"/curricula/{curriculum_name(run_dir)}" in first.stdout
    final = Path(first.stdout.strip().splitlines()[-1].removeprefix("final checkpoint:").strip())
    assert final == latest_checkpoint(run_dir)
    checkpoint = load_checkpoint(final)
    assert checkpoint.counters.steps == 3 * BATCH and checkpoint.counters.iteration == 3
    assert checkpoint.config.teacher == "random" and checkpoint.config.workers == 2

    records = metrics(run_dir)
    assert [r["step"] for r in records] == [BATCH, 2 * BATCH, 3 * BATCH]
    assert sum(r["train/episodes"] for r in records) == checkpoint.counters.episodes > 0
    # The evaluation of the second iteration's weights ran behind sampling, and is in that iteration's record.
    assert 0.0 <= records[1]["eval/success_rate"] <= 1.0 and records[1]["eval/return"] is not None
    assert "eval/return" not in records[0] and "eval/return" not in records[2]
    # The default loop: after the first batch, the workers sample one update behind the learner.
    assert [r["train/policy_lag"] for r in records] == [0.0, 1.0, 1.0] and checkpoint.config.loop == "async"
    events = EventAccumulator(str(run_dir / "tensorboard"))
    events.Reload()
    expected_tags = {"train/episode_reward", "loss/policy_loss", "eval/return", "perf/steps_per_second"}
    assert expected_tags <= set(events.Tags()["scalars"])
    assert [event.step for event in events.Scalars("loss/policy_loss")] == [BATCH, 2 * BATCH, 3 * BATCH]

    # Resume with a larger budget, then stop it the way a person would: Ctrl-C in its terminal.
    resumed = subprocess.Popen(
        train_command(run_dir, ray_cluster, "--total-steps", "1000000", "--resume"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    try:
        wait_for(lambda: len(metrics(run_dir)) >= 5, what="two iterations after resuming")
        os.killpg(resumed.pid, signal.SIGINT)
        output, _ = resumed.communicate(timeout=TIMEOUT_S)
    finally:
        resumed.kill()
    assert resumed.returncode == 128 + signal.SIGINT, output  # stopped before its budget: not done
    assert f"at step {3 * BATCH:_}" in output and "--resume continues the run" in output
    steps = [r["step"] for r in metrics(run_dir)]
    assert steps == [k * BATCH for k in range(1, len(steps) + 1)]
    checkpoint = load_checkpoint(latest_checkpoint(run_dir))
    assert Path(output.strip().splitlines()[-1].removeprefix("final checkpoint:").strip()) == checkpoint.path
    assert checkpoint.counters.steps == steps[-1] and checkpoint.counters.iteration == len(steps)
    assert checkpoint.counters.episodes == sum(r["train/episodes"] for r in metrics(run_dir))

    # The run's own teacher service kept its database in the run directory: start it again and ask.
    with local_teacher_service(run_dir) as teacher_url:
        expected = checkpoint.counters.episodes - checkpoint.counters.offline_episodes
        assert results_received(teacher_url, run_dir) == expected


def test_the_synchronous_loop_stays_on_policy(tmp_path, ray_cluster):
    run_dir = tmp_path / "sync"
    train(run_dir, ray_cluster, "--total-steps", str(2 * BATCH), "--loop", "sync")
    records = metrics(run_dir)
    assert [r["train/policy_lag"] for r in records] == [0.0, 0.0]
    assert records[1]["eval/episode_length"] > 0
    assert load_checkpoint(latest_checkpoint(run_dir)).config.loop == "sync"


def test_training_finishes_when_a_rollout_actor_is_killed_mid_run(tmp_path, ray_cluster):
    import ray

    run_dir = tmp_path / "fault"
    process = subprocess.Popen(
        train_command(run_dir, ray_cluster, "--total-steps", "4000", "--eval-every", "0"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        wait_for(lambda: metrics(run_dir), what="the first iteration")
        victim = f"{curriculum_name(run_dir)}-worker-0-0"
        ray.kill(ray.get_actor(victim, namespace="kuka-curriculum"), no_restart=True)
        output, _ = process.communicate(timeout=TIMEOUT_S)
    finally:
        process.kill()
    assert process.returncode == 0, output
    records = metrics(run_dir)
    assert records[-1]["step"] >= 4000
    assert records[-1]["workers/replacements"] >= 1
    assert load_checkpoint(latest_checkpoint(run_dir)).counters.worker_replacements >= 1


def test_a_teacher_outage_mid_run_loses_no_episode_result(tmp_path, ray_cluster):
    port = free_port()
    teacher_url = f"http://127.0.0.1:{port}"
    database = tmp_path / "teacher.sqlite"
    serve = [
        sys.executable,
        "-m",
        "kuka_curriculum",
        "serve",
        "--port",
        str(port),
        "--db",
        str(database),
        "--log-level",
        "warning",
    ]

    def start_teacher() -> subprocess.Popen:
        teacher = subprocess.Popen(serve, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wait_for(lambda: _healthy(teacher_url), timeout_s=60, what="the teacher service")
        return teacher

    run_dir = tmp_path / "outage"
    teacher = start_teacher()
    process = subprocess.Popen(
        train_command(run_dir, ray_cluster, "--total-steps", "5000", "--eval-every", "0", "--teacher-url", teacher_url),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        wait_for(lambda: metrics(run_dir), what="the first iteration")
        teacher.terminate()
        teacher.wait(30)
        # Two more iterations (2 x 250 steps per environment) outlast every episode that was running
        # when the teacher went down (150 steps at most): their results can only arrive after the restart.
        iterations_before = len(metrics(run_dir))
        wait_for(lambda: len(metrics(run_dir)) >= iterations_before + 2, what="training to go on without the teacher")
        teacher = start_teacher()
        output, _ = process.communicate(timeout=TIMEOUT_S)
        assert process.returncode == 0, output
        counters = load_checkpoint(latest_checkpoint(run_dir)).counters
        # Episodes played on offline assignments (no teacher task id) are not the teacher's to hear of.
        assert results_received(teacher_url, run_dir) == counters.episodes - counters.offline_episodes
    finally:
        process.kill()
        teacher.terminate()
        teacher.wait(30)


def _healthy(url: str) -> bool:
    try:
        return httpx.get(f"{url}/healthz", timeout=1).status_code == 200
    except httpx.HTTPError:
        return False
