"""Restart time of the teacher service after a long history (issue 27): target under 5 s to the
first ``/healthz`` answer after 1,000,000 stored results, and the same next tasks as before the kill.

1. Builds a database (unless ``--db`` names one this script built before): one ALP-GMM curriculum
   over the KUKA space with the training run's parameters (reward range, a fifth of the tasks on
   the hardest task) but ``--fit-rate`` results between fits and at most ``--max-components``
   Gaussians, so the fits take minutes in all rather than hours. It drives the service's own
   ``CurriculumRegistry`` in-process: the same task and result writes, group commits, snapshots,
   fit process and background tree builds as a live service, ``--batch`` tasks drawn and
   reported per round by a scripted student whose reward rises on tasks it has practised.
2. Starts ``kuka-curriculum serve`` on it, draws and reports a few tasks (checked against the
   in-process teacher, which goes through the same steps), SIGKILLs it, starts it again, and
   prints the seconds from the start to the first ``/healthz`` answer, then whether the next tasks
   and the teacher's state equal those of the in-process teacher, which is what the killed
   service would have handed out.

    nice -n 10 .venv/bin/python bench/teacher_restart.py --db runs/restart-bench.db
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import sqlite3
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common.client.schemas import API_PREFIX, ParameterSpec, ResultItem  # noqa: E402
from common.kuka.task_space import KUKA_TASK_SPACE  # noqa: E402
from teacher_service.core.config import Settings  # noqa: E402
from teacher_service.curriculum_spec import AlpGmmCurriculum  # noqa: E402
from teacher_service.metrics import ServiceMetrics  # noqa: E402
from teacher_service.process import ServiceProcess  # noqa: E402
from teacher_service.registry import CurriculumRegistry  # noqa: E402
from teacher_service.store import Store  # noqa: E402
from teacher_service.teachers import EpisodeResult, Teacher  # noqa: E402
from teacher_service.teachers.alp_gmm import AlpGmmParams  # noqa: E402

NAME = "restart"
SEED = 3
TARGET_S = 5.0


def student_reward(task: dict[str, float], practice: float) -> float:
    """Higher on easy tasks and as practice grows, in the training run's reward range [-5, 10]."""
    difficulty = task["jp2"] + task["rnd_obj_x"] + task["rnd_obj_y"]
    return float(np.clip(10.0 / (1.0 + math.exp(3.0 * (difficulty - practice))) - 2.0, -5.0, 10.0))


async def generate(db: Path, spec: AlpGmmCurriculum, results: int, batch: int) -> Teacher:
    """Store ``results`` results through the service's own classes; returns the live teacher."""
    registry = CurriculumRegistry(Store(db, "NORMAL"), ServiceMetrics(), Settings(db=db))
    registry.restore()
    registry.start(asyncio.get_running_loop())
    curriculum, _ = await registry.create(NAME, spec)
    started = time.perf_counter()
    try:
        while curriculum.results_received < results:
            count = min(batch, results - curriculum.results_received)
            practice = 3.0 * curriculum.results_received / results
            tasks = await curriculum.issue(count)
            items = [ResultItem(task_id=t.task_id, reward=student_reward(t.params, practice)) for t in tasks]
            await curriculum.report(items)
            done = curriculum.results_received
            if done % (50 * batch) < batch:
                rate = done / (time.perf_counter() - started)
                print(f"\r  {done:,} results, {curriculum.fits_completed} fits, {rate:,.0f} results/s", end="")
        while curriculum.fits_pending:
            await asyncio.sleep(0.1)
        await asyncio.sleep(0.1)  # the last fit row and snapshot are written after the fit comes back
        print(
            f"\r  {curriculum.results_received:,} results, {curriculum.fits_completed} fits, "
            f"{time.perf_counter() - started:.0f} s"
        )
        return curriculum.teacher
    finally:
        registry.close()


def api(service: ServiceProcess) -> httpx.Client:
    return httpx.Client(base_url=f"{service.url}{API_PREFIX}/curricula/{NAME}", timeout=60.0)


def draw(client: httpx.Client, teacher: Teacher, count: int) -> tuple[list[dict[str, Any]], bool]:
    tasks: list[dict[str, Any]] = client.post("/tasks", json={"count": count}).json()["tasks"]
    expected = json.loads(json.dumps(teacher.sample(count)))
    return tasks, [t["params"] for t in tasks] == expected


def timed_start(service: ServiceProcess) -> float:
    started = time.monotonic()
    service.start(timeout=900)
    return time.monotonic() - started


