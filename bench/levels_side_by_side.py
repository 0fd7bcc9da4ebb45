"""The service's level kinds beside Syllabus 0.7's on a MiniGrid level family, with the same student.

Every run is ``kuka-curriculum train``'s learner and workers (``learner.core.trainer.Trainer``) on the
same levels, budget and PPO settings; only where each episode's level comes from changes:

- ours, through a ``serve`` this script starts: ``plr``, robust PLR (``plr`` with ``robust: true``),
  ``learning-progress``, ``learnability``, and ``random`` (uniform over the training levels);
- Syllabus's PLR and learning progress, in a Ray actor the workers draw from
  (``bench.level_sources``);
- ``no-curriculum``: uniform levels drawn inside each worker, no service at all, the throughput baseline.

After training, each final policy plays ``--test-levels`` held-out levels (seeds from 1,000,000, outside
every training set) ``--test-repeats`` times each, sampling its actions. Per run: held-out success and
return, and the CVaR of success at 10% (the mean success of the worst tenth of held-out levels, as SFL
reports); per kind, means with 95% Student-t intervals over seeds, and the median training steps/s.

Resumable: a finished run (its ``result.json``) is skipped, an unfinished one resumes from its latest
checkpoint. Runs go seed by seed (every kind on seed 0, then on seed 1, ...), so a partial table compares
kinds on the same seeds. Raw files (databases, logs, raw metrics) are git-ignored; ``--summarise`` rewrites
``results.json`` and ``results.md`` from the runs on disk.

    .venv/bin/python bench/levels_side_by_side.py --out benchmarks/levels-minigrid/doorkey-8x8 \\
        --env MiniGrid-DoorKey-8x8-v0 --levels 500 --steps 1000000 --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
import uuid
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common.families.base import HELD_OUT_FIRST_SEED  # noqa: E402
from common.levels import LEVEL_ENV_IDS  # noqa: E402
from learner.core.config import TrainConfig  # noqa: E402

OURS = {
    "random": ("random", {}),
    "plr": ("plr", {}),
    "robust-plr": ("plr", {"robust": True}),
    "learning-progress": ("learning-progress", {}),
    "learnability": ("learnability", {}),
}
"""Our kinds by their row name: the service's teacher kind and its parameters (defaults otherwise)."""
SYLLABUS = ("syllabus-plr", "syllabus-learning-progress")
BASELINE = "no-curriculum"
KINDS = (
    "random", "plr", "syllabus-plr", "robust-plr", "learning-progress", "syllabus-learning-progress", "learnability",
    BASELINE,
)  # fmt: skip
"""Each seed's runs in this order, so a partial table holds the main comparisons first."""
PPO_SETTINGS = {
    "rollout_length": 128,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "entropy_coef": 0.01,
    "minibatch_size": 512,
    "update_epochs": 4,
    "learning_rate": 0.0005,
}
"""The MiniGrid settings of the docs' example (``docs/commands.md``)."""
CVAR_SHARE = 0.1
CURVE_TARGET = 0.8
"""In-run held-out success whose first crossing is a run's steps to master the family."""
WARM_UP_ITERATIONS = 5
"""Iterations at a run's start left out of its steps/s: Ray and the workers are still starting."""
DEFAULTS = TrainConfig()


def run_config(args: argparse.Namespace, kind: str, seed: int) -> TrainConfig:
    teacher, params = OURS.get(kind, ("random", {}))
    return replace(
        DEFAULTS,
        teacher=teacher,
        teacher_overrides=params,
        env=args.env,
        levels=args.levels,
        total_steps=args.steps,
        seed=seed,
        workers=2,
        envs_per_worker=8,
        eval_every=args.eval_every,
        eval_episodes=args.eval_episodes,
        checkpoint_every=25,
        ppo=DEFAULTS.ppo.with_overrides(PPO_SETTINGS),
    )


CURRICULUM_NAME_FILE = "curriculum.txt"


def curriculum_name(run_dir: Path, base: str, resuming: bool) -> str:
    """The run's curriculum name on the shared service: a fresh run gets ``base`` and a new suffix, kept
    in the run directory for its resumes, so a run made again (its directory deleted) never picks up
    the curriculum, and the results, of the run it replaces. A resumed run from before the suffix keeps
    ``base``."""
    kept = run_dir / CURRICULUM_NAME_FILE
    if kept.exists():
        return kept.read_text().strip()
    if resuming:
        return base[:64]
    name = f"{base[:55]}-{uuid.uuid4().hex[:8]}"
    kept.write_text(name + "\n")
    return name


