"""Faults during real training: the Docker stack trains while a killer takes its roles down at random.

Brings up this repository's ``docker-compose.yml`` (the image ``kuka-curriculum:latest`` must be built;
``DOCKER_HOST`` names the engine) with two Ray worker containers and a short-episode KUKA run
(``--steps`` environment steps, ALP-GMM, so the teacher fits and snapshots through the faults). A
compose override, written here, changes three things for measuring only: the teacher's ``/data`` is a
size-limited ext4 file system of its own (a loop device, so that filling it fills nothing else), the
runs volume and a log folder are folders on this machine, and every worker's teacher client writes
its delivery log there (``KC_RESULT_LOG``: the task ids the service acknowledged, and every 5xx).

Once the learner has logged its first iteration, every ``--fault-every`` seconds for ``--duration``
seconds a seeded killer picks a role (teacher, learner, Ray head, a Ray worker) and a fault: ``kill``
(``kill -KILL -1`` inside the container: its processes die as in a crash and the restart policy must
bring it back) or ``restart`` (``docker stop``, then ``docker start``). Once, at ``--disk-full-at``
seconds, the teacher's file system is filled for ``--disk-full-for`` seconds and then freed; no fault
is injected while it is full, so that what the writes get is the disk's doing. A probe draws one
task a second meanwhile and reads ``/healthz``. After ``--duration`` the killer stops and the run is
left to reach its budget. Then:

- the run reached its step budget (the learner exited 0 with its final checkpoint);
- every result the workers' log says the service acknowledged is stored, once: counted by task id
  against the teacher's database (a copy taken at the end);
- while the disk was full, writes were answered 503 with the reason (no 500, no request hung),
  ``/healthz`` said ``degraded``, and the service came back to ``ok`` by itself once freed;
- each curriculum's live state (the teacher's ``state`` and counters from the API) equals a replay of
  its stored results from the first (``teacher_service.replay`` with ``from_start``);
- no role needed a hand: every fault's role came back without the bench doing more than the fault
  itself, and at the end every service is up (the learner exited 0).

With ``--schedule`` the faults are not drawn but given, in order (``teacher:kill,disk-full,...``: a
role and a fault, or the full disk in its place), and each one waits until the stack is ready for it:
``--fault-every`` seconds since the last, the last fault's role back, and the learner
``--steps-between`` steps past where it stood at the last one; so every fault lands on a stack that
trains, whatever the machine's speed (tests/test_chaos_stack.py runs its faults this way).

Prints a table (faults by role, time until the role answered again and until training got past the
step it was at, steps lost at each learner death, results lost and duplicated, 5xx the workers saw)
and writes everything to ``--out``. Needs root (the loop mount), ``docker``, ``docker-compose``.

    DOCKER_HOST=unix:///path/docker.sock .venv/bin/python bench/chaos.py --duration 1800 --fault-every 60 \\
        --steps 2000000 --out benchmarks/chaos/chaos-30min.json
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import os
import random
import shlex
import shutil
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.provenance import commit, machine  # noqa: E402

TOKEN = "chaos-bench-teacher-token"
TEACHER_URL = "http://127.0.0.1:8000"
RAY_DASHBOARD_URL = "http://127.0.0.1:8265/"
ROLES = ("teacher", "learner", "ray-head", "ray-worker")
SERVICES = (*ROLES, "tensorboard")
KINDS = ("kill", "restart")
TRAIN_ARGS = "--max-episode-steps=100 --rollout-length=256 --eval-every=0 --checkpoint-every=2"
"""As tests/test_docker_stack.py: 100-step episodes and 2,048-step iterations, a checkpoint every two."""
KUKA_USER = "1000:1000"
"""The image's user, who must write the teacher's data and the runs."""
RECOVERY_TIMEOUT_S = 600.0
AFTERMATH_S = 120.0
"""How long after a fault the restarts of other roles are counted as its consequences."""
FILLER = "chaos-filler"
STUCK_LOG_LINES = 25
"""Of each role's log, in the error when the stack never trains."""


# --- the stack ------------------------------------------------------------------------------------


def run(command: list[str], timeout: float = 300.0, check: bool = True, **options: Any) -> str:
    result = subprocess.run(command, capture_output=True, text=True, timeout=timeout, check=False, **options)
    if check and result.returncode != 0:
        raise RuntimeError(f"`{shlex.join(command)}` exited {result.returncode}:\n{result.stdout}{result.stderr}")
    return result.stdout


def utc(text: str) -> float:
    """Docker's RFC 3339 time (nanoseconds, Z) as a Unix time."""
    if text.startswith("0001-"):
        return 0.0
    head, _, fraction = text.rstrip("Z").partition(".")
    moment = datetime.datetime.fromisoformat(head).replace(tzinfo=datetime.timezone.utc)
    return moment.timestamp() + (float(f"0.{fraction}") if fraction else 0.0)


