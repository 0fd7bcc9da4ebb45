"""How much of the machine's raw simulation speed ``kuka-curriculum train`` turns into training.

In one run: the raw ceiling (W environment processes at once, random actions, resets and scripted
grasps included) and ``kuka-curriculum train`` as a person runs it (its own local Ray and teacher
service, ALP-GMM, evaluations on as by default) over a fixed budget, once per training loop asked
for. For each run it prints the steps per second over the whole command (start-up included) and
over the training loop, their ratios to the ceiling, and where the learner's wall time went:
waiting for batches, updating, waiting for evaluations, and the rest (logging, checkpoints, the
progress display).

Two ceilings, because the environment's cost per step depends on the task: an episode ends with a
scripted grasp of ~80 ms, and a curriculum's easier tasks start the arm lower, so its episodes are
shorter and grasp more often per step than the hardest task's. The *hardest-task* ceiling (measured
before and after the runs) is the machine's best case; the *same-tasks* ceiling replays, in W raw
processes, the tasks the training run itself played (read from its teacher's database, shuffled),
so the raw loop does the same work per step as training did. The pipeline's own efficiency is the
ratio to the second.

    .venv/bin/python bench/train_speed.py --workers 2 --total-steps 300000 --loops async sync

With ``--baseline COMMIT`` it answers another question: how much faster the working tree trains than that
commit. It exports the commit's whole tree (``git archive``) and runs its ``train``, then the working tree's,
on the same family, teacher, budget and seed, and prints both rates and their ratio (no ceilings):

    .venv/bin/python bench/train_speed.py --baseline e0bfb64 --env KukaGraspHard-v1 --teacher fixed --loops async
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# A sibling script (bench/ is the script's path, not a package).
from episode_equivalence import export_commit

from common.client.task_space import Task
from common.kuka import ENV_IDS
from common.kuka.env import KukaGraspEnv
from common.kuka.task_space import KUKA_TASK_SPACE
from learner.core.config import LOOPS, TrainConfig
from learner.job.teacher_process import DATABASE_FILE
from teacher_service.store import Store

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class RawRate:
    steps_per_second: float
    mean_episode_length: float


def raw_env_rate(seconds: float, seed: int, tasks: list[Task]) -> RawRate:
    """Random-action steps per second of one environment in this process, resets and grasps included;
    each episode plays the next of ``tasks``, in turn."""
    env = KukaGraspEnv(max_steps=TrainConfig.max_episode_steps)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed, options={"task": tasks[0]})
    steps, episodes = 0, 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        _, _, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, size=3).astype(np.float32))
        steps += 1
        if terminated or truncated:
            episodes += 1
            env.reset(options={"task": tasks[episodes % len(tasks)]})
    elapsed = time.perf_counter() - start
    env.close()
    return RawRate(steps / elapsed, steps / max(episodes, 1))


def raw_ceiling(processes: int, seconds: float, first_seed: int, tasks: list[Task]) -> RawRate:
    """``processes`` raw environments running at once, each taking every ``processes``-th task."""
    shares = [(seconds, first_seed + index, tasks[index::processes] or tasks) for index in range(processes)]
    with multiprocessing.get_context("spawn").Pool(processes) as pool:
        rates = pool.starmap(raw_env_rate, shares)
    return RawRate(
        float(sum(rate.steps_per_second for rate in rates)),
        float(np.mean([rate.mean_episode_length for rate in rates])),
    )


def played_tasks(run_dir: Path, seed: int) -> list[Task]:
    """The task of every episode the run reported to its teacher, shuffled: a short replay sees the whole mix."""
    store = Store(run_dir / DATABASE_FILE)
    try:
        [curriculum] = store.curricula()
        tasks = [result.task for result in store.results(curriculum.id)]
    finally:
        store.close()
    order = np.random.default_rng(seed).permutation(len(tasks))
    return [tasks[index] for index in order]


@dataclass(frozen=True)
class TrainRun:
    loop: str
    steps: int
    command_seconds: float
    loop_seconds: float
    waiting: float
    updating: float
    evaluating: float
    mean_episode_length: float
    same_tasks_ceiling: RawRate | None

    @property
    def other(self) -> float:
        return self.loop_seconds - self.waiting - self.updating - self.evaluating


def timed_train(
    loop: str,
    workers: int,
    total_steps: int,
    seed: int,
    run_dir: Path,
    raw_seconds: float | None,
    family: list[str],
    root: Path = ROOT,
) -> TrainRun:
    """``train`` of the code under ``root`` (its packages first on the path), timed; with ``raw_seconds``, also
    the ceiling of the tasks it played. ``family`` holds the ``--env`` and ``--teacher`` flags."""
    command = [sys.executable, "-m", "kuka_curriculum", "train", "--loop", loop, "--workers", str(workers),
               "--total-steps", str(total_steps), "--seed", str(seed), "--run-dir", str(run_dir), *family]  # fmt: skip
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")]))}
    # Both sides' local Ray clusters alike, whichever default each commit's train leaves to Ray: Ray 2.5x turns
    # token authentication on when this is unset, and a stray token file then fails the cluster's start.
    environment.setdefault("RAY_AUTH_MODE", "disabled")
    started = time.perf_counter()
    done = subprocess.run(command, cwd=root, env=environment, capture_output=True, text=True, check=False)
    command_seconds = time.perf_counter() - started
    if done.returncode != 0:
        raise SystemExit(f"train --loop {loop} failed:\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    records = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    first_iteration = records[0]["step"] / records[0]["perf/steps_per_second"]
    episodes = sum(r["train/episodes"] for r in records)
    return TrainRun(
        loop=loop,
        steps=int(records[-1]["step"]),
        command_seconds=command_seconds,
        loop_seconds=records[-1]["time"] - records[0]["time"] + first_iteration,
        waiting=sum(r["perf/wait_seconds"] for r in records),
        updating=sum(r["perf/update_seconds"] for r in records),
        evaluating=sum(r.get("perf/eval_wait_seconds") or 0.0 for r in records),
        mean_episode_length=sum(r["train/episode_length"] * r["train/episodes"] for r in records if r["train/episodes"])
        / episodes,
        same_tasks_ceiling=None
        if raw_seconds is None
        else raw_ceiling(workers, raw_seconds, seed, played_tasks(run_dir, seed)),
    )


def compare_with_baseline(args: argparse.Namespace, family: list[str], scratch: Path) -> None:
    """``train`` of the baseline commit, then of the working tree, per loop; both rates and their ratio."""
    baseline = export_commit(args.baseline, scratch / "baseline")
    print(f"train {' '.join(family)} --workers {args.workers} --total-steps {args.total_steps:_} --seed {args.seed}")
    for loop in args.loops:
        load = os.getloadavg()[0]
        runs: dict[str, list[TrainRun]] = {args.baseline: [], "working tree": []}
        for repeat in range(args.repeats):  # the sides take turns, so a load that drifts slows both alike
            for name, root in ((args.baseline, baseline), ("working tree", ROOT)):
                run_dir = scratch / f"{name}-{loop}-{repeat}"
                runs[name].append(
                    timed_train(loop, args.workers, args.total_steps, args.seed, run_dir, None, family, root)
                )
        print(f"--loop {loop} (load average {load:.2f} before the runs, {os.getloadavg()[0]:.2f} after)")
        rates = {}
        for name, timed in runs.items():
            steps = sum(run.steps for run in timed)
            rates[name] = (
                steps / sum(run.command_seconds for run in timed),
                steps / sum(run.loop_seconds for run in timed),
            )
            whole, loop_rate = rates[name]
            each = ", ".join(f"{run.steps / run.command_seconds:,.0f}" for run in timed)
            print(
                f"  {name:14} whole command {whole:7,.0f} steps/s (each run: {each}), "
                f"training loop {loop_rate:7,.0f} steps/s; episodes of {timed[0].mean_episode_length:.0f} steps"
            )
        before, after = rates.values()
        print(f"  ratio          whole command {after[0] / before[0]:.2f}, training loop {after[1] / before[1]:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=TrainConfig.workers, help="rollout actors and raw processes, W")
    parser.add_argument("--total-steps", type=int, default=300_000, help="train's budget (default 300,000)")
    parser.add_argument("--loops", nargs="+", choices=LOOPS, default=list(LOOPS), help="training loops to time")
    parser.add_argument(
        "--raw-seconds",
        type=float,
        default=30.0,
        help="each raw measurement (the hardest-task one split before and after)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--env", choices=ENV_IDS, default=ENV_IDS[0], help="train's task family")
    parser.add_argument("--teacher", default="alp-gmm", help="train's teacher (fixed: the family's hardest task)")
    parser.add_argument("--baseline", metavar="COMMIT", help="time this commit's train against the working tree's")
    parser.add_argument("--repeats", type=int, default=1, help="with --baseline: runs of each side, in turns")
    args = parser.parse_args()
    family = ["--env", args.env, "--teacher", args.teacher]
    if args.baseline is not None:
        with tempfile.TemporaryDirectory() as scratch:
            compare_with_baseline(args, family, Path(scratch))
        return

    hardest = [KUKA_TASK_SPACE.hardest()]
    with tempfile.TemporaryDirectory() as scratch:
        before = raw_ceiling(args.workers, args.raw_seconds / 2, 0, hardest)
        runs = [
            timed_train(
                loop,
                args.workers,
                args.total_steps,
                args.seed,
                Path(scratch) / f"train-{loop}",
                args.raw_seconds,
                family,
            )
            for loop in args.loops
        ]
        after = raw_ceiling(args.workers, args.raw_seconds / 2, args.workers, hardest)
    ceiling = (before.steps_per_second + after.steps_per_second) / 2

    print(f"hardest-task ceiling, {args.workers} raw environment processes at once: {ceiling:,.0f} steps/s "
          f"(before {before.steps_per_second:,.0f}, after {after.steps_per_second:,.0f}; "
          f"episodes of {before.mean_episode_length:.0f} steps)")  # fmt: skip
    for run in runs:
        assert run.same_tasks_ceiling is not None
        same = run.same_tasks_ceiling.steps_per_second
        print(f"\ntrain --loop {run.loop}: {run.steps:,} steps, episodes of {run.mean_episode_length:.0f} steps")
        print(f"  same-tasks ceiling {same:7,.0f} steps/s (its tasks replayed with random actions: "
              f"episodes of {run.same_tasks_ceiling.mean_episode_length:.0f} steps)")  # fmt: skip
        for label, seconds in (("whole command", run.command_seconds), ("training loop", run.loop_seconds)):
            rate = run.steps / seconds
            print(f"  {label:18} {rate:7,.0f} steps/s  ratio {rate / ceiling:.2f} to the hardest-task ceiling, "
                  f"{rate / same:.2f} to the same-tasks one  ({seconds:.1f} s)")  # fmt: skip
        print(f"  start-up and shut-down: {run.command_seconds - run.loop_seconds:.1f} s")
        shares = {"waiting for batches": run.waiting, "updating": run.updating,
                  "waiting for evaluations": run.evaluating, "other": run.other}  # fmt: skip
        print("  learner's loop time: " + ", ".join(f"{name} {s / run.loop_seconds:.0%}" for name, s in shares.items()))


if __name__ == "__main__":
    main()
