"""``kuka-curriculum bakeoff``: every teacher, several seeds, one budget, one table.

Each teacher x seed is an ordinary ``kuka-curriculum train`` run in ``DIR/runs/<teacher>-seed<k>``,
started as a child process: it brings its own teacher service and Ray connection, a crash stays
inside it, and its log goes to the run directory. The bake-off is resumable at every point: a run
whose checkpoint reached the budget is skipped, a run with an earlier checkpoint continues from
it with ``--resume``, and each final evaluation is cached next to its checkpoint. Ctrl-C is left
to the training child (it checkpoints and stops); running the same command again carries on.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
from tqdm import tqdm

from common import ENV_ID, ENV_IDS
from common.schemas import TeacherKind
from common.task_space import task_space_for
from learner.arguments import UsageError, add_override_flags, int_at_least, positive_int
from learner.checkpoint import latest_checkpoint, load_checkpoint
from learner.checkpoint_evaluation import EvaluationResult, evaluate_checkpoint
from learner.config import LOOPS, TrainConfig
from learner.json_file import write_json
from learner.metrics import METRICS_FILE
from learner.stats import CONFIDENCE, Interval, mean_interval, wilson_interval

DEFAULT_TEACHERS = ("alp-gmm", "manual", "fixed", "random")
TEACHER_LABELS = {
    "alp-gmm": "ALP-GMM",
    "manual": "Manual lesson plan",
    "fixed": "No curriculum: hardest task only",
    "random": "Uniform random tasks",
}
BOOK_RETURNS = {"alp-gmm": 3.71, "fixed": 2.81, "manual": -2.79}
"""The book's chapter 14: mean scaled return over 100 episodes on the hardest task, one seed, ~1.7M steps."""

RUNS_DIR = "runs"
SETTINGS_FILE = "bakeoff.json"
TRAIN_LOG = "train.log"
EVALUATION_FILE = "evaluation.json"
RESULTS_JSON = "results.json"
RESULTS_MARKDOWN = "results.md"
LEARNING_CURVES = "learning_curves.png"
POLL_S = 1.0

TRAINING_FLAGS = {
    "env": "--env",
    "workers": "--workers",
    "envs_per_worker": "--envs-per-worker",
    "rollout_length": "--rollout-length",
    "max_episode_steps": "--max-episode-steps",
    "checkpoint_every": "--checkpoint-every",
    "curve_every": "--eval-every",
    "curve_episodes": "--eval-episodes",
    "loop": "--loop",
}
"""Bake-off options handed to every ``train`` run unchanged (its flag there): what makes the comparison fair."""
REPEATED_FLAGS = {"teacher_params": "--teacher-param", "ppo": "--ppo"}
"""Bake-off options given as NAME=VALUE pairs, handed to every run as one flag per pair."""
ADDED_SETTINGS = {"loop": "sync", "teacher_params": {}, "ppo": {}, "env": ENV_ID}
"""Settings newer than some stored bake-offs, with the value their runs were trained with."""
SUCCESS_TARGET = 0.8
"""The success rate on the hardest task whose first crossing the report times."""
CURVE_WINDOW = 3
"""Consecutive in-run evaluations pooled for that reading, so it is not one small evaluation's luck."""


class RunFailed(Exception):
    """A training child exited with an error."""


@dataclass(frozen=True)
class Run:
    teacher: str
    seed: int
    directory: Path

    @property
    def name(self) -> str:
        return self.directory.name

    def steps_done(self) -> int:
        """Environment steps in the run's latest checkpoint (0 before the first one)."""
        path = latest_checkpoint(self.directory)
        return load_checkpoint(path).counters.steps if path else 0


def plan_runs(out: Path, teachers: Sequence[str], seeds: int) -> list[Run]:
    return [
        Run(teacher, seed, Path(out) / RUNS_DIR / f"{teacher}-seed{seed}")
        for teacher in teachers
        for seed in range(seeds)
    ]


