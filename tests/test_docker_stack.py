"""The real stack under a real Docker engine, used the way a person on a workstation uses it.

The image is built from this checkout, ``docker-compose up`` starts the teacher, a Ray head, two Ray
worker containers, the learner and TensorBoard, and a short training run goes through it while the
test kills the teacher's process and, in a second run, a whole worker container. The first run has
its token in ``.env``; the second has no ``.env`` at all (its few settings in the shell's environment,
as ``TOTAL_STEPS=... docker compose up`` gives them), so the stack makes its own token.

What these machines lack is stood in for, as an air-gapped lab would: Docker Hub is unreachable, so
the base image is a Debian rootfs made with ``debootstrap`` and ``docker import``; the wheels come
from a wheelhouse served on the loopback (``PIP_FIND_LINKS`` with ``PIP_NO_INDEX=1``, the build that
docs/deployment.md describes), filled once with ``pip download`` of the lock, requirements.txt.

The engine is the test's own: ``dockerd`` on a private socket, stopped at the end, with its data
root (the layer cache) and the wheelhouse in ``KC_DOCKER_CACHE`` (default
``/var/tmp/kuka-curriculum-docker``), kept between runs so that a rebuild reuses every unchanged
layer. It needs root, ``dockerd``, ``debootstrap`` and ``docker-compose``; ``.ci/run`` installs them.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from common.client.schemas import API_PREFIX
from teacher_service.process import free_port

pytestmark = [pytest.mark.docker, pytest.mark.timeout(1500)]

ROOT = Path(__file__).resolve().parents[1]
CACHE = Path(os.environ.get("KC_DOCKER_CACHE", "/var/tmp/kuka-curriculum-docker"))
BASE_IMAGE = "kuka-curriculum-standin-base:bookworm"
IMAGE = "kuka-curriculum:latest"
"""The name docker-compose.yml gives the image, so ``up --no-build`` runs the one built here."""
PROJECT = "kcstacktest"
TOKEN = "docker-stack-test-token"
TEACHER_URL = "http://127.0.0.1:8000"
PUBLISHED_PORTS = {"teacher": 8000, "Ray dashboard": 8265, "TensorBoard": 6006}
ARTIFACTS = ROOT / "test-artifacts" / "docker-stack"

TRAIN_ARGS = "--max-episode-steps=100 --rollout-length=256 --eval-every=0 --checkpoint-every=2"
"""Short episodes and batches (2 actors x 4 environments x 256 steps): ALP-GMM's first fit, after
250 results, comes within seconds, and the run has many iterations in which to inject a fault."""
TEACHER_RUN_STEPS = 150_000
"""Long enough to still be training when the killed teacher is back (it trains on without it)."""
WORKER_RUN_STEPS = 40_000

WHEELHOUSE_PORT = 38_271
"""The wheelhouse's URL is a build argument, and a changed one misses the layer cache at every install:
so the same port each run."""
FIGURES: dict[str, float | bool] = {}
"""What a person would time: the build, the start, the training speed; written to ``ARTIFACTS/figures.json``."""

ENGINE_START_S = 60.0
STACK_READY_S = 240.0
RUN_TIMEOUT_S = 600.0
TRAINING_RESUMES_S = 60.0


# --- the engine, the stand-in base, the wheelhouse and the image --------------------------------------


def require(condition: bool, message: str) -> None:
    """Locally, a machine without Docker skips; in CI (where .ci/run installs it) that is a failure."""
    if not condition:
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)


def run(command: list[str], environment: dict[str, str], timeout: float = 900.0, **options: Any) -> str:
    """Run a command; on failure, its output is the error message."""
    result = subprocess.run(
        command, env=environment, capture_output=True, text=True, timeout=timeout, check=False, **options
    )
    assert result.returncode == 0, f"`{' '.join(command)}` exited {result.returncode}:\n{result.stdout}{result.stderr}"
    return result.stdout


def wait_for(predicate: Callable[[], Any], timeout_s: float, what: str, interval_s: float = 1.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(interval_s)
    raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")


def port_is_free(port: int) -> bool:
    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", port)) != 0


@pytest.fixture(scope="module")
def docker_env() -> Iterator[dict[str, str]]:
    """A private ``dockerd``: the environment that points ``docker`` and ``docker-compose`` at it."""
    missing = [tool for tool in ("dockerd", "docker", "docker-compose", "debootstrap") if shutil.which(tool) is None]
    require(not missing, f"missing {', '.join(missing)} (Debian packages docker.io, docker-compose, debootstrap)")
    require(os.geteuid() == 0, "starting dockerd needs root")
    taken = [f"{name} ({port})" for name, port in PUBLISHED_PORTS.items() if not port_is_free(port)]
    assert not taken, f"the stack publishes these ports on 127.0.0.1, and something already listens: {taken}"

    # A short path: the engine's unix sockets must stay within 107 bytes.
    runtime = Path(tempfile.mkdtemp(prefix="kc-dockerd-"))
    socket_path = runtime / "docker.sock"
    environment = {
        "PATH": os.environ["PATH"],
        "HOME": os.environ.get("HOME", "/root"),
        "DOCKER_HOST": f"unix://{socket_path}",
    }
    (CACHE / "engine").mkdir(parents=True, exist_ok=True)
    log = (runtime / "dockerd.log").open("w")
    engine = subprocess.Popen(
        ["dockerd", "--data-root", str(CACHE / "engine"), "--exec-root", str(runtime / "exec"),
         "--host", environment["DOCKER_HOST"], "--pidfile", str(runtime / "dockerd.pid")],
        stdout=log, stderr=subprocess.STDOUT,
    )  # fmt: skip
    try:

        def engine_answers() -> bool:
            assert engine.poll() is None, f"dockerd exited:\n{(runtime / 'dockerd.log').read_text()}"
            return subprocess.run(["docker", "version"], env=environment, capture_output=True).returncode == 0

        wait_for(engine_answers, ENGINE_START_S, "dockerd to answer")
        yield environment
    finally:
        engine.terminate()
        try:
            engine.wait(60)
        except subprocess.TimeoutExpired:
            engine.kill()
            engine.wait()
        log.close()
        shutil.rmtree(runtime, ignore_errors=True)


def image_exists(name: str, environment: dict[str, str]) -> bool:
    inspect = ["docker", "image", "inspect", name]
    return subprocess.run(inspect, env=environment, capture_output=True).returncode == 0


def build_stand_in_base(environment: dict[str, str]) -> None:
    """Debian bookworm with Python 3.11 and its venv module, as one imported layer: the slim Python
    image's stand-in. Package lists, caches and documentation are left out, as that image does."""
    with tempfile.TemporaryDirectory(dir=CACHE, prefix="rootfs-") as scratch:
        rootfs = Path(scratch) / "rootfs"
        packages = "--include=python3,python3-venv,ca-certificates"
        run(["debootstrap", "--variant=minbase", packages, "bookworm", str(rootfs)], environment)
        for leftover in ("var/cache/apt", "var/lib/apt/lists", "usr/share/doc", "usr/share/man", "usr/share/info"):
            shutil.rmtree(rootfs / leftover, ignore_errors=True)
        archive = subprocess.Popen(["tar", "-C", str(rootfs), "-c", "."], stdout=subprocess.PIPE)
        run(["docker", "import", "-", BASE_IMAGE], environment, stdin=archive.stdout)
        assert archive.wait() == 0, "tar of the stand-in rootfs failed"


