"""A fleet on one teacher service: many simulated workers over several curricula for minutes.

Each worker draws ``--batch`` tasks, "plays" them for a random 0.5 to 2 s, and reports their results;
``--workers`` of them share one real ``serve`` over ten curricula of four kinds on the KUKA box
(ALP-GMM, CURROT, learnability and random, the adaptive ones fitting as they go). Prints the requests
by status (5xx must be 0), p50 and p99 per endpoint, results per second, the service's CPU seconds per
result and results per second of service CPU (its fit processes included), the main process's own
CPU per result (HTTP, teachers and store, without the fits), its memory at the start and the end, and
the generator's own CPU beside it.

    .venv/bin/python bench/teacher_fleet.py --workers 1000 --seconds 600             # one task a request
    .venv/bin/python bench/teacher_fleet.py --workers 32 --batch 32 --seconds 600    # 32 a request

The workers speak HTTP/1.1 over raw asyncio streams with keep-alive, one connection each (the
``Connection`` of ``teacher_load.py``), so the generator stays a fraction of a core. Goals (issue 60):
p99 under 100 ms at 1,000 workers; at least 3,000 results per second of service CPU with batching.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.provenance import commit, machine  # noqa: E402
from bench.teacher_load import Connection, cpu_seconds, free_port, http_json, percentile_ms, wait_healthy  # noqa: E402
from common.client.schemas import API_PREFIX, ParameterSpec  # noqa: E402
from common.kuka.task_space import KUKA_TASK_SPACE  # noqa: E402

CURRICULA = {
    "alp-gmm-0": ("alp-gmm", {"fit_rate": 250}),
    "alp-gmm-1": ("alp-gmm", {"fit_rate": 250}),
    "alp-gmm-2": ("alp-gmm", {"fit_rate": 250}),
    "currot-0": ("currot", {}),
    "currot-1": ("currot", {}),
    "currot-2": ("currot", {}),
    "learnability-0": ("learnability", {}),
    "learnability-1": ("learnability", {}),
    "random-0": ("random", {}),
    "random-1": ("random", {}),
}
"""Ten curricula: each worker is assigned one in turn."""


@dataclass
class Tally:
    """What the workers saw: latencies by endpoint and answers by status."""

    seconds: dict[str, list[float]] = field(default_factory=lambda: {"tasks": [], "results": []})
    statuses: Counter[int] = field(default_factory=Counter)
    results: int = 0
    failures: list[str] = field(default_factory=list)


async def worker(port: int, index: int, batch: int, stop: float, tally: Tally) -> None:
    rng = np.random.default_rng(index)
    name = list(CURRICULA)[index % len(CURRICULA)]
    base = f"{API_PREFIX}/curricula/{name}"
    await asyncio.sleep(float(rng.uniform(0.0, 2.0)))  # the fleet does not start in step
    try:
        connection = await Connection.open("127.0.0.1", port)
    except OSError as error:
        tally.failures.append(f"connect: {error}")
        return
    try:
        while time.perf_counter() < stop:
            started = time.perf_counter()
            status, content = await connection.send(f"{base}/tasks", {"count": batch})
            drawn = time.perf_counter()
            tally.statuses[status] += 1
            if status != 200:
                await asyncio.sleep(1.0)
                continue
            tally.seconds["tasks"].append(drawn - started)
            tasks = json.loads(content)["tasks"]
            await asyncio.sleep(float(rng.uniform(0.5, 2.0)))
            results = [
                {"task_id": task["task_id"], "reward": float(rng.normal()), "success": bool(rng.random() < 0.3)}
                for task in tasks
            ]
            sent = time.perf_counter()
            status, _ = await connection.send(f"{base}/results", {"results": results})
            tally.statuses[status] += 1
            if status == 200:
                tally.seconds["results"].append(time.perf_counter() - sent)
                tally.results += len(results)
    except (OSError, asyncio.IncompleteReadError) as error:
        tally.failures.append(f"{type(error).__name__}: {error}")
    finally:
        connection.close()


def family(pid: int) -> list[int]:
    """The process and its live descendants (the fit processes)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError):
                continue
            children.setdefault(parent, []).append(int(entry.name))
    found, queue = [], [pid]
    while queue:
        current = queue.pop()
        found.append(current)
        queue += children.get(current, [])
    return found