def empty_start() -> float:
    """Seconds to the first /healthz on an empty database: imports and start-up, the floor under any restart."""
    with tempfile.TemporaryDirectory() as scratch:
        service = ServiceProcess(Path(scratch) / "empty.db")
        seconds = timed_start(service)
        service.kill()
    return seconds


def in_process_restore(db: Path) -> float:
    """Seconds the service's own restore takes on a copy of ``db``, without Python's start-up and imports."""
    with tempfile.TemporaryDirectory() as scratch:
        copy = Path(scratch) / "copy.db"
        with sqlite3.connect(db) as source, sqlite3.connect(copy) as target:
            source.backup(target)
        started = time.perf_counter()
        registry = CurriculumRegistry(Store(copy), ServiceMetrics(), Settings(db=copy))
        registry.restore()
        seconds = time.perf_counter() - started
        registry.close()
    return seconds


def database_figures(db: Path) -> str:
    with sqlite3.connect(db) as connection:
        results = connection.execute("SELECT count(*) FROM results").fetchone()[0]
        fits = connection.execute("SELECT count(*) FROM fits").fetchone()[0]
        last_seq, covered = connection.execute("SELECT last_seq, results_seen FROM snapshots").fetchone()
        tail = connection.execute("SELECT count(*) FROM results WHERE seq > ?", (last_seq,)).fetchone()[0]
    size = sum(path.stat().st_size for path in (db, Path(f"{db}-wal")) if path.exists())
    return (
        f"{results:,} results, {fits} fits, snapshot after {covered:,} results, {tail} results after it; "
        f"{size / 2**20:,.0f} MiB"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--db", type=Path, default=Path("runs/restart-bench.db"))
    parser.add_argument("--results", type=int, default=1_000_000)
    parser.add_argument("--fit-rate", type=int, default=2_000, help="at most 2,000 where the params are bounded")
    parser.add_argument("--max-components", type=int, default=4)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument(
        "--tail",
        type=int,
        default=960,
        help="results reported to the service before the kill (below 1,000: no new snapshot)",
    )
    args = parser.parse_args()

    params = {
        "reward_range": [-5.0, 10.0],
        "target_task_ratio": 0.2,
        "fit_rate": args.fit_rate,
        "max_components": args.max_components,
    }
    space = [ParameterSpec.from_parameter(p) for p in KUKA_TASK_SPACE.parameters]
    spec = AlpGmmCurriculum(teacher="alp-gmm", space=space, params=AlpGmmParams(**params), seed=SEED)
    if args.db.exists():
        sys.exit(f"{args.db} exists: the next tasks are checked against the teacher that built it; remove it first")
    print(f"building {args.db}: alp-gmm {params}, {args.results:,} results")
    teacher = asyncio.run(generate(args.db, spec, args.results, args.batch))
    print(f"  {database_figures(args.db)}")

    service = ServiceProcess(args.db, env={"KC_SNAPSHOT_EVERY": "1000"})
    print(f"first start on it: /healthz after {timed_start(service):.2f} s")
    same_before = True
    with api(service) as client:
        for _ in range(args.tail // args.batch):
            tasks, same = draw(client, teacher, args.batch)
            results = [{"task_id": t["task_id"], "reward": student_reward(t["params"], 3.0)} for t in tasks]
            client.post("/results", json={"results": results}).raise_for_status()
            for task, result in zip(tasks, results, strict=True):
                assert teacher.learn(EpisodeResult(task["params"], result["reward"])) is None, "keep fits out"
            same_before &= same
    service.kill()
    print(
        f"SIGKILLed after {args.tail // args.batch * args.batch} more results, each batch of tasks "
        f"{'the same as' if same_before else 'DIFFERENT from'} the in-process teacher's"
    )
    print(f"  {database_figures(args.db)}")

    print(f"  the service's restore alone, in-process on a copy: {in_process_restore(args.db):.2f} s")
    restart_s = timed_start(service)
    baseline_s = empty_start()
    with api(service) as client:
        _, same_after = draw(client, teacher, 16)
        same_state = client.get("/state").json()["teacher"] == json.loads(json.dumps(teacher.state()))
    service.stop()
    verdict = "met" if restart_s < TARGET_S else "NOT met"
    print(f"restart: /healthz after {restart_s:.2f} s (target < {TARGET_S:.0f} s: {verdict})")
    print(f"  an empty database, just after: /healthz after {baseline_s:.2f} s")
    print(f"next 16 tasks equal those of the killed service's teacher: {same_after}; teacher state equal: {same_state}")
    return 0 if same_before and same_after and same_state and restart_s < TARGET_S else 1


if __name__ == "__main__":
    raise SystemExit(main())