def fill_wheelhouse(wheelhouse: Path, environment: dict[str, str]) -> None:
    """``pip download`` every wheel the image installs, the runtime lock's, once per version of the lock.

    The host's pip takes torch's CPU build from the machine's local wheels, as the README's install does;
    pip checks every download against the lock's hashes, as the image build does again.
    """
    lock = ROOT / "requirements.txt"
    stamp = hashlib.sha256(lock.read_bytes()).hexdigest()
    stamp_file = wheelhouse / ".requirements-sha256"
    if stamp_file.is_file() and stamp_file.read_text() == stamp:
        return
    wheelhouse.mkdir(parents=True, exist_ok=True)
    run([sys.executable, "-m", "pip", "download", "--quiet", "--dest", str(wheelhouse),
         "--require-hashes", "--requirement", str(lock)], environment)  # fmt: skip
    stamp_file.write_text(stamp)


@contextlib.contextmanager
def served_directory(directory: Path, port: int) -> Iterator[str]:
    """A static HTTP server for ``directory`` on the loopback; its directory listing is what pip's
    ``--find-links`` reads. On ``port`` if it is free, else on any."""
    if not port_is_free(port):
        port = free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "http.server", "--bind", "127.0.0.1", "--directory", str(directory), str(port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}/"
    try:
        wait_for(lambda: not port_is_free(port), 30, "the wheelhouse server", interval_s=0.2)
        yield url
    finally:
        server.terminate()
        server.wait(10)


