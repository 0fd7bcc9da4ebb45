"""Load test of the teacher service: a real uvicorn on localhost and N concurrent clients, each
looping draw-one-task -> report-one-result for a fixed time, against an ALP-GMM curriculum with a
small fit_rate so the teacher refits during the run.

Prints episode round trips per second, p50/p99 latency per endpoint, and p99 while a refit is
running versus outside refits, next to the targets for 2 cores and 32 clients: at least 1,000
round trips/s, p99 under 50 ms, p99 during refits at most twice p99 outside them.

    .venv/bin/python bench/teacher_load.py --clients 32 --seconds 20

The clients speak HTTP/1.1 over raw asyncio streams with keep-alive: a general-purpose Python HTTP
client costs more CPU per request than the service itself, and would mostly measure itself.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common.client.schemas import API_PREFIX, ParameterSpec  # noqa: E402
from common.kuka.task_space import KUKA_TASK_SPACE  # noqa: E402

CURRICULUM = "load"
TARGET_ROUND_TRIPS = 1000.0
TARGET_P99_S = 0.050
TARGET_REFIT_RATIO = 2.0


@dataclass(frozen=True)
class Sample:
    endpoint: str
    started_at: float
    """Wall-clock start, comparable with the service's fit timestamps."""
    seconds: float


