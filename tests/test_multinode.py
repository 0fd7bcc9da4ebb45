"""The docker-compose topology without Docker: every role its own process on localhost.

A Ray head and a Ray worker node (``ray start``, each with its own temp dir and ports), the teacher
service (``kuka-curriculum serve``) and a short training run (``kuka-curriculum train``) that
reaches both by address, as the learner container does. Each node offers one CPU and the run asks
for two rollout actors, so one of them has to be placed on the worker node.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import httpx
import pytest

from common.client.schemas import API_PREFIX
from teacher_service.process import free_port

pytestmark = [pytest.mark.multinode, pytest.mark.timeout(420)]

BIN = Path(sys.executable).parent
TOKEN = "multinode-test-token"
READY_TIMEOUT_S = 90.0
TRAIN_TIMEOUT_S = 300.0
STOP_TIMEOUT_S = 45.0
RAY_READY_LINE = "This command will now block forever"
"""What ``ray start --block`` prints once its node is up and registered with the head."""


def process_environment(teacher_token: str | None = None) -> dict[str, str]:
    """The environment of one role; like the containers, only the teacher and the learner get the token.

    Ray's token authentication is pinned off, as in the containers: left unset, a head started
    here turns it on by itself whenever an earlier ``ray.init()`` left ``~/.ray/auth_token``
    behind, and the worker node, which does not, is then refused. A stray RAY_ADDRESS would
    misdirect every process, so it goes.
    """
    environment = {name: value for name, value in os.environ.items() if not name.startswith(("RAY_", "KC_"))}
    environment.update({"RAY_AUTH_MODE": "disabled", "PYTHONUNBUFFERED": "1"})
    if teacher_token is not None:
        environment["KC_TEACHER_TOKEN"] = teacher_token
    return environment


def launch(command: list[str], log_path: Path, environment: dict[str, str]) -> subprocess.Popen:
    """Start a process in a session of its own, so stopping it reaches every child it spawned."""
    with log_path.open("wb") as log:
        return subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=environment, start_new_session=True)


def stop(process: subprocess.Popen) -> None:
    """SIGTERM to the command alone, so it shuts its own children down in order (a Ray node drains
    through its head, which must still be up); SIGKILL to its whole session if that takes too long."""
    process.terminate()
    try:
        process.wait(STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()


def wait_for(ready: Callable[[], bool], process: subprocess.Popen, log_path: Path, what: str) -> None:
    deadline = time.monotonic() + READY_TIMEOUT_S
    while time.monotonic() < deadline:
        if process.poll() is not None:
            pytest.fail(
                f"{what} exited with code {process.returncode}:\n{log_path.read_text(errors='replace')[-3000:]}"
            )
        if ready():
            return
        time.sleep(0.5)
    pytest.fail(f"{what} was not ready within {READY_TIMEOUT_S:.0f} s:\n{log_path.read_text(errors='replace')[-3000:]}")


def processes_mentioning(text: str) -> dict[int, str]:
    """Live processes whose command line contains ``text`` (Ray's processes name their node's temp dir)."""
    found = {}
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            command = cmdline.read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if text in command:
            found[int(cmdline.parent.name)] = command.strip()
    return found


def survivors_of(text: str) -> dict[int, str]:
    deadline = time.monotonic() + STOP_TIMEOUT_S
    while (survivors := processes_mentioning(text)) and time.monotonic() < deadline:
        time.sleep(0.5)
    return survivors


def actors_logged_on(node_temp_dir: Path, actor_class: str) -> int:
    """Worker processes on this node that hosted ``actor_class``: Ray heads each actor's log with its name."""
    logs = node_temp_dir.glob("session_*/logs/worker-*.out")
    return sum(f":actor_name:{actor_class}" in log.read_text(errors="replace") for log in logs)


@pytest.fixture
def workspace() -> Iterator[Path]:
    """Holds every process's files; once the others are torn down, nothing may still run from it.

    A short path: Ray's unix sockets live under each node's temp dir and must stay within 107 bytes.
    """
    with tempfile.TemporaryDirectory(prefix="kc-multinode-") as directory:
        yield Path(directory)
        survivors = survivors_of(directory)
        for pid in survivors:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        assert not survivors, f"still running after teardown: {list(survivors.values())}"