@pytest.fixture(scope="module")
def project_image(docker_env: dict[str, str]) -> str:
    """This checkout's image, built air-gapped with the classic builder (what docker-compose 1.29 uses)."""
    if not image_exists(BASE_IMAGE, docker_env):
        build_stand_in_base(docker_env)
    wheelhouse = CACHE / "wheelhouse"
    fill_wheelhouse(wheelhouse, docker_env)
    # An earlier build's layers are in the engine's cache: every unchanged step is reused.
    FIGURES["build_had_layer_cache"] = image_exists(IMAGE, docker_env)
    with served_directory(wheelhouse, WHEELHOUSE_PORT) as wheelhouse_url:
        started = time.monotonic()
        # --network host: the build's containers reach the wheelhouse on this machine's loopback.
        run(["docker", "build", "--network", "host", "--tag", IMAGE,
             "--build-arg", f"BASE_IMAGE={BASE_IMAGE}",
             "--build-arg", f"PIP_FIND_LINKS={wheelhouse_url}", "--build-arg", "PIP_NO_INDEX=1",
             str(ROOT)], {**docker_env, "DOCKER_BUILDKIT": "0"})  # fmt: skip
        FIGURES["build_seconds"] = time.monotonic() - started
    FIGURES["image_gigabytes"] = (
        int(run(["docker", "image", "inspect", "--format", "{{.Size}}", IMAGE], docker_env)) / 1e9
    )
    return IMAGE


# --- the stack ------------------------------------------------------------------------------------


class Compose:
    """``docker-compose`` on the project's own compose file, with an env file as ``.env`` (an empty one
    stands for none) and ``settings`` as the shell's environment."""

    def __init__(self, environment: dict[str, str], env_file: Path) -> None:
        self.environment = environment
        self.env_file = env_file
        self.settings: dict[str, str] = {}
        self.up_at = time.monotonic()
        """When the last ``up`` was started."""

    def __call__(self, *arguments: str, timeout: float = 300.0) -> str:
        project = [
            "--project-name",
            PROJECT,
            "--project-directory",
            str(ROOT),
            "--file",
            str(ROOT / "docker-compose.yml"),
        ]
        command = ["docker-compose", *project, "--env-file", str(self.env_file), *arguments]
        return run(command, {**self.environment, **self.settings}, timeout=timeout)

    def containers(self, service: str) -> list[str]:
        return self("ps", "--quiet", service).split()

    def container(self, service: str) -> str:
        [container] = self.containers(service)
        return container

    def docker(self, *arguments: str, timeout: float = 120.0) -> str:
        return run(["docker", *arguments], self.environment, timeout=timeout)

    def state(self, container: str) -> dict[str, Any]:
        state: dict[str, Any] = json.loads(self.docker("inspect", "--format", "{{json .State}}", container))
        state["RestartCount"] = int(self.docker("inspect", "--format", "{{.RestartCount}}", container))
        return state

    def read_runs_file(self, path: str) -> str:
        """A file on the ``runs`` volume, through the TensorBoard container that keeps it mounted."""
        return self.docker("exec", self.container("tensorboard"), "cat", f"/runs/{path}")


def run_settings(**values: str | int) -> dict[str, str]:
    """A short run's settings, as a person would put them in ``.env`` or the shell's environment."""
    settings = {
        "TEACHER": "alp-gmm",
        "ROLLOUT_WORKERS": 2,
        "ENVS_PER_WORKER": 4,
        "RAY_WORKER_CPUS": 2,
        "TRAIN_ARGS": TRAIN_ARGS,
        **values,
    }
    return {name: str(value) for name, value in settings.items()}


def write_env_file(path: Path, **values: str | int) -> Path:
    settings = run_settings(KC_TEACHER_TOKEN=TOKEN, **values)
    path.write_text("".join(f"{name}={value}\n" for name, value in settings.items()))
    return path


def curriculum(name: str, part: str = "") -> dict[str, Any]:
    response = httpx.get(f"{TEACHER_URL}{API_PREFIX}/curricula/{name}{part}", timeout=5)
    response.raise_for_status()
    data: dict[str, Any] = response.json()
    return data


