"""What ``kuka-curriculum tune`` shows while it runs and writes when it ends.

While it runs: one line each time a trial starts, reports a new best or ends (trials running,
pending, finished, failed, and the best so far). At the end, in the tune directory:
``trials.json`` (every trial's settings, status, final and best metrics, and its evaluation
curve), ``curves.png`` (every trial's metric against steps) and ``best.json`` (the best finished
trial's settings, in the settings-file form that ``train --config`` and ``bakeoff --config`` read).
The curves come from each trial's own metrics log (``metrics.jsonl``, or ``metrics.jsonl.xz`` once the
trial is archived), so they survive ``--resume``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ray.tune import Callback

from learner.commands.config_file import NOTES_KEY
from learner.core.figure_file import save_png
from learner.core.json_file import write_json
from learner.experiments.run_archive import metrics_records
from learner.experiments.tune_settings import EXPERIMENT, METRICS, RUNS_DIR, TuneSettings
from learner.experiments.tune_space import SearchSpace, grouped_settings, python_value

TRIALS_FILE = "trials.json"
BEST_FILE = "best.json"
CURVES_FILE = "curves.png"
FINISHED, STOPPED, FAILED, UNFINISHED = "finished", "stopped early", "failed", "unfinished"


PROGRESS_EVERY_S = 60.0
"""The longest a running tune stays silent."""


class TuneProgress(Callback):
    """Prints a status line whenever the picture changes (trials by state, the best so far), and
    at least every ``PROGRESS_EVERY_S`` while trials train, with the steps trained of the whole tune."""

    def __init__(self, metric: str, trials: int, total_steps: int) -> None:
        self.metric = metric
        self.trials = trials
        self.total_steps = total_steps
        self.started = time.monotonic()
        self.best: tuple[float, str, float] | None = None
        self.steps: dict[str, float] = {}
        self.last_line = ""
        self.last_printed = self.started

    def on_trial_start(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        self._print(trials, starting=trial)  # Tune calls this before it marks the trial running

    def on_trial_result(
        self, iteration: int, trials: list[Any], trial: Any, result: dict[str, Any], **info: Any
    ) -> None:
        value = result.get(self.metric)
        if isinstance(value, (int, float)) and not math.isnan(value) and (self.best is None or value > self.best[0]):
            self.best = (float(value), trial.trial_id, float(result.get("steps", 0)))
        self.steps[trial.trial_id] = float(result.get("steps", 0))
        self._print(trials)

    def on_trial_complete(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        self._print(trials)

    def on_trial_error(self, iteration: int, trials: list[Any], trial: Any, **info: Any) -> None:
        print(f"trial {trial.trial_id} failed; its error is in {trial.path}, and trials.json at the end", flush=True)
        self._print(trials)

    def _print(self, trials: list[Any], starting: Any = None) -> None:
        statuses = ["RUNNING" if trial is starting else trial.status for trial in trials]
        counts = {state: statuses.count(state) for state in ("RUNNING", "PENDING", "ERROR")}
        done = statuses.count("TERMINATED")
        best = "none yet" if self.best is None else f"{self.best[0]:.3g} ({self.best[1]} at {self.best[2]:_.0f} steps)"
        line = (
            f"{counts['RUNNING']} running, {counts['PENDING']} pending, {done} finished, {counts['ERROR']} failed "
            f"of {self.trials} | best {self.metric} so far: {best}"
        )
        now = time.monotonic()
        if line != self.last_line or now - self.last_printed >= PROGRESS_EVERY_S:
            self.last_line, self.last_printed = line, now
            steps = f"{sum(self.steps.values()):_.0f} of at most {self.trials * self.total_steps:_} steps trained"
            print(f"[tune {now - self.started:6.0f}s] {line} | {steps}", flush=True)


@dataclass(frozen=True)
class TuneReport:
    summary: str
    unfinished: int
    best: dict[str, Any] | None
    settled_runs: tuple[Path, ...] = ()
    """The run directories of the trials that will not train again (finished, stopped early or failed:
    ``--resume`` continues only the unfinished), which the tune archives (``run_archive``)."""


def evaluation_curve(run_dir: Path) -> list[dict[str, float]]:
    """The run's in-run evaluations by step; a step logged twice (a resumed run repeats the iterations
    after its last checkpoint) keeps its latest record."""
    by_step: dict[int, dict[str, float]] = {}
    for record in metrics_records(run_dir):
        if record.get("eval/success_rate") is not None:
            by_step[int(record["step"])] = {
                "steps": float(record["step"]),
                "success": float(record["eval/success_rate"]),
                "return": float(record["eval/return"]),
            }
    return [by_step[step] for step in sorted(by_step)]


def _error(trial: Any) -> str | None:
    """The exception's last line, from the trial's error file."""
    path = trial.error_file
    if not path or not Path(path).exists():
        return None
    lines = [line.strip() for line in Path(path).read_text(encoding="utf-8", errors="replace").splitlines()]
    lines = [line for line in lines if line]
    return lines[-1] if lines else None


def trial_entry(trial: Any, settings: TuneSettings, runs_dir: Path, out: Path) -> dict[str, Any]:
    run_dir = runs_dir / trial.trial_id
    curve = evaluation_curve(run_dir)
    last = trial.last_result or {}
    # The steps trained, which the last result reports: the last evaluation may come iterations before the end.
    steps = int(last.get("steps") or (curve[-1]["steps"] if curve else 0))
    if trial.status == "ERROR":
        status = FAILED
    elif trial.status == "TERMINATED" and last.get("done"):
        status = FINISHED if steps >= settings.total_steps else STOPPED
    else:
        status = UNFINISHED
    best = max(curve, key=lambda point: point[settings.metric]) if curve else None
    return {
        "trial": trial.trial_id,
        "status": status,
        "config": {key: _json_value(value) for key, value in trial.config.items()},
        "final": curve[-1] if curve else None,
        "best": best,
        "error": _error(trial) if status == FAILED else None,
        "run_dir": str(run_dir.relative_to(out)),
        "curve": curve,
    }


def _json_value(value: Any) -> Any:
    value = python_value(value)
    return list(value) if isinstance(value, tuple) else value


def best_settings(entry: dict[str, Any], settings: TuneSettings, metric_value: float) -> dict[str, Any]:
    """The trial's settings as a settings file (``learner.commands.config_file``): the fixed ones, its draws on top."""
    chosen: dict[str, Any] = {
        "teacher": settings.teacher,
        "env": settings.env,
        "workers": settings.workers,
        "envs_per_worker": settings.envs_per_worker,
        "ppo": dict(settings.ppo),
        "teacher_params": dict(settings.teacher_params),
    }
    grouped = grouped_settings(entry["config"])
    chosen.update(grouped["env"])
    chosen["ppo"].update(grouped["ppo"])
    chosen["teacher_params"].update(grouped["teacher"])
    chosen[NOTES_KEY] = {
        "trial": entry["trial"],
        "metric": settings.metric,
        "value": metric_value,
        "steps": entry["final"]["steps"],
        "total_steps": settings.total_steps,
    }
    return chosen


