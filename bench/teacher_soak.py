"""Soak test of the teacher service as many training runs share it: concurrent clients register
curricula of every kind, draw tasks, abandon some, report results in batches, and keep going through
a SIGKILL and restart of the service in the middle of the run.

Prints results sent and acknowledged against results stored (read from the database afterwards),
the service's memory over time, the restart time, request latency (p50, p99, max) and any 5xx.
What must hold: every acknowledged result is stored, memory stays flat, no 5xx.

    .venv/bin/python bench/teacher_soak.py --minutes 5 --clients 16
"""

from __future__ import annotations

import argparse
import asyncio
import random
import sqlite3
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common.client.schemas import ParameterSpec  # noqa: E402
from common.kuka.task_space import KUKA_TASK_SPACE  # noqa: E402
from teacher_service.process import ServiceProcess  # noqa: E402
from teacher_service.teachers import TEACHER_KINDS  # noqa: E402

KINDS = tuple(TEACHER_KINDS)
SOAK_PARAMS: dict[str, dict[str, object]] = {
    "alp-gmm": {"fit_rate": 250, "history_window": 10_000},
    "riac": {"max_regions": 100},
}
"""ALP-GMM with its smallest nearest-task window and RIAC with few regions, so that their curricula
reach their memory bounds within minutes; every other kind with its defaults."""
SOAK_SERVICE_ENV = {"KC_TASK_WINDOW": "2000"}
"""A task is forgotten 2,000 tasks after it was handed out (the default is 10,000), for the same
reason: each curriculum's bookkeeping of tasks awaiting results reaches its bound within the soak."""
ABANDON_SHARE = 0.05
"""Share of drawn tasks whose episode is 'lost' and never reported."""
MOVE_EVERY_S = 30.0
"""How often a client moves to another of its curricula, registering it (again: a PUT of the same
curriculum is idempotent), so registrations go on all through the soak."""
CURRICULA_PER_CLIENT = 3
"""Each client's curricula: a fixed set, so that memory can level off once each is in use."""
EPISODE_TIME_S = 0.02
"""What one batch of episodes 'takes' between a draw and its report."""
SPACE = [ParameterSpec.from_parameter(p).model_dump() for p in KUKA_TASK_SPACE.parameters]


@dataclass
class Tally:
    """What the clients saw, all of them together."""

    sent: int = 0
    acknowledged: set[tuple[str, str]] = field(default_factory=set)
    abandoned: int = 0
    registrations: int = 0
    latencies: dict[str, list[float]] = field(default_factory=dict)
    server_errors: list[str] = field(default_factory=list)
    refused_outside_outage: list[str] = field(default_factory=list)
    outage: bool = False

    def latency(self, endpoint: str, seconds: float) -> None:
        self.latencies.setdefault(endpoint, []).append(seconds)


def _reward(params: dict[str, float], rng: random.Random) -> float:
    """A student that does better on low jp2 and a narrow block range, with noise."""
    return 6.0 * (1.0 - params["rnd_obj_x"]) * (1.3 - params["jp2"]) + rng.gauss(0.0, 0.5)


async def _call(
    client: httpx.AsyncClient, tally: Tally, endpoint: str, method: str, path: str, body: object
) -> httpx.Response | None:
    """One request; ``None`` when the service cannot be reached (the clients then retry)."""
    started = time.perf_counter()
    try:
        response = await client.request(method, path, json=body)
    except httpx.TransportError as error:
        if not tally.outage:
            tally.refused_outside_outage.append(f"{endpoint}: {type(error).__name__}")
        return None
    tally.latency(endpoint, time.perf_counter() - started)
    if response.status_code >= 500:
        tally.server_errors.append(f"{endpoint} {response.status_code}: {response.text[:200]}")
        return None
    return response


async def _register(client: httpx.AsyncClient, tally: Tally, name: str, kind: str, seed: int) -> None:
    body = {"teacher": kind, "space": SPACE, "params": SOAK_PARAMS.get(kind, {}), "seed": seed}
    while (response := await _call(client, tally, "put", "PUT", f"/api/v1/curricula/{name}", body)) is None:
        await asyncio.sleep(0.2)
    response.raise_for_status()
    tally.registrations += 1


async def _run_client(number: int, url: str, tally: Tally, deadline: float, progress: tqdm) -> None:
    rng = random.Random(number)
    async with httpx.AsyncClient(base_url=url, timeout=10.0) as client:
        generation = 0
        kind = KINDS[number % len(KINDS)]
        name = f"soak-{kind}-{number}-0"
        await _register(client, tally, name, kind, number)
        moved_at = time.monotonic()
        unreported: list[dict[str, object]] = []
        while unreported or time.monotonic() < deadline:
            if time.monotonic() - moved_at > MOVE_EVERY_S and not unreported:
                generation = (generation + 1) % CURRICULA_PER_CLIENT
                kind = KINDS[(number + generation) % len(KINDS)]
                name = f"soak-{kind}-{number}-{generation}"
                await _register(client, tally, name, kind, number)
                moved_at = time.monotonic()
            if not unreported:
                count = rng.randint(1, 8)
                response = await _call(
                    client, tally, "tasks", "POST", f"/api/v1/curricula/{name}/tasks", {"count": count}
                )
                if response is None:
                    await asyncio.sleep(0.2)
                    continue
                response.raise_for_status()
                await asyncio.sleep(EPISODE_TIME_S)
                for task in response.json()["tasks"]:
                    if rng.random() < ABANDON_SHARE:
                        tally.abandoned += 1
                    else:
                        unreported.append({"task_id": task["task_id"], "reward": _reward(task["params"], rng)})
                tally.sent += len(unreported)
            response = await _call(
                client, tally, "results", "POST", f"/api/v1/curricula/{name}/results", {"results": unreported}
            )
            if response is None:
                await asyncio.sleep(0.2)
                continue
            response.raise_for_status()
            tally.acknowledged.update((name, str(item["task_id"])) for item in unreported)
            progress.update(len(unreported))
            unreported = []