def check_settings(out: Path, settings: dict[str, Any]) -> None:
    """Runs in one directory must share their hyperparameters; only the step budget may grow.

    The settings of the first invocation are stored in DIR, and a later invocation that differs is
    refused instead of silently comparing runs trained differently.
    """
    path = Path(out) / SETTINGS_FILE
    if path.exists():
        stored = ADDED_SETTINGS | json.loads(path.read_text(encoding="utf-8"))
        differences = [
            f"{name}: {stored.get(name)!r} before, {value!r} now"
            for name, value in settings.items()
            if name != "total_steps" and stored.get(name) != value
        ]
        if differences:
            raise UsageError(
                f"{out} holds a bake-off with other training settings ({'; '.join(differences)}); "
                "use the same flags or another --out"
            )
        if settings["total_steps"] < stored["total_steps"]:
            raise UsageError(
                f"{out} holds runs trained for {stored['total_steps']:_} steps; "
                f"--total-steps {settings['total_steps']:_} would compare them with shorter ones"
            )
    write_json(path, settings)


def train_command(
    run: Run, total_steps: int, settings: dict[str, Any], resume: bool, ray_address: str | None
) -> list[str]:
    command = [
        sys.executable,
        "-m",
        "common.cli",
        "train",
        "--teacher",
        run.teacher,
        "--seed",
        str(run.seed),
        "--total-steps",
        str(total_steps),
        "--run-dir",
        str(run.directory),
    ]
    for name, flag in TRAINING_FLAGS.items():
        command += [flag, str(settings[name])]
    for name, flag in REPEATED_FLAGS.items():
        for key, value in settings[name].items():
            command += [flag, f"{key}={json.dumps(value)}"]
    if ray_address is not None:
        command += ["--ray-address", ray_address]
    return command + (["--resume"] if resume else [])


def _clear_unfinished_start(run: Run) -> None:
    """A run that stopped before its first checkpoint restarts from nothing; keep only its log."""
    if run.directory.is_dir():
        for entry in run.directory.iterdir():
            if entry.name != TRAIN_LOG:
                shutil.rmtree(entry) if entry.is_dir() else entry.unlink()


def _metrics_records(run: Run) -> list[dict[str, Any]]:
    """The run's metric records; a line cut short (a crash mid-write, or the child writing now) is left out."""
    path = run.directory / METRICS_FILE
    records = []
    for line in path.read_text(encoding="utf-8").splitlines() if path.exists() else []:
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def _logged_steps(run: Run) -> int:
    records = _metrics_records(run)
    return int(records[-1]["step"]) if records else 0


def train_run(run: Run, command: list[str], progress: tqdm[Any], steps_of_other_runs: int) -> bool:
    """Run one training child to its end; False when it was interrupted (Ctrl-C).

    While it runs this process ignores Ctrl-C, which reaches the child too: the child finishes its
    iteration and writes a checkpoint, then the bake-off stops.
    """
    interrupted = False

    def note_interrupt(signum: int, frame: Any) -> None:
        nonlocal interrupted
        interrupted = True

    run.directory.mkdir(parents=True, exist_ok=True)
    log_path = run.directory / TRAIN_LOG
    previous = signal.signal(signal.SIGINT, note_interrupt)
    try:
        with log_path.open("ab") as log:
            child = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
            while child.poll() is None:
                time.sleep(POLL_S)
                progress.update(steps_of_other_runs + _logged_steps(run) - progress.n)
    finally:
        signal.signal(signal.SIGINT, previous)
    if interrupted:
        return False
    if child.returncode != 0:
        tail = "\n".join(log_path.read_text(encoding="utf-8", errors="replace").splitlines()[-15:])
        raise RunFailed(f"training {run.name} exited with code {child.returncode}; see {log_path}:\n{tail}")
    return True


def evaluate_run(run: Run, episodes: int, seed: int, processes: int | None, env_id: str = ENV_ID) -> EvaluationResult:
    """The final policy on its environment's hardest task, cached with the checkpoint it came from."""
    checkpoint = latest_checkpoint(run.directory)
    assert checkpoint is not None, f"{run.name} finished training, so it has written a checkpoint"
    cache = run.directory / EVALUATION_FILE
    if cache.exists():
        cached = json.loads(cache.read_text(encoding="utf-8"))
        if (
            cached["checkpoint"] == checkpoint.name
            and cached["episodes"] == episodes
            and cached["seed"] == seed
            and cached.get("env", ENV_ID) == env_id
        ):
            return EvaluationResult.from_dict(cached)
    task = task_space_for(env_id).hardest()
    result = evaluate_checkpoint(load_checkpoint(checkpoint), task, episodes, seed, processes)
    write_json(cache, {"checkpoint": checkpoint.name, **result.to_dict()})
    return result