def _plot(path: Path, entries: list[dict[str, Any]], metric: str, best: str | None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(8, 5))
    for entry in entries:
        if entry["curve"]:
            steps = [point["steps"] for point in entry["curve"]]
            values = [point[metric] for point in entry["curve"]]
            bold = entry["trial"] == best
            axes.plot(
                steps, values, marker="o", linewidth=2.5 if bold else 1.0, label=f"{entry['trial']} ({entry['status']})"
            )
    axes.set_xlabel("environment steps")
    axes.set_ylabel(f"{metric} on the hardest task (in-run evaluation)")
    axes.set_title("kuka-curriculum tune: every trial" + (f"; best {best}" if best else ""))
    if metric == "success":
        axes.set_ylim(-0.02, 1.02)
    axes.grid(alpha=0.3)
    if any(entry["curve"] for entry in entries):
        axes.legend(fontsize="small")
    figure.tight_layout()
    save_png(figure, path, dpi=100)
    plt.close(figure)


def write_reports(out: Path, settings: TuneSettings, space: SearchSpace, elapsed: float) -> TuneReport:
    from ray.tune import ExperimentAnalysis

    trials = ExperimentAnalysis(str(out / EXPERIMENT)).trials
    entries = sorted((trial_entry(trial, settings, out / RUNS_DIR, out) for trial in trials), key=lambda e: e["trial"])
    finished = [entry for entry in entries if entry["status"] == FINISHED]
    # Ties (short tunes often end at 0% success for all) go to the other metric.
    other = next(name for name in METRICS if name != settings.metric)
    best_entry = max(finished, key=lambda entry: (entry["final"][settings.metric], entry["final"][other]), default=None)
    best = None
    if best_entry is not None:
        best = best_settings(best_entry, settings, best_entry["final"][settings.metric])
        write_json(out / BEST_FILE, best)
    write_json(
        out / TRIALS_FILE,
        {
            "metric": settings.metric,
            "searched": [dimension.key for dimension in space.dimensions],
            "best": best_entry["trial"] if best_entry else None,
            "seconds_this_invocation": round(elapsed, 1),  # Tune's loop; a resumed tune counts only its own
            "trials": entries,
        },
    )
    _plot(out / CURVES_FILE, entries, settings.metric, best_entry["trial"] if best_entry else None)
    lines = [
        f"{len(entries)} trials, {elapsed:.0f} s in this invocation ({settings.metric} at the hardest task, "
        "final evaluation):"
    ]
    for entry in entries:
        value = f"{entry['final'][settings.metric]:.3g}" if entry["final"] else "-"
        drawn = ", ".join(f"{key}={value!r}" for key, value in entry["config"].items())
        lines.append(f"  {entry['trial']}  {entry['status']:<13} {value:>6}  {drawn}")
        if entry["error"]:
            lines.append(f"      error: {entry['error']}")
    if best_entry is None:
        lines.append("no trial finished its budget, so there is no best.json")
    else:
        lines.append(f"best: {best_entry['trial']} -> {out / BEST_FILE}")
    lines += [f"{out / TRIALS_FILE}", f"{out / CURVES_FILE}"]
    unfinished = sum(entry["status"] == UNFINISHED for entry in entries)
    settled = tuple(out / entry["run_dir"] for entry in entries if entry["status"] != UNFINISHED)
    return TuneReport("\n".join(lines), unfinished, best, settled)