class Connection:
    """One keep-alive HTTP/1.1 connection sending JSON POSTs."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, host: str) -> None:
        self._reader, self._writer, self._host = reader, writer, host

    @classmethod
    async def open(cls, host: str, port: int) -> Connection:
        reader, writer = await asyncio.open_connection(host, port)
        writer.get_extra_info("socket").setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return cls(reader, writer, host)

    async def send(self, path: str, payload: object) -> tuple[int, bytes]:
        """POST ``payload`` as JSON; the status and the body of the answer."""
        body = json.dumps(payload).encode()
        head = (
            f"POST {path} HTTP/1.1\r\nHost: {self._host}\r\nContent-Type: application/json\r\n"
            f"Content-Length: {len(body)}\r\n\r\n"
        ).encode()
        self._writer.write(head + body)
        status_line, *header_lines = (await self._reader.readuntil(b"\r\n\r\n")).decode().split("\r\n")
        headers = dict(line.split(": ", 1) for line in header_lines if line)
        content = await self._reader.readexactly(int(headers.get("content-length", "0")))
        return int(status_line.split()[1]), content

    async def post(self, path: str, payload: object) -> object:
        status, content = await self.send(path, payload)
        if status != 200:
            raise RuntimeError(f"POST {path} -> {status}: {content[:200]!r}")
        return json.loads(content)

    def close(self) -> None:
        self._writer.close()


def synthetic_reward(params: dict[str, float], rng: np.random.Generator) -> float:
    """A student that finds the easy end of the box easy, with noise so ALP is not zero."""
    difficulty = float(np.mean(KUKA_TASK_SPACE.to_unit(KUKA_TASK_SPACE.to_array(params))))
    return 10.0 * (1.0 - difficulty) - 3.0 + float(rng.normal(0.0, 1.0))


async def client_loop(
    host: str, port: int, seed: int, batch: int, started: float, warmup: float, stop: float, samples: list[Sample]
) -> None:
    rng = np.random.default_rng(seed)
    connection = await Connection.open(host, port)
    tasks_path = f"{API_PREFIX}/curricula/{CURRICULUM}/tasks"
    results_path = f"{API_PREFIX}/curricula/{CURRICULUM}/results"
    try:
        while (now := time.perf_counter()) < stop:
            wall = time.time()
            drawn_tasks = (await connection.post(tasks_path, {"count": batch}))["tasks"]  # type: ignore[index]
            drawn = time.perf_counter()
            results = []
            for task in drawn_tasks:
                reward = synthetic_reward(task["params"], rng)
                results.append({"task_id": task["task_id"], "reward": reward, "success": reward > 5.0, "length": 100})
            await connection.post(results_path, {"results": results})
            reported = time.perf_counter()
            if now >= started + warmup:
                samples.append(Sample("tasks", wall, drawn - now))
                samples.append(Sample("results", wall + (drawn - now), reported - drawn))
    finally:
        connection.close()


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def http_json(method: str, url: str, payload: object | None = None) -> object:
    data = None if payload is None else json.dumps(payload).encode()
    request = urllib.request.Request(url, data=data, method=method, headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as response:
        return json.loads(response.read())


def wait_healthy(url: str, server: subprocess.Popen, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise RuntimeError(f"the service exited with {server.returncode}")
        try:
            http_json("GET", f"{url}/healthz")
            return
        except OSError:
            time.sleep(0.1)
    raise RuntimeError("the service did not become healthy")


def wait_for_fits(url: str, timeout: float = 300.0) -> None:
    """Let fits that ran during the measurement finish, so their start and end times are known."""
    deadline = time.monotonic() + timeout
    info_url = f"{url}{API_PREFIX}/curricula/{CURRICULUM}"
    while http_json("GET", info_url)["counters"]["fits_pending"]:  # type: ignore[index]
        if time.monotonic() > deadline:
            raise RuntimeError("fits still pending after the run; refit windows are unknown")
        time.sleep(0.2)


def percentile_ms(seconds: list[float], q: float) -> float:
    return float(np.percentile(seconds, q)) * 1000.0 if seconds else math.nan


def during_refit(sample: Sample, fits: list[tuple[float, float]]) -> bool:
    end = sample.started_at + sample.seconds
    return any(start <= end and sample.started_at <= finish for start, finish in fits)


async def drive(args: argparse.Namespace, port: int) -> list[Sample]:
    samples: list[Sample] = []
    started = time.perf_counter()
    stop = started + args.warmup + args.seconds
    await asyncio.gather(
        *(
            client_loop("127.0.0.1", port, seed, args.batch, started, args.warmup, stop, samples)
            for seed in range(args.clients)
        )
    )
    return samples


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clients", type=int, default=32, help="concurrent clients")
    parser.add_argument("--seconds", type=float, default=20.0, help="measured duration")
    parser.add_argument("--warmup", type=float, default=2.0, help="unmeasured lead-in")
    parser.add_argument("--fit-rate", type=int, default=500, help="ALP-GMM results between refits")
    parser.add_argument(
        "--batch",
        type=int,
        default=1,
        help="tasks drawn and results reported per request (1 = the issue's pattern; the TeacherClient prefetches 8)",
    )
    parser.add_argument(
        "--teacher",
        default="alp-gmm",
        choices=["alp-gmm", "random"],
        help="random isolates the service's own cost from the teacher's",
    )
    args = parser.parse_args()

    port = free_port()
    url = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory() as scratch:
        server = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "kuka_curriculum",
                "serve",
                "--port",
                str(port),
                "--db",
                str(Path(scratch) / "load.db"),
                "--log-level",
                "warning",
            ],
            cwd=Path(__file__).resolve().parents[1],
        )
        try:
            wait_healthy(url, server)
            space = [ParameterSpec.from_parameter(p).model_dump() for p in KUKA_TASK_SPACE.parameters]
            http_json(
                "PUT",
                f"{url}{API_PREFIX}/curricula/{CURRICULUM}",
                {
                    "teacher": args.teacher,
                    "space": space,
                    "seed": 0,
                    "params": {"fit_rate": args.fit_rate} if args.teacher == "alp-gmm" else {},
                },
            )
            service_cpu = cpu_seconds(server.pid)
            client_cpu = time.process_time()
            samples = asyncio.run(drive(args, port))
            service_cpu = cpu_seconds(server.pid) - service_cpu
            client_cpu = time.process_time() - client_cpu
            wait_for_fits(url)
            state = http_json("GET", f"{url}{API_PREFIX}/curricula/{CURRICULUM}/state?recent=0")
        finally:
            server.terminate()
            server.wait(timeout=30)

    run_start = min(s.started_at for s in samples)
    run_end = max(s.started_at + s.seconds for s in samples)
    fits = [
        (fit["started_at"], fit["finished_at"])
        for fit in state["fits"]  # type: ignore[index]
        if fit["started_at"] < run_end and fit["finished_at"] > run_start
    ]
    round_trips = sum(1 for sample in samples if sample.endpoint == "results")
    rate = round_trips / args.seconds
    episodes = round_trips * args.batch
    print(
        f"teacher service under load: {args.clients} clients, {args.seconds:.0f} s measured, "
        f"{args.teacher} over the KUKA space" + (f", fit_rate {args.fit_rate}" if args.teacher == "alp-gmm" else "")
    )
    print(
        f"round trips: {round_trips} ({rate:.0f}/s), {args.batch} episode(s) each: "
        f"{episodes / args.seconds:.0f} episodes/s"
    )
    measured = args.warmup + args.seconds
    print(
        f"CPU per round trip: service {service_cpu / measured / rate * 1e3:.2f} ms, "
        f"clients {client_cpu / measured / rate * 1e3:.2f} ms "
        f"(service busy {service_cpu / measured:.0%} of a core, clients {client_cpu / measured:.0%}; "
        f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f})"
    )
    print(f"{'endpoint':<10}{'p50 ms':>10}{'p99 ms':>10}")
    all_seconds = []
    for endpoint in ("tasks", "results"):
        seconds = [s.seconds for s in samples if s.endpoint == endpoint]
        all_seconds += seconds
        print(f"{endpoint:<10}{percentile_ms(seconds, 50):>10.2f}{percentile_ms(seconds, 99):>10.2f}")
    in_refit = [s.seconds for s in samples if during_refit(s, fits)]
    outside = [s.seconds for s in samples if not during_refit(s, fits)]
    durations = [finish - start for start, finish in fits]
    print(
        f"refits overlapping the run: {len(fits)} (mean {np.mean(durations) if durations else math.nan:.2f} s); "
        f"{len(in_refit) / max(len(samples), 1):.0%} of requests overlapped one"
    )
    p99_all, p99_in, p99_out = (percentile_ms(x, 99) for x in (all_seconds, in_refit, outside))
    ratio = p99_in / p99_out
    print(f"p99 during refits {p99_in:.2f} ms, outside refits {p99_out:.2f} ms (ratio {ratio:.2f})")
    checks = [
        (f"round trips/s >= {TARGET_ROUND_TRIPS:.0f}", rate >= TARGET_ROUND_TRIPS),
        (f"p99 < {TARGET_P99_S * 1000:.0f} ms", p99_all < TARGET_P99_S * 1000),
        (f"p99 during refits <= {TARGET_REFIT_RATIO:.0f} x outside", bool(fits) and ratio <= TARGET_REFIT_RATIO),
    ]
    for label, passed in checks:
        print(f"  {'PASS' if passed else 'FAIL'}  {label}")
    return 0 if all(passed for _, passed in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