def results_received(name: str) -> int:
    """The curriculum's result count; 0 until the learner has registered it."""
    try:
        return int(curriculum(name)["counters"]["results_received"])
    except httpx.HTTPError:
        return 0


def teacher_answers() -> bool:
    try:
        return httpx.get(f"{TEACHER_URL}/healthz", timeout=2).status_code == 200
    except httpx.HTTPError:
        return False


def metrics(compose: Compose, run_name: str) -> list[dict[str, Any]]:
    try:
        text = compose.read_runs_file(f"{run_name}/metrics.jsonl")
    except AssertionError:  # not written yet
        return []
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def rollout_actors_hosted(compose: Compose, container: str) -> int:
    """Ray worker processes in this container that hosted a rollout actor (Ray heads each one's log with it)."""
    logs = "cat /tmp/ray/session_latest/logs/worker-*.out 2>/dev/null || true"
    return compose.docker("exec", container, "sh", "-c", logs).count(":actor_name:RolloutWorker")


def wait_for_exit(compose: Compose, container: str) -> dict[str, Any]:
    return wait_for(
        lambda: (state := compose.state(container))["Status"] == "exited" and state, RUN_TIMEOUT_S, "the learner"
    )


@dataclass
class TeacherKillRun:
    """What the test saw of a run whose teacher was killed mid-run; the tests below check it."""

    compose: Compose
    run_name: str
    learner_state: dict[str, Any] = field(default_factory=dict)
    learner_log: str = ""
    actors_per_container: dict[str, int] = field(default_factory=dict)
    before_kill: dict[str, Any] = field(default_factory=dict)
    after_restart: dict[str, Any] = field(default_factory=dict)
    teacher_restarts: int = 0
    steps_at_kill: int = 0
    steps_after_restart: int = 0


@pytest.fixture(scope="module")
def compose(
    project_image: str, docker_env: dict[str, str], tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Compose]:
    """The stack, up with two worker containers; taken down with its volumes at the end, its logs kept."""
    env_file = write_env_file(tmp_path_factory.mktemp("compose") / "stack.env", SEED=0, TOTAL_STEPS=TEACHER_RUN_STEPS)
    stack = Compose(docker_env, env_file)
    try:
        stack.up_at = time.monotonic()
        stack("up", "--detach", "--no-build", "--scale", "ray-worker=2", timeout=STACK_READY_S)
        yield stack
    finally:
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(Exception):
            (ARTIFACTS / "compose.log").write_text(stack("logs", "--no-color", "--timestamps"))
        stack("down", "--volumes", "--remove-orphans", "--timeout", "20")
        (ARTIFACTS / "figures.json").write_text(json.dumps(FIGURES, indent=2) + "\n")
        print(f"docker stack figures: {FIGURES}")


@pytest.fixture(scope="module")
def teacher_kill_run(compose: Compose) -> TeacherKillRun:
    """Training with the teacher's process killed after ALP-GMM's first fit (a crash, not a ``docker stop``)."""
    observed = TeacherKillRun(compose, run_name="alp-gmm-seed0")
    learner = compose.container("learner")
    wait_for(lambda: results_received(observed.run_name), STACK_READY_S, "the teacher's first episode result")
    FIGURES["up_to_first_result_seconds"] = time.monotonic() - compose.up_at
    wait_for(lambda: metrics(compose, observed.run_name), STACK_READY_S, "the learner's first iteration")
    workers = compose.containers("ray-worker")
    observed.actors_per_container = {
        **{f"ray-worker {index}": rollout_actors_hosted(compose, worker) for index, worker in enumerate(workers)},
        "ray-head": rollout_actors_hosted(compose, compose.container("ray-head")),
        "learner": rollout_actors_hosted(compose, learner),
    }

    def fitted() -> bool:
        return bool(curriculum(observed.run_name)["counters"]["fits_completed"] >= 1)

    wait_for(fitted, RUN_TIMEOUT_S, "ALP-GMM's first fit")
    teacher = compose.container("teacher")
    observed.before_kill = curriculum(observed.run_name, "/state")
    observed.steps_at_kill = metrics(compose, observed.run_name)[-1]["step"]
    # With `init: true` the init process survives `kill -1` and exits with the killed service, as a crash would.
    compose.docker("exec", teacher, "sh", "-c", "kill -KILL -1")
    wait_for(lambda: compose.state(teacher)["RestartCount"] >= 1, 60, "Docker to restart the teacher")
    wait_for(teacher_answers, 120, "the restarted teacher to answer")
    observed.after_restart = curriculum(observed.run_name, "/state")
    observed.teacher_restarts = compose.state(teacher)["RestartCount"]
    # The outage lasts about as long as one iteration (~2 s), so the learner may not have logged one
    # since the kill when the teacher answers again; it must do so soon after, and not stay stalled.
    deadline = time.monotonic() + TRAINING_RESUMES_S
    while (step := metrics(compose, observed.run_name)[-1]["step"]) <= observed.steps_at_kill:
        if time.monotonic() > deadline:
            break
        time.sleep(1.0)
    observed.steps_after_restart = step

    observed.learner_state = wait_for_exit(compose, learner)
    observed.learner_log = compose.docker("logs", learner)
    records = metrics(compose, observed.run_name)
    iteration_steps = np.diff([0, *(record["step"] for record in records)])
    seconds = sum(
        steps / record["perf/steps_per_second"] for steps, record in zip(iteration_steps, records, strict=True)
    )
    FIGURES["training_steps_per_second"] = records[-1]["step"] / seconds
    return observed