class Stack:
    """The compose project, its containers by role, and the folders on this machine that it writes."""

    def __init__(self, scratch: Path, project: str, volume_mb: int) -> None:
        self.scratch = scratch
        self.run_name = ""
        """The training run the stack's learner runs: ``start_run`` sets it."""
        self.project = project
        self.data = scratch / "teacher-data"
        self.runs = scratch / "runs"
        self.logs = scratch / "logs"
        self.image = scratch / "teacher-data.img"
        self.env_file = scratch / "stack.env"
        self.override = scratch / "chaos.override.yml"
        self.volume_mb = volume_mb
        self.env_file.touch()
        self.mounted = False

    def prepare(self) -> None:
        for folder in (self.data, self.runs, self.logs):
            folder.mkdir(parents=True, exist_ok=True)
        run(["truncate", "-s", f"{self.volume_mb}M", str(self.image)])
        run(["mkfs.ext4", "-q", "-F", "-m", "0", str(self.image)])
        run(["mount", "-o", "loop", str(self.image), str(self.data)])
        self.mounted = True
        for folder in (self.data, self.runs, self.logs):
            run(["chown", KUKA_USER, str(folder)])
        log_file = "/chaos/delivered.jsonl"
        self.override.write_text(
            json.dumps(
                {
                    "services": {
                        "teacher": {"volumes": [f"{self.data}:/data"]},
                        "ray-worker": {"environment": {"KC_RESULT_LOG": log_file}, "volumes": [f"{self.logs}:/chaos"]},
                        "learner": {
                            "environment": {"KC_RESULT_LOG": log_file},
                            "volumes": [f"{self.runs}:/runs", f"{self.logs}:/chaos"],
                        },
                        "tensorboard": {"volumes": [f"{self.runs}:/runs:ro"]},
                    }
                },
                indent=2,
            )
        )

    def compose_files(self) -> list[Path]:
        return [ROOT / "docker-compose.yml", self.override]

    def compose_environment(self) -> dict[str, str] | None:
        """The environment ``docker-compose`` runs in; None: this process's."""
        return None

    def compose(self, *arguments: str, timeout: float = 300.0) -> str:
        files = [argument for path in self.compose_files() for argument in ("--file", str(path))]
        command = ["docker-compose", "--project-name", self.project, "--project-directory", str(ROOT), *files]
        command += ["--env-file", str(self.env_file), *arguments]
        return run(command, timeout=timeout, env=self.compose_environment())

    def start_run(self, settings: dict[str, str]) -> None:
        """``up`` with ``settings`` as the env file: on a stack already up, compose recreates only the services
        whose settings changed (the learner alone, for a run with another seed or budget)."""
        self.env_file.write_text("".join(f"{name}={value}\n" for name, value in settings.items()))
        self.run_name = f"{settings['TEACHER']}-seed{settings['SEED']}"
        self.compose("up", "--detach", "--no-build", "--scale", "ray-worker=2", timeout=600)

    def containers(self, service: str) -> list[str]:
        labels = [f"label=com.docker.compose.project={self.project}", f"label=com.docker.compose.service={service}"]
        listing = run(["docker", "ps", "--all", "--quiet", "--no-trunc", "--filter", labels[0], "--filter", labels[1]])
        return sorted(listing.split())

    def inspect(self, *containers: str) -> dict[str, dict[str, Any]]:
        if not containers:
            return {}
        out = run(["docker", "inspect", "--format", "{{json .}}", *containers], check=False)
        states = {}
        for line in out.splitlines():
            data = json.loads(line)
            state = data["State"]
            states[data["Id"]] = {
                "status": state["Status"],
                "running": state["Running"],
                "exit_code": state["ExitCode"],
                "started_at": utc(state["StartedAt"]),
                "restarts": data["RestartCount"],
                "health": (state.get("Health") or {}).get("Status"),
                "name": data["Name"].lstrip("/"),
            }
        return states

    def states(self) -> dict[str, dict[str, Any]]:
        """Every container of every service, by id (``inspect``'s fields)."""
        return self.inspect(*(c for service in SERVICES for c in self.containers(service)))

    def save_log(self, artifacts: Path) -> None:
        """The whole ``docker-compose logs`` into ``artifacts``; best effort, as the stack may be half down."""
        artifacts.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(Exception):
            (artifacts / "compose.log").write_text(self.compose("logs", "--no-color", "--timestamps"))

    def down(self) -> None:
        with contextlib.suppress(Exception):
            self.compose("down", "--volumes", "--remove-orphans", "--timeout", "20", timeout=300)
        if self.mounted:
            run(["umount", str(self.data)], check=False)
            self.mounted = False


def http(method: str, url: str, payload: object | None = None, timeout: float = 10.0) -> tuple[int, Any, float]:
    """Status, parsed body (or text) and seconds taken; status 0 when no answer came (the reason as body)."""
    data = None if payload is None else json.dumps(payload).encode()
    headers = {"Content-Type": "application/json", "Authorization": f"Bearer {TOKEN}"}
    request = urllib.request.Request(url, data=data, method=method, headers=headers)
    started = time.monotonic()
    try:
        with urllib.request.urlopen(request, timeout=timeout) as response:
            status, body = response.status, response.read()
    except urllib.error.HTTPError as error:
        status, body = error.code, error.read()
    except (OSError, TimeoutError) as error:
        return 0, f"{type(error).__name__}: {error}", time.monotonic() - started
    try:
        return status, json.loads(body), time.monotonic() - started
    except ValueError:
        return status, body.decode(errors="replace"), time.monotonic() - started


def metrics(stack: Stack, run_name: str) -> list[dict[str, Any]]:
    path = stack.runs / run_name / "metrics.jsonl"
    if not path.exists():
        return []
    records = []
    for line in path.read_text().splitlines():
        with contextlib.suppress(ValueError):  # a line being written
            records.append(json.loads(line))
    return records


# --- faults and recovery ----------------------------------------------------------------------------


@dataclass
class Fault:
    at_s: float
    role: str
    kind: str
    container: str = ""
    done: bool = False
    note: str = ""
    started: float = 0.0
    step_before: int = 0
    back_s: float | None = None
    """Until the role answered again: its container started anew and running, plus the teacher's
    ``/healthz``, the Ray dashboard for the head, a new iteration logged for the learner."""
    progress_regained_s: float | None = None
    """Until the learner logged a step past the one it had logged before the fault."""
    learner_restarts: int = 0
    """Learner restarts in the ``AFTERMATH_S`` seconds after the fault (a head's death may take it, at
    once or when the Ray nodes give up on the old head); a later fault may add its own."""
    worker_restarts: int = 0
    """Ray worker container restarts in the ``AFTERMATH_S`` seconds after the fault."""