def train_one(args: argparse.Namespace, kind: str, seed: int, run_dir: Path, teacher_url: str) -> Path:
    """Train (or resume) one run; returns its final checkpoint."""
    import ray

    from bench.level_sources import SyllabusCurriculum, SyllabusLevels, UniformLevels
    from learner.core.checkpoint import latest_checkpoint, load_checkpoint
    from learner.core.trainer import Trainer
    from learner.job.session import register_curriculum

    config = run_config(args, kind, seed)
    previous = latest_checkpoint(run_dir)
    checkpoint = load_checkpoint(previous) if previous is not None else None
    name = curriculum_name(run_dir, f"{run_dir.parent.parent.name}-{kind}-seed{seed}", previous is not None)
    task_source: Any = None
    syllabus_actor = None
    if kind in OURS:
        register_curriculum(teacher_url, name, config, None)
    elif kind == BASELINE:
        task_source = UniformLevels(args.levels)
    else:
        # A resumed Syllabus run starts its curriculum afresh: Syllabus has no saved state to restore.
        syllabus_actor = SyllabusCurriculum.options(name=name).remote(kind, args.levels, seed, config.batch_size)  # type: ignore[attr-defined]
        task_source = SyllabusLevels(name)
    trainer = Trainer(config, run_dir, teacher_url, name, resume_from=checkpoint, task_source=task_source)
    started = time.monotonic()
    final = trainer.run(
        lambda report: print(
            f"\r{kind} seed {seed}: {report.counters.steps:_} steps, recent success {report.recent_success_rate:.0%}",
            end="",
            flush=True,
        )
    )
    print(f"  ({time.monotonic() - started:.0f} s)")
    if syllabus_actor is not None:
        ray.kill(syllabus_actor)
    return final


def test_one(args: argparse.Namespace, final: Path) -> dict[str, Any]:
    """The final policy on held-out levels, each played ``test_repeats`` times."""
    from bench.level_sources import UniformLevels
    from learner.core.checkpoint import load_checkpoint
    from learner.core.policy import policy_snapshot
    from rollout_worker.actor import WorkerSettings
    from rollout_worker.pool import WorkerPool

    checkpoint = load_checkpoint(final)
    settings = WorkerSettings(
        teacher_url="",
        curriculum="",
        num_envs=1,
        rollout_length=1,
        max_episode_steps=checkpoint.config.max_episode_steps,
        env_id=checkpoint.config.env,
        task_source=UniformLevels(args.levels),
    )
    levels = [HELD_OUT_FIRST_SEED + index for index in range(args.test_levels)]
    seeds = [level for level in levels for _ in range(args.test_repeats)]
    pool = WorkerPool(settings, 2, seed=checkpoint.config.seed)
    try:
        shares = pool.start_evaluation(policy_snapshot(checkpoint), {}, seeds).result()
    finally:
        pool.close()
    by_level: dict[int, list[bool]] = {}
    returns = []
    for slot, share in enumerate(shares):  # slot k played seeds[k::pool size], in order
        for level, episode in zip(seeds[slot :: len(shares)], share, strict=True):
            by_level.setdefault(level, []).append(episode.success)
            returns.append(episode.reward)
    per_level = np.array([np.mean(by_level[level]) for level in levels])
    worst = np.sort(per_level)[: max(1, int(round(CVAR_SHARE * len(per_level))))]
    return {
        "success": float(per_level.mean()),
        "return": float(np.mean(returns)),
        "cvar10_success": float(worst.mean()),
        "per_level_success": [round(float(value), 4) for value in per_level],
        "episodes": len(returns),
    }


def measure_throughput(args: argparse.Namespace) -> None:
    """Each kind's training steps/s on short runs with no evaluation, kinds interleaved over ``--rounds``
    rounds so drift on the machine spreads over all of them; the median over a run's iterations after its
    first ``WARM_UP_ITERATIONS``. Run on a quiet machine."""
    import shutil

    from learner.experiments.run_archive import metrics_records
    from learner.job.session import connect_ray
    from learner.job.teacher_process import launch_local_teacher_service

    out = Path(args.out) / "throughput"
    shutil.rmtree(out, ignore_errors=True)
    measured: dict[str, list[float]] = {}
    timed = argparse.Namespace(**{**vars(args), "steps": args.throughput_steps, "eval_every": 0})
    with contextlib.ExitStack() as stack:
        teacher_url = launch_local_teacher_service(out / "service", stack)()
        connect_ray(None, 2, stack)
        for round_ in range(args.rounds):
            for kind in args.kinds:
                run_dir = out / "runs" / f"{kind}-round{round_}"
                run_dir.mkdir(parents=True)
                train_one(timed, kind, 0, run_dir, teacher_url)
                speeds = [r["perf/steps_per_second"] for r in metrics_records(run_dir) if "perf/steps_per_second" in r]
                measured.setdefault(kind, []).append(float(np.median(speeds[WARM_UP_ITERATIONS:])))
                print(f"{kind} round {round_}: {measured[kind][-1]:,.0f} steps/s")
    baseline = float(np.median(measured[BASELINE])) if BASELINE in measured else None
    throughput = {
        "steps_per_run": args.throughput_steps,
        "rounds": args.rounds,
        "kinds": {
            kind: {
                "steps_per_second": values,
                "median": float(np.median(values)),
                "vs_no_curriculum": float(np.median(values)) / baseline if baseline else None,
            }
            for kind, values in measured.items()
        },
    }
    (Path(args.out) / "throughput.json").write_text(json.dumps(throughput, indent=1) + "\n")
    shutil.rmtree(out / "runs")


