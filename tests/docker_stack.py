"""The one Docker stack that the Docker tests (marker ``docker``) share, as a pytest plugin (tests/conftest.py).

One private engine, one image built from this checkout, one compose project: the tests start their
training runs on it one after another, and between two runs ``up`` recreates only the services whose
settings changed (the learner, for a run with another seed or budget). Building and starting it once
per session instead of once per test file is what keeps ``make test`` within its budget.

The engine is the tests' own: ``dockerd`` on a private socket, stopped at the end, with its data root
(the layer cache) and the wheelhouse in ``KC_DOCKER_CACHE`` (default ``/var/tmp/kuka-curriculum-docker``),
kept between runs so that a rebuild reuses every unchanged layer. While it runs, ``DOCKER_HOST`` names it
in this process's environment, so ``docker``, ``docker-compose`` and ``bench/chaos.py`` all reach it.

What these machines lack is stood in for, as an air-gapped lab would: Docker Hub is unreachable, so
the base image is a Debian rootfs made with ``debootstrap`` and ``docker import``; the wheels come
from a wheelhouse served on the loopback (``PIP_FIND_LINKS`` with ``PIP_NO_INDEX=1``, the build that
docs/deployment.md describes), filled once with ``pip download`` of the lock, requirements.txt.
It needs root, ``dockerd``, ``debootstrap`` and ``docker-compose``; ``.ci/run`` installs them.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT / "bench") not in sys.path:
    sys.path.insert(0, str(ROOT / "bench"))
import chaos  # noqa: E402  (bench/ is scripts, not a package)

CACHE = Path(os.environ.get("KC_DOCKER_CACHE", "/var/tmp/kuka-curriculum-docker"))
BASE_IMAGE = "kuka-curriculum-standin-base:bookworm"
IMAGE = "kuka-curriculum:latest"
"""The name docker-compose.yml gives the image, so ``up --no-build`` runs the one built here."""
PROJECT = "kcstack"
TOKEN = chaos.TOKEN
"""The token the runs with an env file put in it: the chaos bench's, so that its runs and the others' do not
recreate the teacher for a token of their own."""
TEACHER_URL = chaos.TEACHER_URL
PUBLISHED_PORTS = {"teacher": 8000, "Ray dashboard": 8265, "TensorBoard": 6006}
WHEELHOUSE_PORT = 38_271
"""The wheelhouse's URL is a build argument, and a changed one misses the layer cache at every install:
so the same port each run."""
FIGURES: dict[str, float | bool] = {}
"""What a person would time (the build here; the start and the training speed in test_docker_stack.py)."""

ENGINE_START_S = 60.0
STACK_READY_S = 240.0


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The Docker tests run last, in their files' order: the stack they share is up from the first of them to the
    end of the session, and no other test should run beside it (it holds ports 8000, 8265 and 6006, and CPUs)."""
    items.sort(key=lambda item: item.get_closest_marker("docker") is not None)


# --- running things -----------------------------------------------------------------------------------


def require(condition: bool, message: str) -> None:
    """Locally, a machine without Docker skips; in CI (where .ci/run installs it) that is a failure."""
    if not condition:
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)


def run(command: list[str], timeout: float = 900.0, **options: Any) -> str:
    """Run a command; on failure, its output is the error message."""
    result = subprocess.run(command, capture_output=True, text=True, timeout=timeout, check=False, **options)
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


def wait_for_training(stack: chaos.Stack, predicate: Callable[[], Any], what: str, artifacts: Path) -> Any:
    """``wait_for`` over ``STACK_READY_S`` for a run's first progress; a stack that never gets there fails
    with what it was doing (every log's tail, the learner's last), its whole log saved in ``artifacts``."""
    try:
        return wait_for(predicate, STACK_READY_S, what)
    except AssertionError as error:
        raise AssertionError(f"{error}\n{chaos.stuck_at_start(stack, artifacts)}") from None


def port_is_free(port: int) -> bool:
    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", port)) != 0


def any_free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


# --- the engine, the stand-in base, the wheelhouse and the image --------------------------------------