class Observer:
    """Samples the stack every ``interval`` seconds: the learner's last step, every container's state."""

    def __init__(self, stack: Stack, run_name: str, interval: float = 2.0) -> None:
        self.stack, self.run_name, self.interval = stack, run_name, interval
        self.timeline: list[dict[str, Any]] = []
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)

    def _loop(self) -> None:
        while not self.stop.is_set():
            with contextlib.suppress(Exception):
                self.sample()
            self.stop.wait(self.interval)

    def sample(self) -> dict[str, Any]:
        records = metrics(self.stack, self.run_name)
        containers = {
            service: self.stack.containers(service) for service in ("teacher", "learner", "ray-head", "ray-worker")
        }
        states = self.stack.inspect(*(c for ids in containers.values() for c in ids))
        entry = {
            "t": time.time(),
            "step": records[-1]["step"] if records else 0,
            "records": len(records),
            "last_record_at": records[-1]["time"] if records else 0.0,
            "learner_restarts": sum(states[c]["restarts"] for c in containers["learner"] if c in states),
            "worker_restarts": sum(states[c]["restarts"] for c in containers["ray-worker"] if c in states),
            "states": {
                service: [[states[c]["status"], states[c]["restarts"]] for c in ids if c in states]
                for service, ids in containers.items()
            },
        }
        with self.lock:
            self.timeline.append(entry)
        return entry

    def latest(self) -> dict[str, Any]:
        with self.lock:
            return self.timeline[-1] if self.timeline else self.sample()


def role_is_back(stack: Stack, fault: Fault) -> bool:
    state = stack.inspect(fault.container).get(fault.container)
    if state is None or state["started_at"] < fault.started - 1.0:
        return False
    if fault.role == "learner" and exited_cleanly(state):
        # Stopped in its last iteration, it finished the budget there; started again, it found nothing left
        # to train and exited 0 without a new record (CI, 2026-12-03, on a machine that trains faster).
        return True
    if not state["running"]:
        return False
    if fault.role == "teacher":
        return http("GET", f"{TEACHER_URL}/healthz", timeout=3)[0] == 200
    if fault.role == "ray-head":
        return http("GET", RAY_DASHBOARD_URL, timeout=3)[0] == 200
    if fault.role == "learner":
        return any(record["time"] > state["started_at"] for record in metrics(stack, stack.run_name))
    return True


def watch_recovery(stack: Stack, observer: Observer, fault: Fault, aftermath_s: float = AFTERMATH_S) -> None:
    """Fill in ``back_s``, ``progress_regained_s`` and the restarts it caused in the ``aftermath_s`` seconds
    after it, polling once a second."""
    then = observer.latest()
    deadline = fault.started + RECOVERY_TIMEOUT_S
    aftermath = fault.started + aftermath_s
    while time.time() < deadline and (
        fault.back_s is None or fault.progress_regained_s is None or time.time() < aftermath
    ):
        if time.time() < aftermath:
            now = observer.latest()
            fault.learner_restarts = now["learner_restarts"] - then["learner_restarts"]
            fault.worker_restarts = now["worker_restarts"] - then["worker_restarts"]
        now = time.time()
        if fault.back_s is None:
            with contextlib.suppress(Exception):
                if role_is_back(stack, fault):
                    fault.back_s = now - fault.started
        if fault.progress_regained_s is None and now_s_past(fault, aftermath_s) and learner_finished(stack):
            break  # the run ended before it got past that step again (a fault near its end)
        if fault.progress_regained_s is None:
            records = metrics(stack, stack.run_name)
            if records and records[-1]["step"] > fault.step_before and records[-1]["time"] > fault.started:
                fault.progress_regained_s = records[-1]["time"] - fault.started
        time.sleep(1.0)


def now_s_past(fault: Fault, seconds: float) -> bool:
    return time.time() > fault.started + seconds


def stuck_at_start(stack: Stack, artifacts: Path | None) -> str:
    """What a stack that never trained was doing: the tail of every log, Ray's view and each container's state.

    The whole compose log goes to ``artifacts`` too. The tail is in the error so that a CI log shows it, and
    the learner's log, Ray's view and the containers' states come last: a CI page keeps only an error's end.
    A stack whose state cannot be read says so: the caller's error, not the report's, is the one to raise.
    """
    try:
        if artifacts:
            stack.save_log(artifacts)
        lines = []
        for service in ("ray-worker", "teacher", "ray-head", "learner"):
            tail = stack.compose("logs", "--no-color", "--timestamps", "--tail", str(STUCK_LOG_LINES), service)
            lines += [f"--- the last {STUCK_LOG_LINES} lines of {service}'s log:", tail.rstrip()]
        for head in stack.containers("ray-head"):
            # The cluster's own view: which nodes it counts alive, and any actor still waiting for a place.
            status = run(["docker", "exec", head, "ray", "status"], timeout=60, check=False)
            lines += ["--- `ray status` on the head:", status.rstrip()]
        lines.append("--- the containers:")
        lines += [
            f"{state['name']}: {state['status']} (exit {state['exit_code']}, {state['restarts']} restarts, "
            f"health {state['health']})"
            for state in sorted(stack.states().values(), key=lambda state: state["name"])
        ]
    except Exception as error:  # any failure to read the stack is reported: the caller has the error to raise
        return f"(its state could not be read: {type(error).__name__}: {error})"
    return "\n".join(lines)


def exited_cleanly(state: dict[str, Any]) -> bool:
    """A container that ended with exit code 0: for the learner, a run that reached its budget."""
    return bool(state["status"] == "exited" and state["exit_code"] == 0)


def learner_finished(stack: Stack) -> bool:
    states = stack.inspect(*stack.containers("learner"))
    return any(exited_cleanly(state) for state in states.values())


def inject(stack: Stack, fault: Fault, rng: random.Random) -> None:
    """Do one fault; ``done`` False with a note when it could not be done (the container was down)."""
    candidates = stack.containers(fault.role)
    if not candidates:
        fault.note = "no container"
        return
    fault.container = rng.choice(candidates)
    state = stack.inspect(fault.container).get(fault.container, {})
    if not state.get("running"):
        fault.note = f"container not running ({state.get('status')}): still coming back from an earlier fault?"
        return
    fault.started = time.time()
    if fault.kind == "kill":
        # With `init: true` the init process survives `kill -1`; the service dies and the restart policy acts.
        result = subprocess.run(
            ["docker", "exec", fault.container, "sh", "-c", "kill -KILL -1"], capture_output=True, timeout=60
        )
        fault.done = result.returncode == 0 or b"is not running" not in result.stderr
        if result.returncode != 0:
            fault.note = f"docker exec exited {result.returncode}: {result.stderr.decode(errors='replace').strip()}"
    else:
        run(["docker", "stop", "--time", "10", fault.container], timeout=120)
        run(["docker", "start", fault.container], timeout=120)
        fault.done = True