def learning_curve(run: Run, metric: str = "eval/return") -> dict[int, float]:
    """A hardest-task evaluation metric by environment step, from the run's metrics log.

    An interrupted run repeats the iterations after its last checkpoint, so a step logged twice
    keeps its latest record.
    """
    return {
        int(record["step"]): float(record[metric]) for record in _metrics_records(run) if record.get(metric) is not None
    }


def steps_to_success(run: Run, target: float = SUCCESS_TARGET, window: int = CURVE_WINDOW) -> int | None:
    """The first step at which the last ``window`` in-run evaluations, pooled, reach ``target`` success
    (they share their episode count, so pooling is their mean); None if they never do."""
    curve = sorted(learning_curve(run, "eval/success_rate").items())
    for end in range(window, len(curve) + 1):
        if np.mean([rate for _, rate in curve[end - window : end]]) >= target:
            return curve[end - 1][0]
    return None


def median_steps(steps: Sequence[int | None]) -> float | None:
    """The median over seeds, a seed that never got there counting as slower than all; None if the
    median seed never got there."""
    ordered = sorted(math.inf if value is None else value for value in steps)
    middle = len(ordered) // 2
    median = ordered[middle] if len(ordered) % 2 else (ordered[middle - 1] + ordered[middle]) / 2
    return None if math.isinf(median) else float(median)


@dataclass(frozen=True)
class TeacherResult:
    teacher: str
    runs: tuple[Run, ...]
    evaluations: tuple[EvaluationResult, ...]
    env: str = ENV_ID
    """The environment the runs trained and were evaluated on."""

    @property
    def returns(self) -> Interval:
        """Pooled over every seed's episodes; ``seed_returns`` shows the spread between seeds."""
        return mean_interval([episode.reward for result in self.evaluations for episode in result.episodes])

    @property
    def success_rate(self) -> Interval:
        episodes = [episode for result in self.evaluations for episode in result.episodes]
        return wilson_interval(sum(episode.success for episode in episodes), len(episodes))

    @property
    def seed_returns(self) -> list[float]:
        return [result.returns.estimate for result in self.evaluations]

    @property
    def seed_success_rates(self) -> list[float]:
        return [result.success_rate.estimate for result in self.evaluations]

    @property
    def success_over_seeds(self) -> Interval:
        """The mean of the seeds' success rates, with a Student-t interval over seeds (cut to [0, 1]):
        what a new seed may give."""
        interval = mean_interval(self.seed_success_rates)
        return replace(interval, low=max(interval.low, 0.0), high=min(interval.high, 1.0))

    @property
    def return_over_seeds(self) -> Interval:
        return mean_interval(self.seed_returns)

    @property
    def seed_steps_to_success(self) -> list[int | None]:
        return [steps_to_success(run) for run in self.runs]

    def to_dict(self) -> dict[str, Any]:
        return {
            "teacher": self.teacher,
            "seeds": len(self.runs),
            "success_rate_over_seeds": self.success_over_seeds.to_dict(),
            "return_over_seeds": self.return_over_seeds.to_dict(),
            "median_steps_to_success": median_steps(self.seed_steps_to_success),
            "return": self.returns.to_dict(),
            "success_rate": self.success_rate.to_dict(),
            "book_return": BOOK_RETURNS.get(self.teacher) if self.env == ENV_ID else None,
            "runs": [
                {
                    "seed": run.seed,
                    "run_dir": str(run.directory),
                    "return": result.returns.estimate,
                    "success_rate": result.success_rate.estimate,
                    "mean_length": result.mean_length,
                    "steps_to_success": steps,
                }
                for run, result, steps in zip(self.runs, self.evaluations, self.seed_steps_to_success, strict=True)
            ],
        }


def _format_return(interval: Interval) -> str:
    spread = "n/a" if np.isnan(interval.half_width) else f"{interval.half_width:.2f}"
    return f"{interval.estimate:.2f} ± {spread}"


def _format_interval(interval: Interval, percent: bool = False) -> str:
    """'91% [85%, 97%]' or '5.20 [4.10, 6.30]'; bounds are 'n/a' for a single seed."""
    number = "{:.0%}" if percent else "{:.2f}"
    if np.isnan(interval.low):
        return f"{number.format(interval.estimate)} [n/a]"
    return f"{number.format(interval.estimate)} [{number.format(interval.low)}, {number.format(interval.high)}]"