@pytest.fixture(scope="session")
def docker_engine() -> Iterator[str]:
    """A private ``dockerd``; yields its address, which ``DOCKER_HOST`` holds until it stops."""
    missing = [tool for tool in ("dockerd", "docker", "docker-compose", "debootstrap") if shutil.which(tool) is None]
    require(not missing, f"missing {', '.join(missing)} (Debian packages docker.io, docker-compose, debootstrap)")
    require(os.geteuid() == 0, "starting dockerd needs root")
    taken = [f"{name} ({port})" for name, port in PUBLISHED_PORTS.items() if not port_is_free(port)]
    assert not taken, f"the stack publishes these ports on 127.0.0.1, and something already listens: {taken}"

    # A short path: the engine's unix sockets must stay within 107 bytes.
    runtime = Path(tempfile.mkdtemp(prefix="kc-dockerd-"))
    address = f"unix://{runtime / 'docker.sock'}"
    (CACHE / "engine").mkdir(parents=True, exist_ok=True)
    log = (runtime / "dockerd.log").open("w")
    engine = subprocess.Popen(
        ["dockerd", "--data-root", str(CACHE / "engine"), "--exec-root", str(runtime / "exec"),
         "--host", address, "--pidfile", str(runtime / "dockerd.pid")],
        stdout=log, stderr=subprocess.STDOUT,
    )  # fmt: skip
    try:
        with pytest.MonkeyPatch.context() as environment:
            environment.setenv("DOCKER_HOST", address)

            def engine_answers() -> bool:
                assert engine.poll() is None, f"dockerd exited:\n{(runtime / 'dockerd.log').read_text()}"
                return subprocess.run(["docker", "version"], capture_output=True).returncode == 0

            wait_for(engine_answers, ENGINE_START_S, "dockerd to answer")
            yield address
    finally:
        engine.terminate()
        try:
            engine.wait(60)
        except subprocess.TimeoutExpired:
            engine.kill()
            engine.wait()
        log.close()
        # dockerd leaves its default network namespace mounted in its exec root.
        subprocess.run(["umount", str(runtime / "exec" / "netns" / "default")], capture_output=True)
        shutil.rmtree(runtime, ignore_errors=True)


def image_exists(name: str) -> bool:
    return subprocess.run(["docker", "image", "inspect", name], capture_output=True).returncode == 0


def build_stand_in_base() -> None:
    """Debian bookworm with Python 3.11 and its venv module, as one imported layer: the slim Python
    image's stand-in. Package lists, caches and documentation are left out, as that image does."""
    with tempfile.TemporaryDirectory(dir=CACHE, prefix="rootfs-") as scratch:
        rootfs = Path(scratch) / "rootfs"
        packages = "--include=python3,python3-venv,ca-certificates"
        run(["debootstrap", "--variant=minbase", packages, "bookworm", str(rootfs)])
        for leftover in ("var/cache/apt", "var/lib/apt/lists", "usr/share/doc", "usr/share/man", "usr/share/info"):
            shutil.rmtree(rootfs / leftover, ignore_errors=True)
        archive = subprocess.Popen(["tar", "-C", str(rootfs), "-c", "."], stdout=subprocess.PIPE)
        run(["docker", "import", "-", BASE_IMAGE], stdin=archive.stdout)
        assert archive.wait() == 0, "tar of the stand-in rootfs failed"


def fill_wheelhouse(wheelhouse: Path) -> None:
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
         "--require-hashes", "--requirement", str(lock)])  # fmt: skip
    stamp_file.write_text(stamp)


@contextlib.contextmanager
def served_directory(directory: Path, port: int) -> Iterator[str]:
    """A static HTTP server for ``directory`` on the loopback; its directory listing is what pip's
    ``--find-links`` reads. On ``port`` if it is free, else on any."""
    if not port_is_free(port):
        port = any_free_port()
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