# --- the full disk ------------------------------------------------------------------------------------


def fill(folder: Path) -> int:
    """Allocate every free block of ``folder``'s file system to one file; returns the bytes left free."""
    with (folder / FILLER).open("wb") as filler:
        offset, chunk = 0, 64 << 20
        while chunk >= 4096:
            try:
                os.posix_fallocate(filler.fileno(), offset, chunk)
                offset += chunk
            except OSError:
                chunk //= 2
    usage = os.statvfs(folder)
    return usage.f_bavail * usage.f_frsize


@dataclass
class DiskFull:
    at_s: float = 0.0
    for_s: float = 0.0
    bytes_free_when_full: int = -1
    held_s: float = 0.0
    """How long it was full: ``for_s``, or less when freed after enough refusals."""
    probes: list[dict[str, Any]] = field(default_factory=list)
    health: list[dict[str, Any]] = field(default_factory=list)
    ok_again_after_free_s: float | None = None
    write_ok_after_free_s: float | None = None


def disk_full_period(stack: Stack, curriculum: str, disk: DiskFull, hold_s: float, refusals: int = 0) -> None:
    """Fill the teacher's file system, probe writes and health while full, free it, time the recovery.

    Held ``hold_s`` seconds, or only until ``refusals`` probes were refused with a 503 when that is given
    (the service takes writes for a while after the fill, until its database needs a page the disk lacks).
    """
    started = time.time()
    disk.bytes_free_when_full = fill(stack.data)
    tasks_url = f"{TEACHER_URL}/api/v1/curricula/{curriculum}/tasks"
    while time.time() < started + hold_s:
        if refusals and sum(probe["status"] == 503 for probe in disk.probes) >= refusals:
            break
        status, body, seconds = http("POST", tasks_url, {"count": 1}, timeout=15)
        detail = body.get("detail") if isinstance(body, dict) else body
        disk.probes.append({"t": time.time() - started, "status": status, "seconds": seconds, "detail": detail})
        h_status, h_body, _ = http("GET", f"{TEACHER_URL}/healthz", timeout=15)
        disk.health.append({"t": time.time() - started, "status": h_status, "body": h_body})
        time.sleep(1.0)
    (stack.data / FILLER).unlink()
    freed = time.time()
    disk.held_s = freed - started
    while time.time() < freed + 300 and (disk.ok_again_after_free_s is None or disk.write_ok_after_free_s is None):
        h_status, h_body, _ = http("GET", f"{TEACHER_URL}/healthz", timeout=15)
        healthy = h_status == 200 and isinstance(h_body, dict) and h_body.get("status") == "ok"
        if disk.ok_again_after_free_s is None and healthy:
            disk.ok_again_after_free_s = time.time() - freed
        if disk.write_ok_after_free_s is None and http("POST", tasks_url, {"count": 1}, timeout=15)[0] == 200:
            disk.write_ok_after_free_s = time.time() - freed
        time.sleep(1.0)


# --- what is checked at the end ----------------------------------------------------------------------


def copy_database(stack: Stack, destination: Path) -> Path:
    """A consistent copy of the live database (SQLite's backup, which takes the WAL along)."""
    source = sqlite3.connect(f"file:{stack.data / 'teacher.sqlite3'}?mode=ro", uri=True)
    target = sqlite3.connect(destination)
    with target:
        source.backup(target)
    source.close()
    target.close()
    return destination


def count_results(database: Path, delivered: list[dict[str, Any]]) -> dict[str, Any]:
    """Acknowledged task ids (the workers' log) against the stored results, by curriculum and task index."""
    acknowledged: dict[str, set[int]] = {}
    answered_by: dict[str, dict[str, Any]] = {}
    acks = Counter[str]()
    for record in delivered:
        for task_id in record.get("acknowledged", []):
            name, _, index = task_id.rpartition(":")
            acknowledged.setdefault(name, set()).add(int(index))
            answered_by[task_id] = record
        for key in ("accepted", "duplicates", "expired"):
            acks[key] += record.get(key, 0)
    with sqlite3.connect(database) as connection:
        ids = dict(connection.execute("SELECT name, id FROM curricula").fetchall())
        counts = {
            name: Counter(
                dict(
                    connection.execute(
                        "SELECT task_index, count(*) FROM results WHERE curriculum_id = ? GROUP BY task_index", (cid,)
                    ).fetchall()
                )
            )
            for name, cid in ids.items()
        }
    per_curriculum = {}
    lost_answers = Counter[str]()
    for name in sorted(set(acknowledged) | set(counts)):
        stored = counts.get(name, Counter())
        acked = acknowledged.get(name, set())
        for index in sorted(index for index in acked if stored[index] == 0):
            answer = answered_by[f"{name}:{index}"]
            lost_answers[
                f"{answer.get('accepted')} accepted, {answer.get('duplicates')} duplicates, "
                f"{answer.get('expired')} expired of {len(answer['acknowledged'])}"
            ] += 1
        per_curriculum[name] = {
            "acknowledged": len(acked),
            "stored": sum(stored.values()),
            "lost": len([index for index in acked if stored[index] == 0]),
            "duplicated": sum(count - 1 for count in stored.values() if count > 1),
            "stored_not_in_log": len([index for index in stored if index not in acked]),
        }
    statuses = Counter(str(record["status"]) for record in delivered if "status" in record)
    reasons = Counter(f"{record['status']}: {record.get('detail')}" for record in delivered if "status" in record)
    return {
        "per_curriculum": per_curriculum,
        "ack_counts": dict(acks),
        "lost_by_answer": dict(lost_answers.most_common()),
        "worker_5xx": dict(statuses),
        "worker_5xx_reasons": dict(reasons.most_common(8)),
    }