def family_cpu_seconds(pid: int) -> float:
    """CPU seconds of the service, its live descendants, and the children it has reaped."""
    total = 0.0
    for member in family(pid):
        try:
            total += cpu_seconds(member)
        except OSError:
            continue
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return total + (int(fields[13]) + int(fields[14])) / os.sysconf("SC_CLK_TCK")


def family_rss_mb(pid: int) -> float:
    total = 0
    for member in family(pid):
        try:
            for line in Path(f"/proc/{member}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1])
        except OSError:
            continue
    return total / 1024


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=1000)
    parser.add_argument("--batch", type=int, default=1, help="tasks drawn and results reported per request")
    parser.add_argument("--seconds", type=float, default=600.0)
    parser.add_argument("--out", type=Path, help="also write the figures here as JSON")
    args = parser.parse_args()
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    needed = args.workers + 256
    if soft < needed:
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(needed, hard), hard))  # the service inherits it

    port = free_port()
    url = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory() as scratch:
        command = [sys.executable, "-m", "kuka_curriculum", "serve", "--port", str(port)]
        command += ["--db", str(Path(scratch) / "fleet.db"), "--log-level", "warning"]
        server = subprocess.Popen(command, cwd=Path(__file__).resolve().parents[1])
        try:
            wait_healthy(url, server)
            space = [ParameterSpec.from_parameter(p).model_dump() for p in KUKA_TASK_SPACE.parameters]
            for name, (kind, params) in CURRICULA.items():
                http_json(
                    "PUT", f"{url}{API_PREFIX}/curricula/{name}", {"teacher": kind, "space": space, "params": params}
                )
            memory_start = family_rss_mb(server.pid)
            service_cpu, generator_cpu = family_cpu_seconds(server.pid), time.process_time()
            main_cpu = cpu_seconds(server.pid)
            tally = Tally()
            started = time.perf_counter()
            stop = started + args.seconds

            async def fleet() -> None:
                await asyncio.gather(*(worker(port, i, args.batch, stop, tally) for i in range(args.workers)))

            asyncio.run(fleet())
            elapsed = time.perf_counter() - started
            service_cpu = family_cpu_seconds(server.pid) - service_cpu
            main_cpu = cpu_seconds(server.pid) - main_cpu
            generator_cpu = time.process_time() - generator_cpu
            memory_end = family_rss_mb(server.pid)
        finally:
            server.terminate()
            server.wait(timeout=60)

    server_errors = sum(count for status, count in tally.statuses.items() if status >= 500)
    figures = {
        "workers": args.workers,
        "batch": args.batch,
        "seconds": round(elapsed, 1),
        "statuses": dict(sorted(tally.statuses.items())),
        "server_errors": server_errors,
        "failures": len(tally.failures),
        "results": tally.results,
        "results_per_s": round(tally.results / elapsed, 1),
        **{
            f"{endpoint}_p{q}_ms": round(percentile_ms(tally.seconds[endpoint], q), 1)
            for endpoint in ("tasks", "results")
            for q in (50, 99)
        },
        "service_cpu_ms_per_result": round(1000 * service_cpu / max(tally.results, 1), 3),
        "results_per_service_cpu_s": round(tally.results / max(service_cpu, 1e-9), 0),
        "service_main_cpu_ms_per_result": round(1000 * main_cpu / max(tally.results, 1), 3),
        "service_busy_cores": round(service_cpu / elapsed, 2),
        "generator_busy_cores": round(generator_cpu / elapsed, 2),
        "service_rss_mb": [round(memory_start, 0), round(memory_end, 0)],
        "commit": commit(),
        "machine": machine(),
        "load_average": round(os.getloadavg()[0], 1),
    }
    print(json.dumps(figures, indent=1))
    if tally.failures:
        print("first failures:", *tally.failures[:5], sep="\n  ")
    if args.out:
        args.out.write_text(json.dumps(figures, indent=1) + "\n")
    return 1 if server_errors or tally.failures else 0


if __name__ == "__main__":
    sys.exit(main())