@pytest.fixture(scope="session")
def project_image(docker_engine: str) -> str:
    """This checkout's image, built air-gapped with the classic builder (what docker-compose 1.29 uses)."""
    if not image_exists(BASE_IMAGE):
        build_stand_in_base()
    wheelhouse = CACHE / "wheelhouse"
    fill_wheelhouse(wheelhouse)
    # An earlier build's layers are in the engine's cache: every unchanged step is reused.
    FIGURES["build_had_layer_cache"] = image_exists(IMAGE)
    with served_directory(wheelhouse, WHEELHOUSE_PORT) as wheelhouse_url:
        started = time.monotonic()
        # --network host: the build's containers reach the wheelhouse on this machine's loopback.
        run(["docker", "build", "--network", "host", "--tag", IMAGE,
             "--build-arg", f"BASE_IMAGE={BASE_IMAGE}",
             "--build-arg", f"PIP_FIND_LINKS={wheelhouse_url}", "--build-arg", "PIP_NO_INDEX=1",
             str(ROOT)], env={**os.environ, "DOCKER_BUILDKIT": "0"})  # fmt: skip
        FIGURES["build_seconds"] = time.monotonic() - started
    FIGURES["image_gigabytes"] = int(run(["docker", "image", "inspect", "--format", "{{.Size}}", IMAGE])) / 1e9
    return IMAGE


# --- the stack ------------------------------------------------------------------------------------


class SharedStack(chaos.Stack):
    """The compose project every Docker test runs on, from its first run to the end of the session.

    A run the chaos bench measures (``start_run``) has the bench's override: the teacher's data on a
    size-limited file system of its own, the runs and the workers' delivery log in folders here. Every
    other run (``start_plain_run``) has docker-compose.yml alone, as a person runs it: named volumes,
    an env file (an empty one stands for none) and settings in the shell's environment.
    """

    def __init__(self, scratch: Path) -> None:
        super().__init__(scratch, PROJECT, volume_mb=512)
        self.plain = False
        self.shell: dict[str, str] = {}

    def compose_files(self) -> list[Path]:
        files = super().compose_files()
        return files[:1] if self.plain else files

    def compose_environment(self) -> dict[str, str]:
        """The engine's address and ``shell`` alone: a setting in this process's environment would override the
        env file's (``docker-compose`` prefers the shell's)."""
        essentials = {name: os.environ[name] for name in ("PATH", "HOME", "DOCKER_HOST") if name in os.environ}
        return {**essentials, **self.shell}

    def compose(self, *arguments: str, timeout: float = 300.0) -> str:
        """As the bench's; an ``up`` first waits for the services already up to be healthy, as docker-compose
        refuses to start a service whose dependency is unhealthy, and a busy machine's Ray head can fail a
        health check or two after the faults of an earlier run (it is healthy again at the next one)."""
        if arguments[:1] == ("up",):
            wait_for(self.healthy, STACK_READY_S, "the stack's services to be healthy before `up`", interval_s=2.0)
        return super().compose(*arguments, timeout=timeout)

    def healthy(self) -> bool:
        """No running container of this project is unhealthy or still starting."""
        running = [state for state in self.states().values() if state["running"]]
        return all(state["health"] in (None, "healthy") for state in running)

    def start_run(self, settings: dict[str, str]) -> None:
        if not self.mounted:
            self.prepare()
        self.plain, self.shell = False, {}
        super().start_run(settings)

    def start_plain_run(self, env_file: dict[str, str], shell: dict[str, str] | None = None) -> None:
        """``up`` with docker-compose.yml alone, ``env_file`` as its ``.env`` and ``shell`` as the shell's
        environment (``TOTAL_STEPS=... docker compose up``)."""
        self.plain, self.shell = True, dict(shell or {})
        self.env_file.write_text("".join(f"{name}={value}\n" for name, value in env_file.items()))
        settings = {**env_file, **self.shell}
        self.run_name = f"{settings.get('TEACHER', 'alp-gmm')}-seed{settings.get('SEED', '0')}"
        self.compose("up", "--detach", "--no-build", "--scale", "ray-worker=2", timeout=STACK_READY_S)


@pytest.fixture(scope="session")
def docker_stack(project_image: str) -> Iterator[SharedStack]:
    """The shared compose project (not up yet: its first run starts it); taken down with its volumes at the end."""
    scratch = Path(tempfile.mkdtemp(prefix="kc-stack-"))
    stack = SharedStack(scratch)
    try:
        yield stack
    finally:
        stack.down()
        shutil.rmtree(scratch, ignore_errors=True)