def replay_matches(database: Path, live: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Each curriculum rebuilt from its first stored result (stored fits installed where they were),
    compared with what the live service says of it."""
    from teacher_service.core.config import Settings
    from teacher_service.curricula import FIT_HISTORY
    from teacher_service.curriculum_spec import stored_spec
    from teacher_service.replay import replay
    from teacher_service.store import Store
    from teacher_service.teachers import make_teacher

    settings = Settings()
    store = Store(database)
    verdicts = {}
    try:
        for stored in store.curricula():
            spec = stored_spec(stored.spec)
            teacher = make_teacher(spec.teacher, spec.task_space(), spec.seed, spec.params)
            rebuilt = replay(
                store,
                stored.id,
                stored.name,
                teacher,
                task_window=settings.task_window,
                fit_history=FIT_HISTORY,
                recent_results=settings.recent_results,
                from_start=True,
            )
            state = live.get(stored.name, {})
            counters = state.get("curriculum", {}).get("counters", {})
            differences = []
            if json.loads(json.dumps(teacher.state())) != state.get("teacher"):
                differences.append("teacher state")
            pairs = {
                "tasks_issued": rebuilt.tasks_issued,
                "results_received": rebuilt.results_replayed,
                "fits_completed": rebuilt.fits_completed,
            }
            differences += [
                f"{name}: live {counters.get(name)}, replay {value}"
                for name, value in pairs.items()
                if counters.get(name) != value
            ]
            if rebuilt.lost_fits:
                differences.append(f"{len(rebuilt.lost_fits)} fits due and never recorded")
            verdicts[stored.name] = {"equal": not differences, "differences": differences, **pairs}
    finally:
        store.close()
    return verdicts


def learner_starts(log: str) -> list[dict[str, Any]]:
    """Each start of the learner's training (``docker logs --timestamps``): when, and the step it resumed at."""
    starts: list[dict[str, Any]] = []
    for line in log.splitlines():
        stamp, _, text = line.partition(" ")
        if text.startswith("run directory:"):
            starts.append({"at": utc(stamp), "resumed_from": 0})
        elif text.startswith("resuming from ") and starts:
            starts[-1]["resumed_from"] = int(text.rsplit(" ", 1)[-1].replace("_", ""))
    return starts


def steps_lost(starts: list[dict[str, Any]], records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    deaths = []
    for start in starts[1:]:
        before = [record["step"] for record in records if record["time"] < start["at"]]
        last = max(before, default=0)
        deaths.append({"restarted_at": start["at"], "last_step_logged": last, "resumed_from": start["resumed_from"],
                       "steps_lost": last - start["resumed_from"]})  # fmt: skip
    return deaths


def restarts_by_cause(faults: list[dict[str, Any]], timeline: list[dict[str, Any]]) -> dict[str, dict[str, int]]:
    """Restarts by the restart policy (the learner's, the Ray workers'), each counted against the
    last fault done before it was seen, by that fault's role; a kill's restart of its own container
    is left out, so what remains is what the fault took down with it (a head's death takes the
    nodes and the learner). Finer than the per-fault windows, which overlap when faults come often."""
    done = sorted((f for f in faults if f["done"]), key=lambda f: f["started"])
    caused = {role: {"learner": 0, "ray-worker": 0} for role in ROLES}
    for before, after in zip(timeline, timeline[1:], strict=False):
        earlier = [f for f in done if f["started"] <= after["t"]]
        if not earlier:
            continue
        cause = earlier[-1]
        for service, key in (("learner", "learner_restarts"), ("ray-worker", "worker_restarts")):
            caused[cause["role"]][service] += max(0, after.get(key, 0) - before.get(key, 0))
    for fault in done:
        if fault["kind"] == "kill" and fault["role"] in ("learner", "ray-worker"):
            caused[fault["role"]][fault["role"]] -= 1
    return caused


def summary(values: list[float]) -> dict[str, float | None]:
    return {
        "median": statistics.median(values) if values else None,
        "worst": max(values) if values else None,
        "count": len(values),
    }


# --- the run -----------------------------------------------------------------------------------------

DISK_FULL = "disk-full"
"""The schedule's entry for the full disk."""
QUIET_BEFORE_DISK_S, QUIET_AFTER_DISK_S = 5.0, 15.0
"""No fault this close to the full disk, so that what the writes get is the disk's doing."""


def parse_schedule(text: str) -> list[tuple[str, str]]:
    """``--schedule``: comma-separated ``role:kind`` entries and ``disk-full``, as (role, kind) pairs."""
    entries = []
    for entry in text.split(","):
        role, _, kind = entry.strip().partition(":")
        if role == DISK_FULL and not kind:
            entries.append((DISK_FULL, ""))
        elif role in ROLES and kind in KINDS:
            entries.append((role, kind))
        else:
            raise argparse.ArgumentTypeError(
                f"{entry!r} is neither {DISK_FULL} nor role:kind (roles {', '.join(ROLES)}; kinds {', '.join(KINDS)})"
            )
    return entries


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=1800.0, help="seconds of faults, from the first iteration")
    parser.add_argument("--fault-every", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0, help="the killer's")
    parser.add_argument("--steps", type=int, default=2_000_000, help="the run's step budget")
    parser.add_argument("--run-seed", type=int, default=0, help="the training run's seed: its run is alp-gmm-seed<N>")
    parser.add_argument("--disk-full-at", type=float, help="seconds into the faults (default: a third of the way)")
    parser.add_argument("--disk-full-for", type=float, default=120.0)
    parser.add_argument(
        "--disk-full-refusals", type=int, default=0, help="free the disk once this many probes got a 503 (0: hold it)"
    )
    parser.add_argument("--volume-mb", type=int, default=512, help="the teacher's file system")
    parser.add_argument("--min-faults", type=int, default=20, help="faults that must be done for a pass")
    parser.add_argument(
        "--schedule",
        type=parse_schedule,
        help="the faults in this order instead of drawn for --duration: role:kind or disk-full, comma-separated",
    )
    parser.add_argument(
        "--steps-between", type=int, default=8192, help="with --schedule: steps trained from one fault to the next"
    )
    parser.add_argument(
        "--aftermath", type=float, default=AFTERMATH_S, help="seconds after a fault in which restarts count as its own"
    )
    parser.add_argument("--start-timeout", type=float, default=600.0, help="from `up` to the first iteration")
    parser.add_argument("--finish-timeout", type=float, default=1800.0, help="after the faults, for the budget")
    parser.add_argument("--project", default="kcchaos", help="the compose project name")
    parser.add_argument("--out", type=Path, help="write the results here as JSON")
    parser.add_argument("--artifacts", type=Path, help="keep the logs, the timeline and the database copy here")
    return parser.parse_args(argv)


def run_settings(args: argparse.Namespace) -> dict[str, str]:
    """The stack's settings (its env file) for the run ``args`` ask for."""
    return {
        "KC_TEACHER_TOKEN": TOKEN,
        "TEACHER": "alp-gmm",
        "KUKA_ENV": "KukaGrasp-v0",
        "TOTAL_STEPS": str(args.steps),
        "ROLLOUT_WORKERS": "2",
        "ENVS_PER_WORKER": "4",
        "RAY_WORKER_CPUS": "2",
        "SEED": str(args.run_seed),
        "TRAIN_ARGS": TRAIN_ARGS,
    }


@dataclass
class Killer:
    """Does the run's faults and starts a thread that watches each one's recovery."""

    stack: Stack
    observer: Observer
    aftermath_s: float
    started: float
    """When the learner's first iteration was seen: fault times count from it."""
    faults: list[Fault] = field(default_factory=list)
    watchers: list[threading.Thread] = field(default_factory=list)

    def now_s(self) -> float:
        return time.time() - self.started

    def fault(self, role: str, kind: str, pick: random.Random, skip: str = "") -> Fault:
        """One fault, or one recorded as skipped for ``skip``; ``pick`` chooses among a role's replicas."""
        fault = Fault(at_s=self.now_s(), role=role, kind=kind)
        if skip:
            fault.note = skip
        elif fault.role == "learner" and learner_finished(self.stack):
            fault.note = "skipped: the learner has finished its run"
        else:
            records = metrics(self.stack, self.stack.run_name)
            fault.step_before = records[-1]["step"] if records else 0
            try:
                inject(self.stack, fault, pick)
            except Exception as error:  # a fault the bench could not do is recorded, not fatal
                fault.note = f"{type(error).__name__}: {error}"
            if fault.done:
                watcher = threading.Thread(
                    target=watch_recovery, args=(self.stack, self.observer, fault, self.aftermath_s), daemon=True
                )
                watcher.start()
                self.watchers.append(watcher)
        self.faults.append(fault)
        print(f"{fault.at_s:6.0f} s  {fault.kind:7} {fault.role:10} {'done' if fault.done else fault.note}",
              flush=True)  # fmt: skip
        return fault


def drawn_faults(killer: Killer, args: argparse.Namespace, disk: DiskFull, rng: random.Random) -> None:
    """Every ``--fault-every`` s for ``--duration`` s a role and a fault drawn at random; the disk full once."""
    disk_thread = threading.Thread(
        target=disk_full_period,
        args=(killer.stack, killer.stack.run_name, disk, args.disk_full_for, args.disk_full_refusals),
        daemon=True,
    )
    disk_started = False
    quiet_from, quiet_to = disk.at_s - QUIET_BEFORE_DISK_S, disk.at_s + args.disk_full_for + QUIET_AFTER_DISK_S
    next_fault = args.fault_every
    while True:
        now_s = killer.now_s()
        if not disk_started and now_s >= disk.at_s:
            disk_thread.start()
            disk_started = True
            print(f"{now_s:6.0f} s  disk full for {args.disk_full_for:.0f} s", flush=True)
        if next_fault > args.duration:
            break
        if now_s >= next_fault:
            role, kind = rng.choice(ROLES), rng.choice(KINDS)
            pick = random.Random(rng.random())  # which replica: drawn whether or not it is used
            killer.fault(role, kind, pick, skip="skipped: the disk is full" if quiet_from <= now_s <= quiet_to else "")
            next_fault += args.fault_every
        time.sleep(0.5)
    if disk_started:
        disk_thread.join()


def ready_for_next(stack: Stack, previous: Fault | None, step: int) -> bool:
    """The last fault's role is back and the learner has logged ``step`` (or has finished its run)."""
    if previous is not None and previous.done and previous.back_s is None:
        return False
    if learner_finished(stack):
        return True
    records = metrics(stack, stack.run_name)
    return bool(records) and records[-1]["step"] >= step


def scheduled_faults(killer: Killer, args: argparse.Namespace, disk: DiskFull, rng: random.Random) -> None:
    """``--schedule``'s entries in order, each once ``ready_for_next`` and ``--fault-every`` s after the last;
    a wait for a role that never comes back ends after ``RECOVERY_TIMEOUT_S`` (its fault then fails the run)."""
    previous: Fault | None = None
    not_before = time.time()
    step_then = 0
    for role, kind in args.schedule:
        deadline = time.time() + RECOVERY_TIMEOUT_S
        while time.time() < deadline and not (
            time.time() >= not_before and ready_for_next(killer.stack, previous, step_then + args.steps_between)
        ):
            time.sleep(0.5)
        records = metrics(killer.stack, killer.stack.run_name)
        step_then = records[-1]["step"] if records else 0
        if role == DISK_FULL:
            disk.at_s = killer.now_s()
            print(f"{disk.at_s:6.0f} s  disk full for {args.disk_full_for:.0f} s", flush=True)
            disk_full_period(killer.stack, killer.stack.run_name, disk, args.disk_full_for, args.disk_full_refusals)
            previous, not_before = None, time.time() + max(args.fault_every, QUIET_AFTER_DISK_S)
            continue
        previous = killer.fault(role, kind, random.Random(rng.random()))
        not_before = time.time() + args.fault_every


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    scratch = Path(tempfile.mkdtemp(prefix="kc-chaos-"))
    stack = Stack(scratch, args.project, args.volume_mb)
    try:
        stack.prepare()
        report = run_chaos(stack, args, sys.argv[1:] if argv is None else argv)
    finally:
        stack.down()
        shutil.rmtree(scratch, ignore_errors=True)
    print_report(report)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1) + "\n")
    return 0 if report.get("passed") else 1


