"""The service's level kinds beside Syllabus 0.7's on a MiniGrid level family, each peer as its authors ship
it, with one student for all (issue 79).

Every run is ``kuka-curriculum train``'s learner and workers (``learner.core.trainer.Trainer``) on the same
levels, budget and PPO settings; only where each episode's level comes from changes, and the score the
workers send with each episode (``--ppo level_score``: each PLR its authors' score). The arms (``ARMS``, each
row's setup in its ``setup``):

- ours, through a ``serve`` this script starts: ``random`` (uniform levels), ``plr`` (the PLR paper's: a sweep,
  then every draw a replay), ``plr-hybrid`` (our variant, half the draws uniform after the sweep),
  ``robust-plr`` (DCD's MiniGrid settings, charged only for the steps it trains on), ``learning-progress`` and
  ``learnability``;
- Syllabus's PLR, online learning progress and Learnability top-10 with its procgen example's settings, in a
  Ray actor the workers draw from (``bench.level_sources``), Learnability's evaluation episodes charged;
- ``no-curriculum``: uniform levels drawn inside each worker, no service at all: the throughput baseline
  (``--throughput``), not in the learning runs by default (it draws what ``random`` draws).

Each run trains ``--steps`` steps of its budget (every step played, or for robust PLR the steps trained on),
evaluates on ``--eval-episodes`` held-out levels every ``--eval-every`` iterations (the take-off curve), and
its final policy then plays ``--test-levels`` held-out levels ``--test-repeats`` times each, sampling its
actions. Held-out levels are the seeds from 1,000,000, outside every training set; on ``MiniGrid-Gamut-v0``
none of their layouts occurs among the training levels, which ``results.json`` counts
(``bench.level_layouts``).

Per run (``runs/<arm>-seed<seed>/result.json``): held-out success (by tier on the gamut), return, CVaR10, the
in-run curve, the budget step of take-off (the first in-run evaluation at ``--take-off`` held-out success or
more), the steps played, trained and charged, the PLR sweep's end, the Syllabus actor's state, steps/s, the
commit and the UTC times. ``--summarise`` (also run after each seed) writes ``results.json`` with every run, the
command, machine and dates, the rliable figures of ``learner.experiments.run_statistics`` (IQM and mean with
stratified bootstrap intervals, the share of runs that take off, P(improvement) of every arm over uniform
and of each of ours over its Syllabus counterpart, the performance profile), steps-to-take-off as
Kaplan-Meier survival curves (runs that never take off censored at the budget), and ``results.md``.

Resumable: a finished run (its ``result.json``) is skipped; an unfinished run of ours resumes from its
latest checkpoint (the service keeps its curriculum), an unfinished Syllabus run starts again from nothing
(its curricula have no saved state). Runs go seed by seed, every arm on seed 0 first, so a partial table
compares arms on the same seeds. ``benchmarks/levels-minigrid/gamut-200/run.sh`` runs the whole plan
unattended.

    .venv/bin/python bench/levels_side_by_side.py --out benchmarks/levels-minigrid/gamut-200 --seeds 0 1
    .venv/bin/python bench/levels_side_by_side.py --out benchmarks/levels-minigrid/gamut-200 --throughput
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import json
import math
import shlex
import shutil
import sys
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.provenance import commit, machine  # noqa: E402
from common.families.base import HELD_OUT_FIRST_SEED  # noqa: E402
from common.levels import GAMUT_ENV_ID, LEVEL_ENV_IDS  # noqa: E402
from learner.core.config import TrainConfig  # noqa: E402
from learner.core.figure_file import save_png  # noqa: E402


@dataclass(frozen=True)
class Arm:
    """One row: where its levels come from, the score its episodes carry, what its budget counts, and its setup."""

    source: str
    """``service`` (ours, through the teacher service), ``syllabus`` (``bench.level_sources``) or ``worker``
    (uniform levels drawn in the worker)."""
    setup: str
    teacher: str = "random"
    params: Mapping[str, Any] = field(default_factory=dict)
    level_score: str = "positive_value_loss"
    budget_steps: str = "played"
    sweeps: bool = False
    """A PLR that plays every level once before it replays: the step its sweep ends is recorded."""


DCD_ROBUST_PLR = {
    "robust": True,
    "replay_prob": 0.5,
    "min_seen_share": 0.5,
    "replay_schedule": "proportionate",
    "temperature": 0.3,
    "staleness_coef": 0.3,
}
"""Robust PLR (PLR⊥) on MiniGrid in DCD (facebookresearch/dcd), train_scripts/grid_configs/minigrid/
60_blocks_uniform/mg_60b_uni_robust_plr.json (ACCEL's): level_replay_prob 0.5, level_replay_rho 0.5, the
proportionate schedule (arguments.py's default), rank transform at temperature 0.3, staleness_coef 0.3
(arguments.py's default), positive_value_loss, no_exploratory_grad_updates. (The 25-block config of the robust
PLR paper takes temperature 0.1 and grounded_signed_value_loss.)"""

ARMS: dict[str, Arm] = {
    "random": Arm("service", "ours: `random`, uniform over the training levels", teacher="random"),
    "plr": Arm(
        "service",
        "ours: `plr` at its defaults, the PLR paper's: rank, temperature 0.1, staleness 0.1, the proportionate "
        "schedule from a sweep of every level, then every draw a replay; value_l1",
        teacher="plr",
        level_score="value_l1",
        sweeps=True,
    ),
    "syllabus-plr": Arm(
        "syllabus",
        "Syllabus: its procgen example's PLR, TaskSampler(strategy value_l1, replay_schedule fixed), drawn by its "
        "own TaskSampler.sample(); scores from our workers over whole episodes",
        level_score="value_l1",
        sweeps=True,
    ),
    "learning-progress": Arm("service", "ours: `learning-progress` at its defaults", teacher="learning-progress"),
    "syllabus-learning-progress": Arm(
        "syllabus",
        "Syllabus: its example's online learning progress (update every 25 batches, ema 0.1, p_theta 0.1, "
        "normalize_success False); uniform draws until its first update, where Syllabus's wrappers ask it "
        "at each environment's first reset",
    ),
    "learnability": Arm("service", "ours: `learnability` at its defaults", teacher="learnability"),
    "syllabus-learnability": Arm(
        "syllabus",
        "Syllabus: its example's Learnability top-10 (learnable_prob 0.5; 20 evaluation episodes per level "
        "every 25 batches, played score-only on the training workers while training waits); its evaluation "
        "steps count in its budget, where the example counts only training steps",
    ),
    "robust-plr": Arm(
        "service",
        "ours: `plr` robust with DCD's MiniGrid settings (replay 0.5 from half the levels scored, "
        "proportionate, rank, temperature 0.3, staleness 0.3, positive value loss, no gradient on explored "
        "levels); charged only for the steps it trains on; once every level is scored it always replays "
        "(DCD's generator never runs out of new levels)",
        teacher="plr",
        params=DCD_ROBUST_PLR,
        budget_steps="trained",
        sweeps=True,
    ),
    "plr-hybrid": Arm(
        "service",
        "ours, a named variant: `plr` with replay_prob 0.5, after the sweep half the draws uniform (neither "
        "paper's); value_l1",
        teacher="plr",
        params={"replay_prob": 0.5},
        level_score="value_l1",
        sweeps=True,
    ),
    "no-curriculum": Arm("worker", "no curriculum: uniform levels drawn in each worker, no service"),
}
"""Every row, in the order each seed's runs go (the main comparisons first)."""
UNIFORM = "random"
BASELINE = "no-curriculum"
PLAN_ARMS = tuple(arm for arm in ARMS if arm != BASELINE)
"""The arms of the learning runs by default; ``no-curriculum`` times the service's cost (``--throughput``)."""
COUNTERPARTS = {
    "plr": "syllabus-plr",
    "plr-hybrid": "syllabus-plr",
    "robust-plr": "syllabus-plr",
    "learning-progress": "syllabus-learning-progress",
    "learnability": "syllabus-learnability",
}
"""Each of ours and the Syllabus arm it is compared with (Syllabus's robust PLR needs an evaluator of its own:
ours is compared with its PLR)."""
OURS = tuple(arm for arm, spec in ARMS.items() if spec.source == "service" and arm != UNIFORM)
SYLLABUS = tuple(arm for arm, spec in ARMS.items() if spec.source == "syllabus")

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
STEPS = 500_000
"""Steps of budget per run, for a run of a few minutes on 2 cores (the plan in docs/results/levels.md)."""
TAKE_OFF = 0.5
"""Held-out success at which a run has taken off: on the gamut, above the 3/8 the three tiers without a key
can give, so a run there solves locked-door rooms."""
CVAR_SHARE = 0.1
WARM_UP_ITERATIONS = 5
"""Iterations at a run's start left out of its steps/s: Ray and the workers are still starting."""
PROGRESS_REPS = 1000
"""Bootstrap resamples of the summaries written between seeds (results.json records how many it used)."""
NOTES_FILE = "notes.json"
RESULT_FILE = "result.json"
DEFAULTS = TrainConfig()


def run_config(args: argparse.Namespace, kind: str, seed: int) -> TrainConfig:
    arm = ARMS[kind]
    return replace(
        DEFAULTS,
        teacher=arm.teacher,  # type: ignore[arg-type]
        teacher_overrides=dict(arm.params),
        env=args.env,
        levels=args.levels,
        total_steps=args.steps,
        budget_steps=arm.budget_steps,  # type: ignore[arg-type]
        seed=seed,
        workers=2,
        envs_per_worker=8,
        eval_every=args.eval_every,
        eval_episodes=args.eval_episodes,
        checkpoint_every=25,
        ppo=DEFAULTS.ppo.with_overrides({**PPO_SETTINGS, "level_score": arm.level_score}),
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


def _utc_now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


INVOCATIONS_FILE = "invocations.json"


def record_invocation(out: Path, mode: str) -> None:
    """Add this command, its machine and its start to the list the results carry (``--summarise`` adds none)."""
    path = out / INVOCATIONS_FILE
    kept = json.loads(path.read_text()) if path.exists() else []
    command = shlex.join([sys.executable, *sys.argv])
    kept.append({"mode": mode, "command": command, "started": _utc_now(), "commit": commit(), "machine": machine()})
    path.write_text(json.dumps(kept, indent=1) + "\n")


def _sweep_probe(kind: str, name: str, teacher_url: str, levels: int, actor: Any) -> Callable[[], bool] | None:
    """A check that every level has been played once (a PLR's sweep is over), or None for an arm without one."""
    if not ARMS[kind].sweeps:
        return None
    if actor is not None:
        import ray

        return lambda: ray.get(actor.status.remote())["seen_share"] >= 1.0
    from common.client.teacher_client import TeacherClient

    def swept() -> bool:
        with TeacherClient(teacher_url, name) as client:
            return int(client.state(recent=0).teacher["scored_levels"]) >= levels

    return swept


def train_one(args: argparse.Namespace, kind: str, seed: int, run_dir: Path, teacher_url: str) -> tuple[Path, dict]:
    """Train (or resume) one run; returns its final checkpoint and its notes (the sweep's end, Syllabus's state)."""
    import ray

    from bench.level_sources import SyllabusCurriculum, SyllabusLevels, UniformLevels
    from learner.core.checkpoint import latest_checkpoint, load_checkpoint
    from learner.core.trainer import Trainer
    from learner.job.session import register_curriculum

    arm = ARMS[kind]
    config = run_config(args, kind, seed)
    previous = latest_checkpoint(run_dir)
    if previous is not None and arm.source == "syllabus":
        print(f"{kind} seed {seed}: Syllabus's curricula keep no state to resume from; starting the run again")
        shutil.rmtree(run_dir)
        run_dir.mkdir(parents=True)
        previous = None
    checkpoint = load_checkpoint(previous) if previous is not None else None
    notes_path = run_dir / NOTES_FILE
    notes: dict[str, Any] = json.loads(notes_path.read_text()) if previous is not None and notes_path.exists() else {}
    notes.setdefault("started", _utc_now())
    name = curriculum_name(run_dir, f"{run_dir.parent.parent.name}-{kind}-seed{seed}", previous is not None)
    task_source: Any = None
    actor = None
    if arm.source == "service":
        register_curriculum(teacher_url, name, config, None)
    elif arm.source == "worker":
        task_source = UniformLevels(args.levels)
    else:
        actor = SyllabusCurriculum.options(name=name).remote(kind, args.levels, seed, config.batch_size)  # type: ignore[attr-defined]
        task_source = SyllabusLevels(name)
    probe = _sweep_probe(kind, name, teacher_url, args.levels, actor)
    trainer = Trainer(config, run_dir, teacher_url, name, resume_from=checkpoint, task_source=task_source)

    def on_iteration(report: Any) -> None:
        if probe is not None and "sweep_end_step" not in notes and probe():
            notes["sweep_end_step"] = report.counters.steps
            notes["sweep_end_budget_step"] = report.counters.budget_spent(config.budget_steps)
        if args.progress:
            print(
                f"\r{kind} seed {seed}: {report.counters.steps:_} steps, "
                f"recent success {report.recent_success_rate:.0%}",
                end="",
                flush=True,
            )

    started = time.monotonic()
    try:
        final = trainer.run(on_iteration)
    finally:
        notes_path.write_text(json.dumps(notes, indent=1) + "\n")
    notes["wall_seconds"] = notes.get("wall_seconds", 0.0) + (time.monotonic() - started)
    notes["finished"] = _utc_now()
    if actor is not None:
        notes["syllabus"] = ray.get(actor.status.remote())
        ray.kill(actor)
    notes_path.write_text(json.dumps(notes, indent=1) + "\n")
    print(f"  ({notes['wall_seconds']:.0f} s)" if args.progress else f"{kind} seed {seed}: trained")
    return final, notes


def test_one(args: argparse.Namespace, final: Path) -> dict[str, Any]:
    """The final policy on held-out levels, each played ``test_repeats`` times, sampling its actions."""
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
    tested: dict[str, Any] = {
        "success": float(per_level.mean()),
        "return": float(np.mean(returns)),
        "cvar10_success": float(worst.mean()),
        "per_level_success": [round(float(value), 4) for value in per_level],
        "episodes": len(returns),
    }
    if checkpoint.config.env == GAMUT_ENV_ID:
        from common.levels.gamut import TIERS

        tiers = np.array(levels) % len(TIERS)
        tested["success_by_tier"] = [round(float(per_level[tiers == tier].mean()), 4) for tier in range(len(TIERS))]
    return tested


def in_run_curve(run_dir: Path, budget_steps: str) -> dict[str, list[float]]:
    """The in-run held-out evaluations against the steps of the budget spent by then (played steps, or for a
    budget of trained steps, played less score-only), and the training steps/s after the warm-up."""
    from learner.experiments.run_archive import metrics_records

    steps, success, speeds = [], [], []
    score_only = 0.0
    for index, record in enumerate(metrics_records(run_dir)):
        score_only += record.get("train/score_only_steps", 0.0)
        if "eval/success_rate" in record:
            steps.append(record["step"] - (score_only if budget_steps == "trained" else 0.0))
            success.append(record["eval/success_rate"])
        if "perf/steps_per_second" in record and index >= WARM_UP_ITERATIONS:
            speeds.append(record["perf/steps_per_second"])
    return {"steps": steps, "success": success, "steps_per_second": speeds}


def take_off_step(curve: Mapping[str, Sequence[float]], threshold: float) -> float | None:
    """The budget step of the first in-run evaluation at ``threshold`` held-out success or more (None: none)."""
    return next(
        (step for step, value in zip(curve["steps"], curve["success"], strict=True) if value >= threshold), None
    )


def run_all(args: argparse.Namespace) -> None:
    from learner.core.checkpoint import load_checkpoint
    from learner.experiments.run_archive import archive_run
    from learner.job.session import connect_ray
    from learner.job.teacher_process import launch_local_teacher_service

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    record_invocation(out, "runs")
    with contextlib.ExitStack() as stack:
        teacher_url = launch_local_teacher_service(out / "service", stack)()
        connect_ray(args.ray_address, 2, stack)
        for seed in args.seeds:
            for kind in args.kinds:
                run_dir = out / "runs" / f"{kind}-seed{seed}"
                result_path = run_dir / RESULT_FILE
                if result_path.exists():
                    continue
                run_dir.mkdir(parents=True, exist_ok=True)
                final, notes = train_one(args, kind, seed, run_dir, teacher_url)
                tested = test_one(args, final)
                counters = load_checkpoint(final).counters
                arm = ARMS[kind]
                curve = in_run_curve(run_dir, arm.budget_steps)
                result = {
                    "kind": kind,
                    "seed": seed,
                    "final_checkpoint": final.name,
                    "test_levels": args.test_levels,
                    "test_repeats": args.test_repeats,
                    **tested,
                    "steps_played": counters.steps,
                    "steps_score_only": counters.score_only_steps,
                    "steps_trained": counters.steps - counters.score_only_steps,
                    "budget_steps": arm.budget_steps,
                    "budget_spent": counters.budget_spent(arm.budget_steps),
                    "take_off_step": take_off_step(curve, args.take_off),
                    "curve": {"steps": curve["steps"], "success": curve["success"]},
                    "steps_per_second": float(np.median(curve["steps_per_second"]))
                    if curve["steps_per_second"]
                    else None,
                    "commit": commit(),
                    **notes,
                }
                result_path.write_text(json.dumps(result, indent=1) + "\n")
                print(
                    f"{kind} seed {seed}: held-out {tested['success']:.1%}, take-off "
                    f"{result['take_off_step'] or 'none'}, {counters.steps:_} steps played"
                )
                archive_run(run_dir)
            # Once a seed, a progress summary on fewer resamples (each bootstraps every figure afresh, minutes at
            # 10,000); the plan's last command, --summarise, writes the figures with --reps.
            summarise(argparse.Namespace(**{**vars(args), "reps": min(args.reps, PROGRESS_REPS)}))


def kaplan_meier(times: Sequence[float | None], censored_at: float, confidence: float = 0.95) -> dict[str, Any]:
    """The Kaplan-Meier estimate of the share of runs not yet taken off, over the budget: ``times`` are the
    runs' take-off steps, None for a run that never took off (censored at ``censored_at``, the budget, after
    every take-off). With Greenwood's variance, a log(-log) band; and the median, the first step where the
    estimate reaches 0.5 (None: it does not within the budget)."""
    from statistics import NormalDist

    z = NormalDist().inv_cdf(0.5 + confidence / 2)
    at_risk = len(times)
    events = sorted(float(t) for t in times if t is not None)
    survival, greenwood = 1.0, 0.0
    curve = {"steps": [0.0], "survival": [1.0], "low": [1.0], "high": [1.0]}
    for step in sorted(set(events)):
        taken_off = events.count(step)
        survival *= 1.0 - taken_off / at_risk
        greenwood += taken_off / (at_risk * (at_risk - taken_off)) if at_risk > taken_off else math.inf
        at_risk -= taken_off
        if 0.0 < survival < 1.0 and math.isfinite(greenwood):
            spread = z * math.sqrt(greenwood) / abs(math.log(survival))
            low, high = survival ** math.exp(spread), survival ** math.exp(-spread)
        else:
            low, high = survival, survival
        for key, value in zip(("steps", "survival", "low", "high"), (step, survival, low, high), strict=True):
            curve[key].append(value)
    median = next((step for step, value in zip(curve["steps"], curve["survival"], strict=True) if value <= 0.5), None)
    return {
        **curve,
        "runs": len(times),
        "taken_off": len(events),
        "censored_at": censored_at,
        "median_take_off_step": median,
    }


def load_runs(out: Path) -> dict[str, list[dict[str, Any]]]:
    """Every finished run on disk, by arm, in seed order (runs of the first side-by-side's driver, which
    recorded no budget, are not read: ``benchmarks/levels-minigrid/doorkey-8x8`` keeps its own summary)."""
    runs: dict[str, list[dict[str, Any]]] = {}
    for kind in ARMS:
        found = [json.loads(path.read_text()) for path in (out / "runs").glob(f"{kind}-seed*/{RESULT_FILE}")]
        found = [run for run in found if run["kind"] == kind and "budget_spent" in run]
        if found:
            runs[kind] = sorted(found, key=lambda run: run["seed"])
    return runs


def layout_counts(args: argparse.Namespace) -> dict[str, Any]:
    """How many distinct layouts the training and held-out levels hold, and how many held-out ones are training
    layouts (``bench.level_layouts``), kept beside the results once counted."""
    from bench.level_layouts import count_layouts

    path = Path(args.out) / "layouts.json"
    wanted = {"env": args.env, "training_levels": args.levels, "held_out_levels": args.test_levels}
    if path.exists():
        kept = json.loads(path.read_text())
        if all(kept.get(key) == value for key, value in wanted.items()):
            return dict(kept)
    counts = count_layouts(args.env, args.levels, args.test_levels)
    path.write_text(json.dumps(counts, indent=1) + "\n")
    return counts


def summarise(args: argparse.Namespace) -> None:
    from learner.experiments.run_statistics import plot_performance_profile, run_statistics

    out = Path(args.out)
    runs = load_runs(out)
    if not runs:
        return
    invocations = out / INVOCATIONS_FILE
    scores = {kind: [run["success"] for run in found] for kind, found in runs.items()}
    baseline = UNIFORM if UNIFORM in scores else None
    statistics = run_statistics(scores, baseline=baseline, threshold=args.take_off, reps=args.reps)
    counterparts = {}
    for ours, theirs in COUNTERPARTS.items():
        if ours in scores and theirs in scores:
            pair = run_statistics({ours: scores[ours], theirs: scores[theirs]}, baseline=theirs, reps=args.reps)
            improvement = pair.arms[ours].improvement
            assert improvement is not None
            counterparts[ours] = {"against": theirs, "improvement": improvement.to_dict()}
    best = best_against_best(statistics, scores, args.reps)
    survival = {
        kind: kaplan_meier([run["take_off_step"] for run in found], float(args.steps)) for kind, found in runs.items()
    }
    results: dict[str, Any] = {
        "issue": 79,
        "invocations": json.loads(invocations.read_text()) if invocations.exists() else [],
        "first_run_started": min(run.get("started", "") for found in runs.values() for run in found) or None,
        "last_run_finished": max(run.get("finished", "") for found in runs.values() for run in found) or None,
        "env": args.env,
        "levels": args.levels,
        "steps": args.steps,
        "eval_every": args.eval_every,
        "eval_episodes": args.eval_episodes,
        "test_levels": args.test_levels,
        "test_repeats": args.test_repeats,
        "take_off": args.take_off,
        "ppo": PPO_SETTINGS,
        "layouts": layout_counts(args),
        "arms": {
            kind: {
                "setup": ARMS[kind].setup,
                "teacher": ARMS[kind].teacher if ARMS[kind].source == "service" else None,
                "params": dict(ARMS[kind].params),
                "level_score": ARMS[kind].level_score,
                "budget_steps": ARMS[kind].budget_steps,
            }
            for kind in runs
        },
        "statistics": statistics.to_dict(),
        "against_counterpart": counterparts,
        "best_against_best": best,
        "survival": survival,
        "runs": {kind: [_without_per_level(run) for run in found] for kind, found in runs.items()},
    }
    throughput_path = out / "throughput.json"
    if throughput_path.exists():
        results["throughput"] = json.loads(throughput_path.read_text())
    (out / "results.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / "results.md").write_text(results_table(results))
    plot_performance_profile(
        out / "performance_profile.png",
        scores,
        title=f"{args.env}, {args.levels} levels: final held-out success (95% bootstrap bands over runs)",
        reps=args.reps,
    )
    plot_survival(survival, out / "take_off_survival.png", f"{args.env}, {args.levels} levels", args.take_off)
    plot_curves(runs, out / "learning_curves.png", f"{args.env}, {args.levels} training levels")


def best_against_best(statistics: Any, scores: Mapping[str, Sequence[float]], reps: int) -> dict[str, Any] | None:
    """Our arm with the highest IQM against Syllabus's with the highest: P(improvement) with its interval (the
    two picked after the runs, so the figure flatters the better of each side)."""
    from learner.experiments.run_statistics import run_statistics

    ours = [kind for kind in OURS if kind in scores]
    theirs = [kind for kind in SYLLABUS if kind in scores]
    if not ours or not theirs:
        return None
    best_ours = max(ours, key=lambda kind: statistics.arms[kind].iqm.estimate)
    best_theirs = max(theirs, key=lambda kind: statistics.arms[kind].iqm.estimate)
    pair = run_statistics({best_ours: scores[best_ours], best_theirs: scores[best_theirs]}, best_theirs, reps=reps)
    improvement = pair.arms[best_ours].improvement
    assert improvement is not None
    return {"ours": best_ours, "syllabus": best_theirs, "improvement": improvement.to_dict()}


def _without_per_level(run: Mapping[str, Any]) -> dict[str, Any]:
    return {key: value for key, value in run.items() if key != "per_level_success"}


def _style(kind: str) -> str:
    return "--" if kind.startswith("syllabus") else ":" if kind in (UNIFORM, BASELINE) else "-"


def plot_survival(survival: Mapping[str, Mapping[str, Any]], path: Path, title: str, threshold: float) -> None:
    """Each arm's Kaplan-Meier curve of runs not yet taken off, with its band."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(10.0, 5.0), layout="constrained")
    axes = figure.add_subplot()
    for kind, curve in survival.items():
        steps = [*curve["steps"], curve["censored_at"]]
        line = axes.step(steps, [*curve["survival"], curve["survival"][-1]], _style(kind), where="post")[0]
        line.set_label(f"{kind} ({curve['taken_off']} of {curve['runs']})")
        axes.fill_between(
            steps, [*curve["low"], curve["low"][-1]], [*curve["high"], curve["high"][-1]], step="post",
            color=line.get_color(), alpha=0.1,
        )  # fmt: skip
    axes.set_xlabel("steps of the budget")
    axes.set_ylabel(f"share of runs not yet at {threshold:.0%} held-out")
    axes.set_ylim(-0.02, 1.02)
    axes.set_title(
        f"{title}: steps to take off\n(Kaplan-Meier, 95% log-log bands; runs that never take off censored at the "
        "budget)",
        fontsize="medium",
    )
    axes.grid(alpha=0.3)
    axes.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize="small")
    save_png(figure, path, dpi=100)


def plot_curves(runs: Mapping[str, Sequence[Mapping[str, Any]]], path: Path, title: str) -> None:
    """In-run held-out success, each arm's mean over its runs (on the evaluations all of them reached)."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(10.0, 5.0), layout="constrained")
    axes = figure.add_subplot()
    for kind, found in runs.items():
        length = min(len(run["curve"]["steps"]) for run in found)
        if length == 0:
            continue
        steps = np.mean([run["curve"]["steps"][:length] for run in found], axis=0)
        success = np.mean([run["curve"]["success"][:length] for run in found], axis=0)
        axes.plot(steps, 100 * success, _style(kind), label=f"{kind} ({len(found)} runs)")
    axes.set_xlabel("steps of the budget")
    axes.set_ylabel("held-out success % (in-run evaluations)")
    axes.set_title(title)
    axes.grid(alpha=0.3)
    axes.legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize="small")
    save_png(figure, path, dpi=100)


def _interval(cell: Mapping[str, Any] | None, percent: bool = True) -> str:
    if cell is None:
        return "—"
    scale, digits = (100.0, 1) if percent else (1.0, 2)
    estimate = f"{cell['estimate'] * scale:.{digits}f}"
    if cell["low"] is None:
        return f"{estimate} [n/a]"
    return f"{estimate} [{cell['low'] * scale:.{digits}f}, {cell['high'] * scale:.{digits}f}]"


def markdown_table(headers: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    return lines + ["| " + " | ".join(row) + " |" for row in rows]


def results_table(results: Mapping[str, Any]) -> str:
    statistics = results["statistics"]["arms"]
    rows = []
    for kind, found in results["runs"].items():
        figures = statistics[kind]
        counterpart = results["against_counterpart"].get(kind)
        median = results["survival"][kind]["median_take_off_step"]
        speeds = [run["steps_per_second"] for run in found if run.get("steps_per_second")]
        rows.append(
            [
                kind,
                str(len(found)),
                _interval(figures["iqm"]),
                _interval(figures["mean"]),
                _interval(figures["share_at_or_above_threshold"]),
                _interval(figures["improvement_over_baseline"], percent=False),
                f"{_interval(counterpart['improvement'], percent=False)} vs {counterpart['against']}"
                if counterpart
                else "—",
                f"{median:,.0f}" if median is not None else "not reached",
                f"{np.mean([run['steps_trained'] / run['steps_played'] for run in found]):.2f}",
                f"{np.median(speeds):,.0f}" if speeds else "—",
            ]
        )
    best = results.get("best_against_best")
    lines = [
        f"# {results['env']}, {results['levels']} training levels, {results['steps']:,} steps of budget",
        "",
        f"Held-out: {results['test_levels']} levels x {results['test_repeats']} episodes, sampling actions; "
        f"layouts: {results['layouts']['held_out_layouts_in_training']} of {results['layouts']['held_out_levels']} "
        "held-out layouts occur among the training levels. IQM, mean and P(improvement) by rliable with stratified "
        f"bootstrap 95% intervals; take-off is held-out success of {results['take_off']:.0%} or more (its share "
        "with a Wilson interval; the median step from the Kaplan-Meier curve, runs that never take off censored at "
        "the budget). steps/s: the median of the runs' medians, on whatever else the machine was running.",
        "",
        *markdown_table(
            [
                "arm",
                "runs",
                "IQM %",
                "mean %",
                "take off %",
                "P(> uniform)",
                "P(> Syllabus counterpart)",
                "median take-off step",
                "trained / played",
                "steps/s",
            ],
            rows,
        ),
    ]
    lines += tier_table(results["runs"])
    if best:
        lines += [
            "",
            f"Best against best (highest IQM, picked after the runs): {best['ours']} over {best['syllabus']}, "
            f"P(improvement) {_interval(best['improvement'], percent=False)}.",
        ]
    throughput = results.get("throughput")
    if throughput:
        speeds = [
            [
                kind,
                ", ".join(f"{value:,.0f}" for value in row["steps_per_second"]),
                f"{row['median']:,.0f}",
                "—" if row.get("ratio_median") is None else
                f"{row['ratio_median']:.2f} [{row['ratio_min']:.2f}, {row['ratio_max']:.2f}]",
            ]
            for kind, row in throughput["kinds"].items()
        ]  # fmt: skip
        lines += [
            "",
            f"Throughput: {throughput['steps_per_run']:,}-step runs with no evaluation, kinds interleaved over "
            f"{throughput['rounds']} rounds; training steps/s, the median over the iterations from step "
            f"{throughput['window_start']:,} (PLR's replay phase: its sweeps ended by step "
            f"{throughput['latest_sweep_end'] or 0:,}); against no curriculum in the same round, the median and "
            f"range over rounds. Identical no-curriculum runs spread by {throughput['baseline_spread']:.0%} "
            "(max over min, less 1).",
            "",
            *markdown_table(["kind", "steps/s per round", "median", "vs no curriculum [min, max]"], speeds),
        ]
    return "\n".join(lines) + "\n"


def tier_table(runs: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[str]:
    """Each arm's held-out success by gamut tier, the mean over its runs: a score over all levels does not say
    which rooms a teacher's choice of levels helped with. Empty off the gamut."""
    from common.levels.gamut import TIERS

    by_tier = {
        kind: [run["success_by_tier"] for run in found if run.get("success_by_tier")] for kind, found in runs.items()
    }
    rows = [
        [kind, *(f"{100.0 * value:.1f}" for value in np.mean(tiers, axis=0))]
        for kind, tiers in by_tier.items()
        if tiers
    ]
    if not rows:
        return []
    headers = ["arm", *(f"{tier.size}x{tier.size} {tier.barrier}" for tier in TIERS)]
    return [
        "",
        "Held-out success by tier (room side and barrier), % over the arm's runs:",
        "",
        *markdown_table(headers, rows),
    ]


def measure_throughput(args: argparse.Namespace) -> None:
    """Each kind's training steps/s on runs with no evaluation, long enough for a PLR's replay phase: the median
    over a run's iterations from ``--throughput-window`` of its steps on (a PLR's sweep is over by then: each
    run's sweep end is recorded, and the window's start is checked against it), kinds interleaved over
    ``--rounds`` rounds, their order turned by one each round so none always runs first. Every round runs
    the same seed, so a kind's rounds are identical runs and their spread is the machine's noise. Run on a
    quiet machine."""
    from learner.experiments.run_archive import metrics_records
    from learner.job.session import connect_ray
    from learner.job.teacher_process import launch_local_teacher_service

    record_invocation(Path(args.out), "throughput")
    out = Path(args.out) / "throughput"
    shutil.rmtree(out, ignore_errors=True)
    window_start = int(args.throughput_window * args.throughput_steps)
    measured: dict[str, list[float]] = {}
    sweeps: dict[str, list[int | None]] = {}
    timed = argparse.Namespace(**{**vars(args), "steps": args.throughput_steps, "eval_every": 0})
    kinds = list(args.kinds)
    with contextlib.ExitStack() as stack:
        teacher_url = launch_local_teacher_service(out / "service", stack)()
        connect_ray(args.ray_address, 2, stack)
        for round_ in range(args.rounds):
            order = kinds[round_ % len(kinds) :] + kinds[: round_ % len(kinds)]
            for kind in order:
                run_dir = out / "runs" / f"{kind}-round{round_}"
                run_dir.mkdir(parents=True)
                _, notes = train_one(timed, kind, 0, run_dir, teacher_url)
                speeds = [
                    r["perf/steps_per_second"]
                    for index, r in enumerate(metrics_records(run_dir))
                    if "perf/steps_per_second" in r and index >= WARM_UP_ITERATIONS and r["step"] >= window_start
                ]
                measured.setdefault(kind, []).append(float(np.median(speeds)))
                if ARMS[kind].sweeps:
                    sweeps.setdefault(kind, []).append(notes.get("sweep_end_step"))
                print(f"{kind} round {round_}: {measured[kind][-1]:,.0f} steps/s")
    sweep_ends = [end for ends in sweeps.values() for end in ends]
    unfinished = [kind for kind, ends in sweeps.items() if any(end is None or end > window_start for end in ends)]
    baseline = measured.get(BASELINE)
    kinds_out: dict[str, Any] = {}
    for kind, values in measured.items():
        row: dict[str, Any] = {"steps_per_second": values, "median": float(np.median(values))}
        if baseline is not None:
            ratios = [value / base for value, base in zip(values, baseline, strict=True)]
            row.update(
                ratios=ratios,
                ratio_median=float(np.median(ratios)),
                ratio_min=min(ratios),
                ratio_max=max(ratios),
            )
        if kind in sweeps:
            row["sweep_end_steps"] = sweeps[kind]
        kinds_out[kind] = row
    throughput = {
        "steps_per_run": args.throughput_steps,
        "rounds": args.rounds,
        "window_start": window_start,
        "latest_sweep_end": max((end for end in sweep_ends if end is not None), default=None),
        "sweeps_unfinished_at_window_start": unfinished,
        "baseline_spread": (max(baseline) / min(baseline) - 1.0) if baseline else None,
        "machine": machine(),
        "measured": _utc_now(),
        "command": shlex.join([sys.executable, *sys.argv]),
        "kinds": kinds_out,
    }
    if unfinished:
        print(f"warning: the sweep of {', '.join(unfinished)} was not over at step {window_start:,} in every round")
    (Path(args.out) / "throughput.json").write_text(json.dumps(throughput, indent=1) + "\n")
    shutil.rmtree(out / "runs")


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    from learner.experiments.run_statistics import REPS, REPS_HELP, bootstrap_reps

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="where the runs and results go")
    parser.add_argument("--env", default=GAMUT_ENV_ID, choices=LEVEL_ENV_IDS)
    parser.add_argument("--levels", type=int, default=200, help="training levels (reset seeds 0 to N-1)")
    parser.add_argument("--steps", type=int, default=STEPS, help="steps of budget per run")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(20)))
    parser.add_argument("--kinds", nargs="+", default=None, choices=list(ARMS), help="arms (default: all but none)")
    parser.add_argument("--eval-every", type=int, default=25, help="iterations between in-run held-out evaluations")
    parser.add_argument("--eval-episodes", type=int, default=40, help="held-out levels per in-run evaluation")
    parser.add_argument("--test-levels", type=int, default=200, help="held-out levels of the final test")
    parser.add_argument("--test-repeats", type=int, default=2, help="episodes per held-out level in the final test")
    parser.add_argument("--take-off", type=float, default=TAKE_OFF, help="held-out success that counts as take-off")
    parser.add_argument("--reps", type=bootstrap_reps, default=REPS, help=REPS_HELP)
    parser.add_argument("--ray-address", help="a running Ray cluster (default: start a local one)")
    parser.add_argument("--progress", action="store_true", help="show each run's steps as it trains")
    parser.add_argument("--summarise", action="store_true", help="only rewrite results.json and results.md")
    parser.add_argument("--throughput", action="store_true", help="measure each kind's steps/s instead (quiet machine)")
    parser.add_argument("--throughput-steps", type=int, default=400_000, help="steps per throughput run")
    parser.add_argument(
        "--throughput-window", type=float, default=0.5, help="share of a throughput run before its timed window"
    )
    parser.add_argument("--rounds", type=int, default=5, help="throughput rounds over every kind")
    args = parser.parse_args(argv)
    if args.kinds is None:
        args.kinds = list(ARMS) if args.throughput else list(PLAN_ARMS)
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
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