def run_all(args: argparse.Namespace) -> None:
    from learner.experiments.run_archive import archive_run
    from learner.job.session import connect_ray
    from learner.job.teacher_process import launch_local_teacher_service

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as stack:
        teacher_url = launch_local_teacher_service(out / "service", stack)()
        connect_ray(None, 2, stack)
        for seed in args.seeds:
            for kind in args.kinds:
                run_dir = out / "runs" / f"{kind}-seed{seed}"
                result_path = run_dir / "result.json"
                if result_path.exists():
                    continue
                run_dir.mkdir(parents=True, exist_ok=True)
                final = train_one(args, kind, seed, run_dir, teacher_url)
                tested = test_one(args, final)
                print(f"{kind} seed {seed}: held-out {tested['success']:.1%}, CVaR10 {tested['cvar10_success']:.1%}")
                result = {
                    "kind": kind,
                    "seed": seed,
                    "final_checkpoint": final.name,
                    "test_levels": args.test_levels,
                    "test_repeats": args.test_repeats,
                    **tested,
                }
                result_path.write_text(json.dumps(result, indent=1) + "\n")
                archive_run(run_dir)
                summarise(args)


def summarise(args: argparse.Namespace) -> None:
    from learner.evaluation.stats import mean_interval
    from learner.experiments.run_archive import metrics_records

    out = Path(args.out)
    rows: dict[str, Any] = {}
    curves: dict[str, list[dict[str, Any]]] = {}
    for kind in KINDS:
        runs = []
        for result_path in sorted((out / "runs").glob(f"{kind}-seed*/result.json")):
            result = json.loads(result_path.read_text())
            records = metrics_records(result_path.parent)
            speeds = [r["perf/steps_per_second"] for r in records if "perf/steps_per_second" in r]
            result["steps_per_second"] = float(np.median(speeds)) if speeds else None
            evaluations = [(r["step"], r["eval/success_rate"]) for r in records if "eval/success_rate" in r]
            result["steps_to_80"] = next((step for step, success in evaluations if success >= CURVE_TARGET), None)
            result["midway_success"] = next(
                (success for step, success in reversed(evaluations) if step <= args.steps // 2), 0.0
            )
            runs.append(result)
            curves.setdefault(kind, []).append(
                {
                    "seed": result["seed"],
                    "steps": [r["step"] for r in records if "eval/success_rate" in r],
                    "success": [r["eval/success_rate"] for r in records if "eval/success_rate" in r],
                }
            )
        if not runs:
            continue
        rows[kind] = {
            "seeds": [run["seed"] for run in runs],
            **{
                measure: mean_interval([run[measure] for run in runs]).to_dict()
                for measure in ("success", "return", "cvar10_success", "midway_success")
            },
            "steps_per_second_median": float(np.median([run["steps_per_second"] or np.nan for run in runs])),
            "median_steps_to_80": _median_or_none([run["steps_to_80"] for run in runs]),
            "runs": [{key: value for key, value in run.items() if key != "per_level_success"} for run in runs],
        }
    results = {
        "env": args.env,
        "levels": args.levels,
        "steps": args.steps,
        "test_levels": args.test_levels,
        "test_repeats": args.test_repeats,
        "ppo": PPO_SETTINGS,
        "kinds": rows,
        "curves": curves,
    }
    throughput_path = out / "throughput.json"
    if throughput_path.exists():
        results["throughput"] = json.loads(throughput_path.read_text())
    (out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / "results.md").write_text(results_table(results))
    plot_curves(results, out / "learning_curves.png")


def plot_curves(results: dict[str, Any], path: Path) -> None:
    """Held-out success during training, each kind's mean over its seeds (on the steps all of them reached)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(8, 4.5))
    for kind, runs in results["curves"].items():
        length = min(len(run["steps"]) for run in runs)
        if length == 0:
            continue
        steps = np.array(runs[0]["steps"][:length])
        success = np.mean([run["success"][:length] for run in runs], axis=0)
        style = "--" if kind.startswith("syllabus") else ":" if kind == BASELINE else "-"
        axes.plot(steps, 100 * success, style, label=f"{kind} ({len(runs)} seeds)")
    axes.set_xlabel("training steps")
    axes.set_ylabel("held-out success % (in-run evaluations)")
    axes.set_title(f"{results['env']}, {results['levels']} training levels")
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)


def _median_or_none(steps: list[int | None]) -> float | None:
    """The median, counting a run that never got there as later than every one that did (None: over half never did)."""
    ordered = sorted(steps, key=lambda value: (value is None, value or 0))
    middle = ordered[(len(ordered) - 1) // 2 : len(ordered) // 2 + 1]
    return None if None in middle else float(np.mean([value for value in middle if value is not None]))


def _interval(cell: dict[str, Any], scale: float = 100.0) -> str:
    estimate = cell["estimate"] * scale
    if cell["low"] is None:
        return f"{estimate:.1f}"
    return f"{estimate:.1f} [{cell['low'] * scale:.1f}, {cell['high'] * scale:.1f}]"


def markdown_table(headers: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    return lines + ["| " + " | ".join(row) + " |" for row in rows]


def results_table(results: dict[str, Any]) -> str:
    baseline = results["kinds"].get(BASELINE, {}).get("steps_per_second_median")
    rows = [
        [
            kind,
            str(len(row["seeds"])),
            _interval(row["success"]),
            _interval(row["return"], 1.0),
            _interval(row["cvar10_success"]),
            _interval(row["midway_success"]),
            f"{row['steps_per_second_median']:,.0f}",
            f"{row['steps_per_second_median'] / baseline:.2f}" if baseline else "-",
            f"{row['median_steps_to_80']:,.0f}" if row["median_steps_to_80"] is not None else "not reached",
        ]
        for kind, row in results["kinds"].items()
    ]
    lines = [
        f"# {results['env']}, {results['levels']} training levels, {results['steps']:,} steps",
        "",
        f"Held-out: {results['test_levels']} levels x {results['test_repeats']} episodes; 95% intervals over seeds; "
        "steps/s is the median of the runs' median training steps/s; steps to 80% is the median over seeds of the "
        "first in-run evaluation at 80% held-out success or more; halfway is the in-run held-out success at half the "
        "budget.",
        "",
        *markdown_table(
            ["kind", "seeds", "held-out %", "return", "CVaR10 %", "halfway %", "steps/s", "vs none", "steps to 80%"],
            rows,
        ),
    ]
    throughput = results.get("throughput")
    if throughput:
        speeds = [
            [kind, f"{row['median']:,.0f}", f"{row['vs_no_curriculum']:.2f}" if row["vs_no_curriculum"] else "-"]
            for kind, row in throughput["kinds"].items()
        ]
        lines += [
            "",
            f"Throughput: {throughput['steps_per_run']:,}-step runs, no evaluation, kinds interleaved over "
            f"{throughput['rounds']} rounds; median training steps/s.",
            "",
            *markdown_table(["kind", "steps/s", "vs no curriculum"], speeds),
        ]
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="where the runs and results go")
    parser.add_argument("--env", default="MiniGrid-DoorKey-8x8-v0", choices=LEVEL_ENV_IDS)
    parser.add_argument("--levels", type=int, default=500, help="training levels (reset seeds 0 to N-1)")
    parser.add_argument("--steps", type=int, default=1_000_000, help="training steps per run")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    parser.add_argument("--eval-every", type=int, default=25, help="iterations between in-run held-out evaluations")
    parser.add_argument("--eval-episodes", type=int, default=50, help="held-out levels per in-run evaluation")
    parser.add_argument("--test-levels", type=int, default=100, help="held-out levels of the final test")
    parser.add_argument("--test-repeats", type=int, default=5, help="episodes per held-out level in the final test")
    parser.add_argument("--summarise", action="store_true", help="only rewrite results.json and results.md")
    parser.add_argument(
        "--throughput", action="store_true", help="measure each kind's steps/s on short runs instead (a quiet machine)"
    )
    parser.add_argument("--throughput-steps", type=int, default=150_000, help="steps per throughput run")
    parser.add_argument("--rounds", type=int, default=2, help="throughput rounds over every kind")
    args = parser.parse_args()
    if args.throughput:
        measure_throughput(args)
        summarise(args)
    elif args.summarise:
        summarise(args)
    else:
        run_all(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