def run_chaos(stack: Stack, args: argparse.Namespace, argv: list[str]) -> dict[str, Any]:
    """One run on a prepared ``stack``, up or not: start it, do the faults, let it reach its budget, check.

    The stack stays up, for its owner to take down; the report's ``passed`` is the verdict."""
    disk_full_at = args.duration / 3 if args.disk_full_at is None else args.disk_full_at
    settings = run_settings(args)
    run_name = f"{settings['TEACHER']}-seed{settings['SEED']}"
    scratch = Path(tempfile.mkdtemp(prefix="kc-chaos-run-"))
    observer = Observer(stack, run_name)
    rng = random.Random(args.seed)
    disk = DiskFull(at_s=disk_full_at, for_s=args.disk_full_for)
    report: dict[str, Any] = {
        "command": shlex.join(["bench/chaos.py", *argv]),
        "date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "commit": commit(),
        "machine": machine(),
        "settings": {k: v for k, v in settings.items() if k != "KC_TEACHER_TOKEN"} | {
            "duration_s": args.duration, "fault_every_s": args.fault_every, "seed": args.seed,
            "disk_full_at_s": disk_full_at, "disk_full_for_s": args.disk_full_for, "volume_mb": args.volume_mb,
            "disk_full_refusals": args.disk_full_refusals,
            "schedule": [":".join(filter(None, entry)) for entry in args.schedule or []],
            "steps_between": args.steps_between if args.schedule else None, "aftermath_s": args.aftermath,
        },
    }  # fmt: skip
    try:
        up_at = time.time()
        stack.start_run(settings)
        deadline = time.time() + args.start_timeout
        while not metrics(stack, run_name):
            if time.time() > deadline:
                detail = stuck_at_start(stack, args.artifacts)
                waited = f"{args.start_timeout:.0f} s"
                raise RuntimeError(f"the learner logged no iteration within {waited} of `up`\n{detail}")
            time.sleep(2.0)
        killer = Killer(stack, observer, args.aftermath, started=time.time())
        report["up_to_first_iteration_s"] = killer.started - up_at
        observer.thread.start()
        if args.schedule:
            print(f"training; the faults in order: {', '.join(report['settings']['schedule'])}", flush=True)
            scheduled_faults(killer, args, disk, rng)
        else:
            print(f"training; faults every {args.fault_every:.0f} s for {args.duration:.0f} s, "
                  f"disk full at {disk_full_at:.0f} s for {args.disk_full_for:.0f} s", flush=True)  # fmt: skip
            drawn_faults(killer, args, disk, rng)

        print("faults over; waiting for the run to reach its budget", flush=True)
        deadline = time.time() + args.finish_timeout
        while not learner_finished(stack) and time.time() < deadline:
            time.sleep(5.0)
        for watcher in killer.watchers:
            watcher.join(timeout=max(0.0, deadline - time.time()))
        # Settle: no fit pending and the counters still for a few seconds.
        last: Any = None
        for _ in range(120):
            status, body, _ = http("GET", f"{TEACHER_URL}/api/v1/curricula/{run_name}")
            counters = body.get("counters", {}) if status == 200 and isinstance(body, dict) else None
            if counters:
                counters = {
                    k: counters[k] for k in ("tasks_issued", "results_received", "fits_completed", "fits_pending")
                }
            if counters and not counters["fits_pending"] and counters == last:
                break
            last = counters
            time.sleep(3.0)
        observer.stop.set()
        final = observer.sample()

        live = {}
        status, listing, _ = http("GET", f"{TEACHER_URL}/api/v1/curricula")
        names = [entry["name"] for entry in listing["curricula"]] if status == 200 else [run_name]
        for name in names:
            live[name] = http("GET", f"{TEACHER_URL}/api/v1/curricula/{name}/state?recent=0", timeout=60)[1]
        database = copy_database(stack, scratch / "teacher-copy.sqlite3")
        delivery_log = stack.logs / "delivered.jsonl"
        delivered = (
            [json.loads(line) for line in delivery_log.read_text().splitlines()] if delivery_log.exists() else []
        )
        learner_ids = stack.containers("learner")
        learner_log = run(["docker", "logs", "--timestamps", learner_ids[0]], check=False) if learner_ids else ""
        records = metrics(stack, run_name)
        states = stack.states()

        results = count_results(database, delivered)
        replayed = replay_matches(database, live)
        deaths = steps_lost(learner_starts(learner_log), records)
        checked = evaluate(args, killer.faults, disk, results, replayed, deaths, records, states, learner_log, final)
        report.update(checked)
        report["timeline_samples"] = len(observer.timeline)
        report["restarts_by_cause"] = restarts_by_cause(report["faults"], observer.timeline)
        if args.artifacts:
            args.artifacts.mkdir(parents=True, exist_ok=True)
            shutil.copy(database, args.artifacts / "teacher-copy.sqlite3")
            (args.artifacts / "timeline.json").write_text(json.dumps(observer.timeline))
            (args.artifacts / "learner.log").write_text(learner_log)
            if delivery_log.exists():
                shutil.copy(delivery_log, args.artifacts / "delivered.jsonl")
            stack.save_log(args.artifacts)
    finally:
        observer.stop.set()
        shutil.rmtree(scratch, ignore_errors=True)
    return report