# --- what a person sees -----------------------------------------------------------------------------


def test_the_learner_finishes_with_its_final_checkpoint_on_the_runs_volume(teacher_kill_run: TeacherKillRun) -> None:
    state = teacher_kill_run.learner_state
    assert (state["ExitCode"], state["RestartCount"]) == (0, 0), teacher_kill_run.learner_log[-3000:]
    last_line = teacher_kill_run.learner_log.strip().splitlines()[-1]
    assert last_line.startswith("final checkpoint: /runs/alp-gmm-seed0/checkpoints/"), last_line
    checkpoint = last_line.removeprefix("final checkpoint: ")
    teacher_kill_run.compose.docker("exec", teacher_kill_run.compose.container("tensorboard"), "test", "-s", checkpoint)
    assert metrics(teacher_kill_run.compose, teacher_kill_run.run_name)[-1]["step"] >= TEACHER_RUN_STEPS


def test_rollout_actors_run_on_both_worker_containers_only(teacher_kill_run: TeacherKillRun) -> None:
    placed = teacher_kill_run.actors_per_container
    assert placed["ray-head"] == placed["learner"] == 0, placed
    workers = [count for name, count in placed.items() if name.startswith("ray-worker")]
    assert len(workers) == 2 and all(count >= 1 for count in workers), placed


def test_the_printed_dashboard_opens_on_the_host_with_the_curriculum_and_its_results(
    teacher_kill_run: TeacherKillRun,
) -> None:
    dashboard = f"{TEACHER_URL}/curricula/{teacher_kill_run.run_name}"
    assert f"dashboard:     {dashboard}" in teacher_kill_run.learner_log
    page = httpx.get(dashboard, timeout=10)
    assert page.status_code == 200 and teacher_kill_run.run_name in page.text
    state = curriculum(teacher_kill_run.run_name, "/state")
    assert state["curriculum"]["config"]["teacher"] == "alp-gmm"
    assert state["recent_results"] and state["curriculum"]["counters"]["fits_completed"] >= 1


def test_tensorboard_and_the_ray_dashboard_answer_on_the_host(teacher_kill_run: TeacherKillRun) -> None:
    runs = httpx.get(f"http://127.0.0.1:{PUBLISHED_PORTS['TensorBoard']}/data/runs", timeout=30)
    assert runs.status_code == 200 and f"{teacher_kill_run.run_name}/tensorboard" in runs.json()
    ray_dashboard = httpx.get(f"http://127.0.0.1:{PUBLISHED_PORTS['Ray dashboard']}/", timeout=30)
    assert ray_dashboard.status_code == 200


def test_a_write_without_the_token_is_refused(teacher_kill_run: TeacherKillRun) -> None:
    tasks = f"{TEACHER_URL}{API_PREFIX}/curricula/{teacher_kill_run.run_name}/tasks"
    assert httpx.post(tasks, json={"count": 1}, timeout=10).status_code == 401
    wrong = httpx.post(tasks, json={"count": 1}, headers={"Authorization": "Bearer wrong"}, timeout=10)
    assert wrong.status_code == 401
    right = httpx.post(tasks, json={"count": 1}, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=10)
    assert right.status_code == 200