def _format_steps(steps: float | None) -> str:
    return "not reached" if steps is None else f"{steps / 1e6:.2f}M"


def _format_setting(name: str, value: Any) -> str:
    if isinstance(value, dict):
        return f"{name.replace('_', ' ')} " + ", ".join(f"{key}={json.dumps(item)}" for key, item in value.items())
    return f"{name.replace('_', ' ')} {value}"


def registration_params(teacher: str, settings: dict[str, Any]) -> dict[str, Any]:
    """What ``train`` registers the teacher's curriculum with: the KUKA defaults, then the bake-off's overrides."""
    overrides = settings.get("teacher_params", {})
    return TrainConfig(teacher=cast(TeacherKind, teacher), teacher_overrides=overrides).teacher_params


def results_markdown(results: Sequence[TeacherResult], settings: dict[str, Any], episodes: int, seed: int) -> str:
    trained = ", ".join(
        _format_setting(name, value)
        for name, value in settings.items()
        if name not in ("total_steps", "teacher_params") and value != {}
    )
    registered = "; ".join(
        _format_setting(TEACHER_LABELS[result.teacher], params)
        for result in results
        if (params := registration_params(result.teacher, settings))
    )
    seeds = max(len(result.runs) for result in results)
    env = settings.get("env", ENV_ID)
    # The book's returns were measured on its own task: they say nothing of another family's hardest.
    book_returns = BOOK_RETURNS if env == ENV_ID else {}
    hardest = "the hardest task" if env == ENV_ID else f"the hardest task of {env}"
    lines = [
        "# Teacher bake-off on the hardest task",
        "",
        f"Each teacher trained {seeds} seed{'s' if seeds > 1 else ''} for {settings['total_steps']:_} environment "
        f"steps with the same settings ({trained}) and hyperparameters. Each final policy then played "
        f"{episodes} deterministic episodes on {hardest} (episode seeds {seed} to {seed + episodes - 1}, "
        "the same for every run).",
        *(
            [f"Teachers registered with these parameters on top of their own defaults: {registered}."]
            if registered
            else []
        ),
        "",
        "## Between seeds: what a new seed may give",
        "",
        f"| Teacher | Success rate, mean over seeds ({CONFIDENCE:.0%} CI over seeds) | Success per seed "
        f"| Median steps to {SUCCESS_TARGET:.0%} success (per seed) | Mean return over seeds ({CONFIDENCE:.0%} CI) |",
        "|---|---|---|---|---|",
    ]
    for result in results:
        success, returns = result.success_over_seeds, result.return_over_seeds
        per_seed = ", ".join(f"{rate:.0%}" for rate in result.seed_success_rates)
        steps = result.seed_steps_to_success
        lines.append(
            f"| {TEACHER_LABELS[result.teacher]} (`{result.teacher}`) | {_format_interval(success, percent=True)} "
            f"| {per_seed} | {_format_steps(median_steps(steps))} ({', '.join(_format_steps(v) for v in steps)}) "
            f"| {_format_interval(returns)} |"
        )
    lines += [
        "",
        "The interval is a Student-t interval over the per-seed success rates: it says how much a new seed may "
        f"vary. Steps to {SUCCESS_TARGET:.0%} success: the first step at which {CURVE_WINDOW} consecutive in-run "
        f"evaluations on the hardest task ({settings['curve_episodes']} episodes each, every "
        f"{settings['curve_every']} iterations), pooled, reach it; a seed that never does counts as slowest.",
        "",
        "## Pooled episodes: evaluation noise",
        "",
        f"| Teacher | Mean return ({CONFIDENCE:.0%} CI) | Success rate (Wilson {CONFIDENCE:.0%}) | Seeds "
        "| Mean return per seed | Book's mean return |",
        "|---|---|---|---|---|---|",
    ]
    for result in results:
        success = result.success_rate
        book = book_returns.get(result.teacher)
        per_seed = ", ".join(f"{value:.2f}" for value in result.seed_returns)
        lines.append(
            f"| {TEACHER_LABELS[result.teacher]} (`{result.teacher}`) | {_format_return(result.returns)} "
            f"| {success.estimate:.0%} [{success.low:.0%}, {success.high:.0%}] | {len(result.runs)} "
            f"| {per_seed} | {'—' if book is None else f'{book:.2f}'} |"
        )
    lines += [
        "",
        "These intervals pool the evaluation episodes of all seeds, so they measure evaluation noise, not the "
        "spread between seeds.",
        "The book's figures (chapter 14) come from one seed per teacher at about 1.7M steps, with RLlib's PPO, "
        "60 workers and one ALP-GMM per environment copy, and no error bars; its 'no curriculum' run trained "
        "on the hardest task, as our `fixed` teacher does. It reports no uniform-random baseline.",
        "",
        f"![Hardest-task evaluations during training]({LEARNING_CURVES})",
        "",
    ]
    return "\n".join(lines)