def evaluate(
    args: argparse.Namespace,
    faults: list[Fault],
    disk: DiskFull,
    results: dict[str, Any],
    replayed: dict[str, Any],
    deaths: list[dict[str, Any]],
    records: list[dict[str, Any]],
    states: dict[str, dict[str, Any]],
    learner_log: str,
    final: dict[str, Any],
) -> dict[str, Any]:
    done = [fault for fault in faults if fault.done]
    by_role = {}
    for role in ROLES:
        mine = [fault for fault in done if fault.role == role]
        by_role[role] = {
            "faults": len(mine),
            "kill": sum(fault.kind == "kill" for fault in mine),
            "restart": sum(fault.kind == "restart" for fault in mine),
            "back_s": summary([f.back_s for f in mine if f.back_s is not None]),
            "progress_regained_s": summary([f.progress_regained_s for f in mine if f.progress_regained_s is not None]),
            "learner_restarts_after": sum(f.learner_restarts for f in mine),
            "worker_restarts_after": sum(f.worker_restarts for f in mine),
        }
    learners = [state for state in states.values() if state["name"].split("_")[1] == "learner"]
    final_step = records[-1]["step"] if records else 0
    last_line = learner_log.strip().splitlines()[-1].partition(" ")[2] if learner_log.strip() else ""
    reached = (
        final_step >= args.steps
        and bool(learners)
        and all(exited_cleanly(s) for s in learners)
        and last_line.startswith("final checkpoint: ")
    )
    per = results["per_curriculum"]
    lost = sum(entry["lost"] for entry in per.values())
    duplicated = sum(entry["duplicated"] for entry in per.values())
    acknowledged = sum(entry["acknowledged"] for entry in per.values())
    probes = disk.probes
    probe_statuses = Counter(str(probe["status"]) for probe in probes)
    refused = [p for p in probes if p["status"] == 503]
    with_reason = [p for p in refused if p["detail"] and "disk" in str(p["detail"])]
    hung = [p for p in probes if p["status"] == 0 or p["seconds"] > 10.0]
    bad_5xx = [p for p in probes if p["status"] >= 500 and p["status"] != 503]
    degraded = [h for h in disk.health if isinstance(h["body"], dict) and h["body"].get("status") == "degraded"]
    worker_500s = {status: n for status, n in results["worker_5xx"].items() if status != "503"}
    disk_ok = (
        bool(refused)
        and len(with_reason) == len(refused)
        and not hung
        and not bad_5xx
        and not worker_500s
        and bool(degraded)
        and disk.ok_again_after_free_s is not None
        and disk.write_ok_after_free_s is not None
    )
    not_back = [f"{f.role} {f.kind} at {f.at_s:.0f} s" for f in done if f.back_s is None]
    services_up = {
        state["name"]: state["status"] for state in states.values() if state["name"].split("_")[1] != "learner"
    }
    hands_off = not not_back and all(status == "running" for status in services_up.values())
    criteria = {
        "faults": {
            "pass": len(done) >= args.min_faults,
            "detail": f"{len(done)} faults done of {len(faults)} scheduled",
        },
        "budget reached": {
            "pass": reached, "detail": f"final step {final_step:,} of {args.steps:,}; last line {last_line!r}",
        },
        "results stored exactly once": {
            "pass": lost == 0 and duplicated == 0 and acknowledged > 0,
            "detail": f"{acknowledged:,} acknowledged, {lost} lost, {duplicated} duplicated"
            + (f"; the answers that acknowledged the lost: {results['lost_by_answer']}" if lost else ""),
        },
        "disk full: 503 with the reason, degraded, recovers": {
            "pass": disk_ok,
            "detail": f"probes {dict(probe_statuses)}, {len(with_reason)} of {len(refused)} 503s name the disk, "
            f"{len(hung)} hung or unanswered, /healthz degraded {len(degraded)} times, ok again "
            f"{disk.ok_again_after_free_s} s and a write accepted {disk.write_ok_after_free_s} s after freeing; "
            f"workers saw 5xx {results['worker_5xx']}",
        },
        "state equals a replay": {
            "pass": bool(replayed) and all(v["equal"] for v in replayed.values()),
            "detail": "; ".join(f"{n}: {'equal' if v['equal'] else v['differences']}" for n, v in replayed.items()),
        },
        "no role needed a hand": {
            "pass": hands_off,
            "detail": f"not back: {not_back or 'none'}; at the end {services_up}",
        },
    }  # fmt: skip
    return {
        "faults": [asdict(fault) for fault in faults],
        "faults_by_role": by_role,
        "learner_deaths": deaths,
        "disk_full": asdict(disk) | {"probe_statuses": dict(probe_statuses)},
        "results": results,
        "replay": replayed,
        "final": {"step": final_step, "budget": args.steps, "states": states, "last_sample": final},
        "criteria": criteria,
        "passed": all(c["pass"] for c in criteria.values()),
    }