def test_a_killed_teacher_comes_back_by_itself_with_its_counters_and_fits(teacher_kill_run: TeacherKillRun) -> None:
    assert teacher_kill_run.teacher_restarts >= 1
    before, after = teacher_kill_run.before_kill, teacher_kill_run.after_restart
    for counter in ("tasks_issued", "results_received", "fits_completed"):
        assert after["curriculum"]["counters"][counter] >= before["curriculum"]["counters"][counter], counter
    fits_after = {fit["index"]: fit for fit in after["fits"]}
    for fit in before["fits"]:
        assert fits_after[fit["index"]]["started_at"] == fit["started_at"], "a fit was lost or rewritten"
    assert any(fit["replayed"] for fit in after["fits"]), "the restarted teacher did not rebuild its fits"


def test_the_learner_carries_on_and_no_episode_result_is_lost(teacher_kill_run: TeacherKillRun) -> None:
    assert teacher_kill_run.steps_after_restart > teacher_kill_run.steps_at_kill, "training stalled"
    records = metrics(teacher_kill_run.compose, teacher_kill_run.run_name)
    reported = sum(r["train/episodes"] - r["train/offline_episodes"] for r in records)
    received = curriculum(teacher_kill_run.run_name)["counters"]["results_received"]
    assert received == reported > 0


@dataclass
class NoEnvRun:
    """The second run: no ``.env``, so the stack's own token; one of the two worker containers killed."""

    compose: Compose
    victim: str
    learner_state: dict[str, Any]
    learner_log: str
    token: str


@pytest.fixture(scope="module")
def no_env_run(teacher_kill_run: TeacherKillRun, tmp_path_factory: pytest.TempPathFactory) -> NoEnvRun:
    """The same stack brought up again with no ``.env`` and another seed: the teacher (whose token
    changes) and the learner are recreated; the teacher's database and the runs stay on their volumes."""
    compose = teacher_kill_run.compose
    compose.env_file = tmp_path_factory.mktemp("no-env") / "empty.env"
    compose.env_file.write_text("")
    compose.settings = run_settings(SEED=1, TOTAL_STEPS=WORKER_RUN_STEPS)
    compose("up", "--detach", "--no-build", "--scale", "ray-worker=2", timeout=STACK_READY_S)
    learner = compose.container("learner")
    wait_for(lambda: metrics(compose, "alp-gmm-seed1"), STACK_READY_S, "the second run's first iteration")
    victim = compose.containers("ray-worker")[0]
    compose.docker("kill", victim)

    state = wait_for_exit(compose, learner)
    token = compose.docker("exec", compose.container("teacher"), "cat", "/secrets/teacher-token").strip()
    return NoEnvRun(compose, victim, state, compose.docker("logs", learner), token)


def test_training_completes_when_a_worker_container_is_killed(no_env_run: NoEnvRun) -> None:
    compose = no_env_run.compose
    state = no_env_run.learner_state
    assert (state["ExitCode"], state["RestartCount"]) == (0, 0), no_env_run.learner_log[-3000:]
    assert compose.state(no_env_run.victim)["Status"] == "exited", "the killed worker container came back"
    records = metrics(compose, "alp-gmm-seed1")
    assert records[-1]["step"] >= WORKER_RUN_STEPS
    assert records[-1]["workers/replacements"] >= 1, "no rollout actor was replaced after its container died"
    last_line = no_env_run.learner_log.strip().splitlines()[-1]
    assert last_line.startswith("final checkpoint: /runs/alp-gmm-seed1/checkpoints/"), last_line


def test_with_no_env_the_stack_makes_a_token_and_the_learner_says_how_to_read_it(no_env_run: NoEnvRun) -> None:
    log = no_env_run.learner_log
    hint = "teacher token: made on the stack's first start; read it with: docker compose exec teacher cat "
    assert f"{hint}/secrets/teacher-token" in log, log[:3000]
    assert f"dashboard:     {TEACHER_URL}/curricula/alp-gmm-seed1" in log
    assert len(no_env_run.token) >= 40 and no_env_run.token != TOKEN

    tasks = f"{TEACHER_URL}{API_PREFIX}/curricula/alp-gmm-seed1/tasks"
    assert httpx.post(tasks, json={"count": 1}, timeout=10).status_code == 401
    old = httpx.post(tasks, json={"count": 1}, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=10)
    assert old.status_code == 401, "the .env token of the first run should no longer be accepted"
    made = httpx.post(tasks, json={"count": 1}, headers={"Authorization": f"Bearer {no_env_run.token}"}, timeout=10)
    assert made.status_code == 200