def plot_learning_curves(path: Path, results: Sequence[TeacherResult]) -> None:
    """Success rate and return on the hardest task during training: the mean over seeds, with a band
    from the worst to the best seed, one line per teacher."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(12, 5), layout="constrained")
    panels = figure.subplots(1, 2)
    for axes, metric, label in zip(
        panels, ("eval/success_rate", "eval/return"), ("success rate", "mean return"), strict=True
    ):
        plotted = False
        for result in results:
            curves = [learning_curve(run, metric) for run in result.runs]
            common_steps = sorted(set.intersection(*(set(curve) for curve in curves)))
            if not common_steps:
                continue
            values = np.array([[curve[step] for step in common_steps] for curve in curves])
            name = f"{TEACHER_LABELS[result.teacher]} ({len(curves)} seed{'s' if len(curves) > 1 else ''})"
            (line,) = axes.plot(common_steps, values.mean(axis=0), label=name)
            if len(curves) > 1:
                axes.fill_between(
                    common_steps, values.min(axis=0), values.max(axis=0), color=line.get_color(), alpha=0.2
                )
            plotted = True
        if plotted:
            axes.legend(loc="best")
        else:
            axes.text(
                0.5,
                0.5,
                "no evaluations were logged during training (--curve-every 0?)",
                ha="center",
                va="center",
                transform=axes.transAxes,
            )
        axes.set_xlabel("environment steps")
        axes.set_ylabel(f"{label} on the hardest task")
        axes.grid(alpha=0.3)
    figure.suptitle("Hardest-task evaluations during training (band: worst to best seed)")
    figure.savefig(path, dpi=120)


def write_reports(
    out: Path, results: Sequence[TeacherResult], settings: dict[str, Any], episodes: int, seed: int
) -> None:
    write_json(
        out / RESULTS_JSON,
        {
            "settings": settings,
            "evaluation": {
                "env": settings.get("env", ENV_ID),
                "task": task_space_for(settings.get("env", ENV_ID)).hardest(),
                "episodes": episodes,
                "seed": seed,
                "confidence": CONFIDENCE,
            },
            "teachers": [result.to_dict() for result in results],
        },
    )
    (out / RESULTS_MARKDOWN).write_text(results_markdown(results, settings, episodes, seed), encoding="utf-8")
    plot_learning_curves(out / LEARNING_CURVES, results)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = TrainConfig()
    parser.add_argument(
        "--teachers",
        nargs="+",
        choices=DEFAULT_TEACHERS,
        default=list(DEFAULT_TEACHERS),
        metavar="TEACHER",
        help=f"teachers to compare (default: {' '.join(DEFAULT_TEACHERS)})",
    )
    parser.add_argument("--seeds", type=positive_int, default=3, help="seeds per teacher: 0, 1, ... (default 3)")
    parser.add_argument(
        "--total-steps",
        type=positive_int,
        default=defaults.total_steps,
        help=f"environment steps per run (default {defaults.total_steps:_})",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("runs/bakeoff"), help="bake-off directory (default runs/bakeoff)"
    )
    evaluation = parser.add_argument_group("final evaluation (hardest task)")
    evaluation.add_argument(
        "--eval-episodes", type=positive_int, default=100, help="episodes per final policy (default 100)"
    )
    evaluation.add_argument("--eval-seed", type=int, default=0, help="episode i is seeded eval-seed + i (default 0)")
    evaluation.add_argument("--eval-processes", type=positive_int, help="evaluation processes (default: one per CPU)")
    training = parser.add_argument_group("training, the same for every run")
    training.add_argument(
        "--env",
        choices=ENV_IDS,
        default=defaults.env,
        help=f"task family; each run's final evaluation is its hardest task (default {defaults.env})",
    )
    training.add_argument(
        "--workers", type=positive_int, default=defaults.workers, help=f"rollout actors (default {defaults.workers})"
    )
    training.add_argument(
        "--envs-per-worker",
        type=positive_int,
        default=defaults.envs_per_worker,
        help=f"environments per actor (default {defaults.envs_per_worker})",
    )
    training.add_argument(
        "--rollout-length",
        type=positive_int,
        default=defaults.ppo.rollout_length,
        help=f"steps per environment per iteration (default {defaults.ppo.rollout_length})",
    )
    training.add_argument(
        "--max-episode-steps",
        type=positive_int,
        default=defaults.max_episode_steps,
        help=f"episode step limit (default {defaults.max_episode_steps})",
    )
    training.add_argument(
        "--checkpoint-every",
        type=positive_int,
        default=defaults.checkpoint_every,
        help=f"iterations between checkpoints (default {defaults.checkpoint_every})",
    )
    training.add_argument(
        "--curve-every",
        type=int_at_least(0),
        default=defaults.eval_every,
        help=f"iterations between learning-curve evaluations, 0 for none (default {defaults.eval_every})",
    )
    training.add_argument(
        "--curve-episodes",
        type=positive_int,
        default=defaults.eval_episodes,
        help=f"episodes per learning-curve evaluation (default {defaults.eval_episodes})",
    )
    training.add_argument(
        "--loop", choices=LOOPS, default=defaults.loop, help=f"training loop (default {defaults.loop})"
    )
    add_override_flags(training, "for every run")
    training.add_argument(
        "--ray-address", help="a running Ray cluster for the runs (default: each run starts a local one)"
    )


def run(args: argparse.Namespace) -> int:
    try:
        return _bakeoff(args)
    except UsageError as error:
        print(f"kuka-curriculum bakeoff: error: {error}", file=sys.stderr)
        return 2
    except RunFailed as error:
        print(f"kuka-curriculum bakeoff: {error}", file=sys.stderr)
        return 1


def _bakeoff(args: argparse.Namespace) -> int:
    teachers = list(dict.fromkeys(args.teachers))
    settings = {name: getattr(args, name) for name in TRAINING_FLAGS} | {"total_steps": args.total_steps}
    settings |= {name: dict(getattr(args, name)) for name in REPEATED_FLAGS}
    check_settings(args.out, settings)
    runs = plan_runs(args.out, teachers, args.seeds)
    done = {run.name: run.steps_done() for run in runs}

    def counted(run: Run) -> int:
        return min(done[run.name], int(args.total_steps))

    # Steps trained in earlier sessions start the bar, so its rate and ETA count this session's steps only.
    total = len(runs) * args.total_steps
    already = sum(counted(run) for run in runs)
    with tqdm(
        total=total, initial=already, unit="step", unit_scale=True, desc="bake-off", dynamic_ncols=True
    ) as progress:
        for run in runs:
            if done[run.name] >= args.total_steps:
                progress.write(f"{run.name}: finished at {done[run.name]:_} steps, skipped")
                continue
            resume = done[run.name] > 0
            if resume:
                (run.directory / EVALUATION_FILE).unlink(missing_ok=True)
            else:
                _clear_unfinished_start(run)
            progress.write(
                f"{run.name}: {'resuming at ' + format(done[run.name], '_') if resume else 'training'} "
                f"(log: {run.directory / TRAIN_LOG})"
            )
            command = train_command(run, args.total_steps, settings, resume, args.ray_address)
            steps_of_other_runs = sum(counted(other) for other in runs if other is not run)
            finished = train_run(run, command, progress, steps_of_other_runs) and run.steps_done() >= args.total_steps
            if not finished:
                progress.write("interrupted; run the same command again to resume")
                return 130
            done[run.name] = run.steps_done()

    results = []
    for teacher in teachers:
        teacher_runs = tuple(run for run in runs if run.teacher == teacher)
        evaluations = []
        for run in teacher_runs:
            evaluation = evaluate_run(run, args.eval_episodes, args.eval_seed, args.eval_processes, args.env)
            print(f"{run.name}: {evaluation.summary()}")
            evaluations.append(evaluation)
        results.append(TeacherResult(teacher, teacher_runs, tuple(evaluations), args.env))
    write_reports(args.out, results, settings, args.eval_episodes, args.eval_seed)
    for name in (RESULTS_MARKDOWN, RESULTS_JSON, LEARNING_CURVES):
        print(args.out / name)
    return 0