def _rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for process {pid}")


def _stored(db: Path) -> set[tuple[str, str]]:
    with sqlite3.connect(db) as connection:
        rows = connection.execute(
            "SELECT c.name, r.task_index FROM results r JOIN curricula c ON c.id = r.curriculum_id"
        ).fetchall()
    return {(name, f"{name}:{index}") for name, index in rows}


async def _soak(service: ServiceProcess, clients: int, seconds: float, memory_every_s: float) -> dict[str, object]:
    tally = Tally()
    start = time.monotonic()
    deadline = start + seconds
    memory: list[tuple[float, float]] = []
    """(seconds into the soak, service RSS in MiB); the reading at ``kill_reading`` is the last before the kill."""
    restart_s, kill_reading = 0.0, 0
    with tqdm(desc="results acknowledged", unit="result", disable=None) as progress:
        workers = [
            asyncio.create_task(_run_client(number, service.url, tally, deadline, progress))
            for number in range(clients)
        ]
        killed = False
        while not all(worker.done() for worker in workers):
            await asyncio.sleep(memory_every_s)
            elapsed = time.monotonic() - start
            if not killed and elapsed >= seconds / 2:
                memory.append((elapsed, _rss_mib(service.pid)))
                kill_reading = len(memory) - 1
                tally.outage = True
                service.kill()
                began = time.perf_counter()
                await asyncio.to_thread(service.start, 120.0)
                restart_s = time.perf_counter() - began
                tally.outage = False
                killed = True
            memory.append((time.monotonic() - start, _rss_mib(service.pid)))
        for worker in workers:
            worker.result()
    return {"tally": tally, "memory": memory, "restart_s": restart_s, "kill_reading": kill_reading}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=5.0, help="length of the soak (default 5)")
    parser.add_argument("--clients", type=int, default=16, help="concurrent clients (default 16)")
    parser.add_argument("--memory-every", type=float, default=5.0, help="seconds between memory readings")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="teacher-soak-") as directory:
        db = Path(directory) / "teacher.db"
        service = ServiceProcess(db, env=SOAK_SERVICE_ENV)
        service.start()
        try:
            outcome = asyncio.run(_soak(service, args.clients, args.minutes * 60, args.memory_every))
        finally:
            service.stop()
        stored = _stored(db)

    tally: Tally = outcome["tally"]  # type: ignore[assignment]
    memory: list[tuple[float, float]] = outcome["memory"]  # type: ignore[assignment]
    lost = tally.acknowledged - stored
    latencies = np.concatenate([np.array(values) for values in tally.latencies.values()])
    print(f"\nsoak: {args.clients} clients, {args.minutes:g} min, one SIGKILL and restart half-way")
    print(f"registrations (PUT): {tally.registrations}, curricula: at most {args.clients * CURRICULA_PER_CLIENT}")
    print(f"results sent: {tally.sent}, acknowledged: {len(tally.acknowledged)}, stored: {len(stored)}")
    print(f"acknowledged but not stored: {len(lost)}; tasks abandoned (never reported): {tally.abandoned}")
    print(f"restart to first /healthz answer: {outcome['restart_s']:.2f} s")
    kill: int = outcome["kill_reading"]  # type: ignore[assignment]
    print(
        "service memory (RSS, MiB): "
        f"before the kill {memory[0][1]:.0f} -> {memory[kill][1]:.0f}, "
        f"after the restart {memory[kill + 1][1]:.0f} -> {memory[-1][1]:.0f}"
    )
    print("  readings: " + ", ".join(f"{at:.0f}s {mib:.0f}" for at, mib in memory))
    for endpoint, values in sorted(tally.latencies.items()):
        ms = np.array(values) * 1000
        print(
            f"latency {endpoint:8s} n={len(ms):6d}  p50 {np.percentile(ms, 50):6.1f} ms"
            f"  p99 {np.percentile(ms, 99):6.1f} ms  max {ms.max():7.1f} ms"
        )
    print(f"latency all      n={len(latencies):6d}  p99 {np.percentile(latencies, 99) * 1000:6.1f} ms")
    print(f"5xx answers: {len(tally.server_errors)}", *tally.server_errors[:5], sep="\n  ")
    print(f"connection failures outside the outage: {len(tally.refused_outside_outage)}")
    if lost or tally.server_errors:
        raise SystemExit("FAILED: results lost or server errors")


if __name__ == "__main__":
    main()
