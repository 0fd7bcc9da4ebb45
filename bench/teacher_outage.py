"""A teacher away for minutes while the learner trains: what the workers do, hold and deliver.

Starts a ``serve``, then ``kuka-curriculum train`` on a MiniGrid level family against it (fast steps,
so the figures are about the outage, not the simulator). After ``--before`` seconds the service is
killed (SIGKILL, as a crash); ``--outage`` seconds later it starts again on the same database and
port; ``--after`` seconds later training is stopped with Ctrl-C, which delivers what the workers
hold. Prints, per phase, training steps/s (the learner's ``perf/steps_per_second``), offline episodes
and the results waiting in the workers' clients (``teacher/results_waiting``); the workers' memory
(RSS of the Ray rollout actors) over the run; and results the service holds at the end against the
episodes the workers played on tasks it issued.

    .venv/bin/python bench/teacher_outage.py --before 120 --outage 600 --after 120
"""

from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.teacher_fleet import family_rss_mb  # noqa: E402
from bench.teacher_load import free_port, http_json, wait_healthy  # noqa: E402
from common.client.schemas import API_PREFIX  # noqa: E402

CURRICULUM = "run"
"""train names its curriculum after its run directory."""
TRAIN = [
    "--env", "MiniGrid-DoorKey-5x5-v0", "--teacher", "random", "--levels", "1000", "--total-steps", "100000000",
    "--workers", "2", "--envs-per-worker", "8", "--rollout-length", "128", "--eval-every", "1000000",
    "--ppo", "gamma=0.99", "--ppo", "entropy_coef=0.01", "--ppo", "minibatch_size=512", "--ppo", "update_epochs=4",
]  # fmt: skip


def start_service(port: int, db: Path) -> subprocess.Popen[bytes]:
    command = [sys.executable, "-m", "kuka_curriculum", "serve", "--port", str(port), "--db", str(db)]
    server = subprocess.Popen([*command, "--log-level", "warning"], cwd=Path(__file__).resolve().parents[1])
    wait_healthy(f"http://127.0.0.1:{port}", server)
    return server


def worker_rss_mb() -> float:
    """The summed RSS of the Ray rollout actors (their processes are titled ``ray::RolloutWorker``)."""
    total = 0.0
    for status in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            if status.read_bytes().startswith(b"ray::RolloutWorker"):
                total += family_rss_mb(int(status.parent.name))
        except OSError:
            continue
    return total


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=float, default=120.0)
    parser.add_argument("--outage", type=float, default=600.0)
    parser.add_argument("--after", type=float, default=120.0)
    parser.add_argument("--out", type=Path, help="also write the figures here as JSON")
    args = parser.parse_args()

    port = free_port()
    url = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory() as scratch:
        db, run_dir = Path(scratch) / "teacher.db", Path(scratch) / "run"
        server = start_service(port, db)
        command = [sys.executable, "-m", "kuka_curriculum", "train", *TRAIN, "--teacher-url", url]
        trainer = subprocess.Popen(
            [*command, "--run-dir", str(run_dir)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        marks: dict[str, float] = {}
        memory: list[tuple[float, float]] = []

        def watch(seconds: float) -> None:
            deadline = time.time() + seconds
            while time.time() < deadline:
                memory.append((time.time(), worker_rss_mb()))
                time.sleep(min(10.0, max(deadline - time.time(), 0.0)))

        try:
            watch(args.before)
            marks["outage_start"] = time.time()
            server.kill()
            server.wait()
            watch(args.outage)
            marks["outage_end"] = time.time()
            server = start_service(port, db)
            watch(args.after)
            marks["stop"] = time.time()
            trainer.send_signal(signal.SIGINT)
            trainer.wait(timeout=300)
            info = http_json("GET", f"{url}{API_PREFIX}/curricula/{CURRICULUM}")
        finally:
            if trainer.poll() is None:
                trainer.kill()
            server.terminate()
            server.wait(timeout=60)
        records = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]

    def phase(start: float, end: float) -> dict[str, float]:
        inside = [r for r in records if start <= r["time"] < end and "perf/steps_per_second" in r]
        return {
            "iterations": len(inside),
            "steps_per_s": round(float(np.median([r["perf/steps_per_second"] for r in inside])), 0) if inside else 0,
            "offline_episodes": sum(r.get("train/offline_episodes", 0) for r in inside),
            "episodes": sum(r.get("train/episodes", 0) for r in inside),
            "results_waiting_max": max((r.get("teacher/results_waiting", 0) for r in inside), default=0),
        }

    started = records[0]["time"] if records else 0.0
    online = sum(r.get("train/episodes", 0) - r.get("train/offline_episodes", 0) for r in records)
    figures = {
        "before": phase(started, marks["outage_start"]),
        "outage": phase(marks["outage_start"], marks["outage_end"]),
        "after": phase(marks["outage_end"], marks["stop"] + 60),
        "worker_rss_mb": {
            "before": round(max((m for t, m in memory if t < marks["outage_start"]), default=0.0), 0),
            "outage_max": round(
                max((m for t, m in memory if marks["outage_start"] <= t < marks["outage_end"]), default=0.0), 0
            ),
            "end": round(memory[-1][1], 0) if memory else 0.0,
        },
        "episodes_on_issued_tasks": online,
        "results_stored": info["counters"]["results_received"],  # type: ignore[index]
        "results_dropped": max((r.get("teacher/results_dropped", 0) for r in records), default=0),
    }
    print(json.dumps(figures, indent=1))
    if args.out:
        args.out.write_text(json.dumps(figures, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