def print_report(report: dict[str, Any]) -> None:
    if "criteria" not in report:
        print("the run did not get as far as its checks")
        return

    def seconds(value: float | None) -> str:
        return "-" if value is None else f"{value:.1f}"

    print(
        "\nrole        faults  kill  restart  back (median / worst s)  training past its step (median / worst s)"
        "  learner / worker restarts within 120 s"
    )
    for role, row in report["faults_by_role"].items():
        back, regained = row["back_s"], row["progress_regained_s"]
        print(f"{role:11} {row['faults']:6} {row['kill']:5} {row['restart']:8}  "
              f"{seconds(back['median']):>8} / {seconds(back['worst']):<8}      "
              f"{seconds(regained['median']):>8} / {seconds(regained['worst']):<8}                 "
              f"{row['learner_restarts_after']} / {row['worker_restarts_after']}")  # fmt: skip
    for role, caused in report.get("restarts_by_cause", {}).items():
        print(f"after {role} faults the restart policy also restarted the learner {caused['learner']} times, "
              f"a Ray worker {caused['ray-worker']} times")  # fmt: skip
    for death in report["learner_deaths"]:
        print(f"learner restart: last step logged {death['last_step_logged']:,}, resumed from "
              f"{death['resumed_from']:,}: {death['steps_lost']:,} steps lost")  # fmt: skip
    for name, criterion in report["criteria"].items():
        print(f"{'PASS' if criterion['pass'] else 'FAIL'}  {name}: {criterion['detail']}")


if __name__ == "__main__":
    sys.exit(main())