@pytest.fixture
def ray_head(workspace: Path) -> Iterator[tuple[str, Path]]:
    temp_dir, log_path, port = workspace / "head", workspace / "ray-head.log", free_port()
    process = launch(
        [
            str(BIN / "ray"),
            "start",
            "--head",
            f"--port={port}",
            f"--temp-dir={temp_dir}",
            f"--ray-client-server-port={free_port()}",
            "--num-cpus=1",
            "--include-dashboard=false",
            "--disable-usage-stats",
            "--block",
        ],
        log_path,
        process_environment(),
    )
    try:
        wait_for(lambda: RAY_READY_LINE in log_path.read_text(errors="replace"), process, log_path, "the Ray head")
        yield f"127.0.0.1:{port}", temp_dir
    finally:
        stop(process)


@pytest.fixture
def ray_worker_node(workspace: Path, ray_head: tuple[str, Path]) -> Iterator[Path]:
    head_address, _ = ray_head
    temp_dir, log_path = workspace / "worker", workspace / "ray-worker.log"
    process = launch(
        [
            str(BIN / "ray"),
            "start",
            f"--address={head_address}",
            f"--temp-dir={temp_dir}",
            "--num-cpus=1",
            "--disable-usage-stats",
            "--block",
        ],
        log_path,
        process_environment(),
    )
    try:
        wait_for(
            lambda: RAY_READY_LINE in log_path.read_text(errors="replace"), process, log_path, "the Ray worker node"
        )
        yield temp_dir
    finally:
        stop(process)


@pytest.fixture
def teacher_url(workspace: Path) -> Iterator[str]:
    log_path, port = workspace / "teacher.log", free_port()
    url = f"http://127.0.0.1:{port}"
    process = launch(
        [
            str(BIN / "kuka-curriculum"),
            "serve",
            "--host=127.0.0.1",
            f"--port={port}",
            f"--db={workspace / 'teacher.sqlite3'}",
        ],
        log_path,
        process_environment(TOKEN),
    )

    def healthy() -> bool:
        try:
            return httpx.get(f"{url}/healthz", timeout=1.0).status_code == 200
        except httpx.HTTPError:
            return False

    try:
        wait_for(healthy, process, log_path, "the teacher service")
        yield url
    finally:
        stop(process)


def test_training_spreads_rollout_actors_over_ray_nodes(
    workspace: Path, ray_head: tuple[str, Path], ray_worker_node: Path, teacher_url: str
) -> None:
    head_address, head_temp_dir = ray_head
    run_dir = workspace / "run"
    # The address a person's browser would use, unlike the one the learner is given.
    public_url = teacher_url.replace("127.0.0.1", "localhost")
    train = subprocess.run(
        [
            str(BIN / "kuka-curriculum"),
            "train",
            "--teacher=alp-gmm",
            "--total-steps=3000",
            "--workers=2",
            "--envs-per-worker=2",
            "--rollout-length=256",
            "--max-episode-steps=200",
            "--eval-every=0",
            "--seed=0",
            f"--run-dir={run_dir}",
            f"--teacher-url={teacher_url}",
            f"--public-url={public_url}",
            f"--ray-address={head_address}",
        ],
        env=process_environment(TOKEN),
        capture_output=True,
        text=True,
        timeout=TRAIN_TIMEOUT_S,
    )
    assert train.returncode == 0, f"train failed:\n{train.stdout[-3000:]}\n{train.stderr[-3000:]}"

    final_checkpoint = Path(train.stdout.split("final checkpoint:")[-1].strip())
    assert final_checkpoint.is_file() and final_checkpoint.is_relative_to(run_dir)

    placed = {
        "head": actors_logged_on(head_temp_dir, "RolloutWorker"),
        "worker node": actors_logged_on(ray_worker_node, "RolloutWorker"),
    }
    assert all(placed.values()), f"rollout actors per node: {placed}"

    [curriculum] = httpx.get(f"{teacher_url}{API_PREFIX}/curricula", timeout=5.0).json()["curricula"]
    assert curriculum["counters"]["results_received"] > 0, "the teacher heard of no finished episode"

    dashboard = f"{public_url}/curricula/{curriculum['name']}"
    assert f"dashboard:     {dashboard}\n" in train.stdout
    assert httpx.get(dashboard, timeout=5.0).status_code == 200
