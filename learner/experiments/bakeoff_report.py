"""The bake-off's report: ``results.json`` (every figure, per seed included), ``results.md`` (the
tables a person reads), ``learning_curves.png`` (hardest-task success during training),
``performance_profile.png`` (the spread of each teacher's seeds, ``run_statistics``) and
``success_by_placement.png`` (where each teacher's students fail, the scripted controller beside them).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from common.client.schemas import TEACHER_LABELS
from common.families import family_for
from common.kuka import ENV_ID
from common.kuka.arm import TARGET_X_RANGE
from common.kuka.diagnostics import EpisodeDiagnostics
from common.levels import DEFAULT_LEVELS
from learner.core.config import TrainConfig
from learner.core.figure_file import save_png
from learner.core.json_file import write_json
from learner.evaluation.checkpoint_evaluation import EvaluationResult
from learner.evaluation.episode_diagnostics import band_table, failures_outside, plot_bands, success_by_band
from learner.evaluation.selection import VALIDATION_EPISODES
from learner.evaluation.stats import CONFIDENCE, Interval
from learner.experiments.bakeoff_runs import learning_curve
from learner.experiments.bakeoff_statistics import (
    CURVE_WINDOW,
    DEFAULT_BASELINE,
    HALF_SUCCESS,
    STEP_TARGETS,
    SUCCESS_TARGET,
    TeacherResult,
    median_steps,
    seed_statistics,
)
from learner.experiments.run_statistics import REPS, SEED, RunStatistics, plot_performance_profile, statistics_table

BOOK_RETURNS = {"alp-gmm": 3.71, "fixed": 2.81, "manual": -2.79}
"""The book's chapter 14: mean scaled return over 100 episodes on the hardest task, one seed, ~1.7M steps."""

RESULTS_JSON = "results.json"
RESULTS_MARKDOWN = "results.md"
LEARNING_CURVES = "learning_curves.png"
PLACEMENT_PLOT = "success_by_placement.png"
PERFORMANCE_PROFILE = "performance_profile.png"
RUN_STATISTICS_JSON = "run_statistics.json"
RUN_STATISTICS_MARKDOWN = "run_statistics.md"
"""What ``recompute_run_statistics`` writes for a bake-off whose results.json predates the run statistics."""
SCRIPTED_EVALUATION = "scripted_evaluation.json"
"""The scripted controller's episodes on the final evaluation's seeds, cached beside the report."""
SCRIPTED_LABEL = "Scripted controller (no learning)"


def teacher_label(kind: str) -> str:
    """How the report names a teacher kind; a kind without a label yet keeps its name."""
    return TEACHER_LABELS.get(kind, kind)


def teacher_record(result: TeacherResult) -> dict[str, Any]:
    """One teacher's entry in ``results.json``."""
    return {
        "teacher": result.teacher,
        "seeds": len(result.runs),
        "success_rate_over_seeds": result.success_over_seeds.to_dict(),
        "return_over_seeds": result.return_over_seeds.to_dict(),
        "median_steps_to_success": median_steps(result.seed_steps_to_success),
        "median_steps_to_half_success": median_steps(result.seed_steps_to(HALF_SUCCESS)),
        "return": result.returns.to_dict(),
        "success_rate": result.success_rate.to_dict(),
        "book_return": BOOK_RETURNS.get(result.teacher) if result.env == ENV_ID else None,
        **placement_record(result.diagnosed),
        "runs": [
            {
                "seed": run.seed,
                "run_dir": str(run.directory),
                "return": evaluation.returns.estimate,
                "success_rate": evaluation.success_rate.estimate,
                "mean_length": evaluation.mean_length,
                "steps_to_success": steps,
                "steps_to_half_success": half,
                "curve_seeds": seeds,
            }
            for run, evaluation, steps, half, seeds in zip(
                result.runs,
                result.evaluations,
                result.seed_steps_to_success,
                result.seed_steps_to(HALF_SUCCESS),
                result.seed_curve_seeds,
                strict=True,
            )
        ],
    }


def placement_record(diagnosed: Sequence[tuple[EpisodeDiagnostics, bool]]) -> dict[str, Any]:
    """Success by placement band and how many failures lay beyond the clamp; None for episodes evaluated
    before they recorded where their block lay."""
    if not diagnosed:
        return {"success_by_placement": None, "failures_beyond_clamp": None}
    outside, failures = failures_outside(diagnosed)
    return {
        "success_by_placement": [band.to_dict() for band in success_by_band(diagnosed)],
        "failures_beyond_clamp": {"beyond": outside, "failures": failures},
    }


def counted(count: int, singular: str, plural: str) -> str:
    """``1 seed``, ``2 seeds``: a count with its noun agreeing, for table labels."""
    return f"{count} {singular if count == 1 else plural}"


def placement_rows(
    results: Sequence[TeacherResult], scripted: EvaluationResult | None
) -> list[tuple[str, Sequence[tuple[EpisodeDiagnostics, bool]]]]:
    """The placement table's rows: each teacher with diagnosed episodes, then the scripted controller."""
    rows: list[tuple[str, Sequence[tuple[EpisodeDiagnostics, bool]]]] = [
        (f"{teacher_label(result.teacher)} ({counted(len(result.runs), 'seed', 'seeds')})", result.diagnosed)
        for result in results
        if result.diagnosed
    ]
    if scripted is not None and scripted.diagnostics:
        rows.append((SCRIPTED_LABEL, scripted.diagnosed()))
    return rows


def placement_markdown(results: Sequence[TeacherResult], scripted: EvaluationResult | None) -> list[str]:
    """The section that says where the students fail, or nothing when no episode recorded its placement."""
    rows = placement_rows(results, scripted)
    if not rows:
        return []
    missing = [teacher_label(result.teacher) for result in results if not result.diagnosed]
    low, high = TARGET_X_RANGE
    return [
        "## Where the students fail: success by block placement",
        "",
        f"The arm's IK target is clamped to x in [{low:.2f}, {high:.2f}]; a block beyond it can only be grasped "
        "by hanging the fingers over its end. Success of the final evaluations, pooled over a teacher's seeds, "
        "by how far the block lay beyond the clamp in x (episodes in brackets); the straight-ahead column "
        "counts again blocks the last bands hold. The scripted controller, which reads only the observation, "
        "played the same episode seeds.",
        "",
        *band_table(rows),
        "",
        *(
            [f"Evaluated before episodes recorded their placement, so left out: {', '.join(missing)}.", ""]
            if missing
            else []
        ),
        f"![Success by block placement]({PLACEMENT_PLOT})",
        "",
    ]


def seed_scores(results: Sequence[TeacherResult]) -> dict[str, list[float]]:
    """Each teacher's per-seed success rates on the hardest task: the scores its run statistics are over."""
    return {result.teacher: result.seed_success_rates for result in results}


def scored_policy(settings: dict[str, Any]) -> str:
    """What a run's score is of: its last checkpoint, or with ``policy_choice`` validated the checkpoint
    chosen on validation episodes (``learner.evaluation.selection``); settings stored before the choice
    existed are final."""
    if settings.get("policy_choice", "final") == "validated":
        return f"validated policy (the best of its late checkpoints on {VALIDATION_EPISODES} validation episodes)"
    return "final policy"


def scores_sentence(policy: str, where: str = "") -> str:
    """What the run statistics score each seed by, ``policy`` as ``scored_policy`` names it, and where its
    scores stand (``where``, after the task)."""
    return (
        f"Each seed's score is the success rate of its {policy} on the hardest task{where}. Computed with rliable "
        "(Agarwal et al., NeurIPS 2021), which showed that a few seeds and a point estimate mis-rank methods."
    )


def run_statistics_markdown(statistics: RunStatistics, baseline: str, policy: str) -> list[str]:
    """The section on what the seeds can tell apart: the run statistics' table, what its figures mean, and the
    performance profile; ``baseline`` is the one asked for, which ``statistics`` lacks when it was not run, and
    ``policy`` the one each seed was scored by (``scored_policy``)."""
    labels = {teacher: f"{teacher_label(teacher)} (`{teacher}`)" for teacher in statistics.arms}
    if statistics.baseline is None:
        improvement = (
            f"P(improvement) needs the baseline, {teacher_label(baseline)} (`{baseline}`), among the teachers: "
            "train it too, or name another with `--baseline`."
        )
    else:
        improvement = (
            f"P(improvement) is the chance that a seed of the teacher ends above a seed of "
            f"{teacher_label(statistics.baseline)}, ties counted half, over every pair of their seeds: 0.50 is "
            "no difference, 1.00 every seed above every one of the baseline's."
        )
    return [
        "## Over seeds, robustly: what the runs can tell apart",
        "",
        scores_sentence(policy, " (the table above)"),
        "",
        *statistics_table(statistics, labels),
        "",
        "The IQM is the mean of the middle half of the seeds, which one freak seed cannot drag (under four "
        f"seeds it trims nothing and is the mean). IQM and mean carry stratified-bootstrap percentile intervals "
        f"({statistics.reps:,} resamples, seed {statistics.seed}); the share of seeds at "
        f"{statistics.threshold:.0%} or more a Wilson interval. {improvement} A single seed leaves nothing to "
        "resample (n/a); two or three leave so few distinct resamples that the bootstrap interval is narrower "
        "than the truth.",
        "",
        f"![Performance profiles: the share of each teacher's seeds above each success rate]({PERFORMANCE_PROFILE})",
        "",
    ]


def curve_seeds_note(results: Sequence[TeacherResult]) -> str:
    """What the in-run evaluations played: stratified seeds, and which runs, trained before them, played the
    consecutive seeds from 10,000 instead, whose steps read early."""
    older = [
        f"{run.teacher} seed {run.seed}"
        for result in results
        for run, seeds in zip(result.runs, result.seed_curve_seeds, strict=True)
        if seeds == "consecutive"
    ]
    note = (
        "Their episodes are a fixed stratified set of the hardest task's, whose blocks lie over the placement "
        "bands as the final evaluation's do (`learner.core.periodic_evaluation`)."
    )
    if older:
        note += (
            f" Except for {', '.join(older)}: trained before issue 59, their in-run evaluations played the "
            "consecutive seeds from 10,000, whose blocks lie nearer the arm than the final evaluation's, so "
            "their steps read early."
        )
    return note


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


def _format_median_steps(steps: Sequence[int | None]) -> str:
    return f"{_format_steps(median_steps(steps))} ({', '.join(_format_steps(value) for value in steps)})"


def _format_setting(name: str, value: Any) -> str:
    if isinstance(value, dict):
        return f"{name.replace('_', ' ')} " + ", ".join(f"{key}={json.dumps(item)}" for key, item in value.items())
    return f"{name.replace('_', ' ')} {value}"


def registration_params(teacher: str, settings: dict[str, Any]) -> dict[str, Any]:
    """What ``train`` registers the teacher's curriculum with: the KUKA defaults, then the bake-off's
    overrides for that teacher."""
    overrides = settings.get("teacher_params", {}).get(teacher, {})
    return TrainConfig(teacher=teacher, teacher_overrides=overrides).teacher_params


def results_markdown(
    results: Sequence[TeacherResult],
    settings: dict[str, Any],
    episodes: int,
    seed: int,
    scripted: EvaluationResult | None = None,
    statistics: RunStatistics | None = None,
    baseline: str = DEFAULT_BASELINE,
) -> str:
    """``statistics``: the run statistics over ``results`` against ``baseline`` (``seed_statistics``),
    computed here when not given."""
    if statistics is None:
        statistics = seed_statistics(seed_scores(results), baseline)
    trained = ", ".join(
        _format_setting(name, value)
        for name, value in settings.items()
        if name not in ("total_steps", "teacher_params") and value != {}
    )
    registered = "; ".join(
        _format_setting(teacher_label(result.teacher), params)
        for result in results
        if (params := registration_params(result.teacher, settings))
    )
    seed_counts = sorted({len(result.runs) for result in results})
    seeds = (
        counted(seed_counts[0], "seed", "seeds")
        if len(seed_counts) == 1
        else f"{seed_counts[0]} to {seed_counts[-1]} seeds (the Seeds column says how many)"
    )
    env = settings.get("env", ENV_ID)
    # The book's returns were measured on its own task: they say nothing of another family's hardest.
    book_returns = BOOK_RETURNS if env == ENV_ID else {}
    hardest = "the hardest task" if env == ENV_ID else f"the hardest task of {env}"
    lines = [
        "# Teacher bake-off on the hardest task",
        "",
        f"Each teacher trained {seeds} for {settings['total_steps']:_} environment "
        f"steps with the same settings ({trained}) and hyperparameters. Each run's {scored_policy(settings)} then "
        f"played {episodes} deterministic episodes on {hardest} (episode seeds {seed} to {seed + episodes - 1}, "
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
        f"| Median steps to {HALF_SUCCESS:.0%} success (per seed) "
        f"| Median steps to {SUCCESS_TARGET:.0%} success (per seed) | Mean return over seeds ({CONFIDENCE:.0%} CI) |",
        "|---|---|---|---|---|---|",
    ]
    for result in results:
        success, returns = result.success_over_seeds, result.return_over_seeds
        per_seed = ", ".join(f"{rate:.0%}" for rate in result.seed_success_rates)
        steps = [result.seed_steps_to(target) for target in STEP_TARGETS]
        lines.append(
            f"| {teacher_label(result.teacher)} (`{result.teacher}`) | {_format_interval(success, percent=True)} "
            f"| {per_seed} | {' | '.join(_format_median_steps(each) for each in steps)} "
            f"| {_format_interval(returns)} |"
        )
    lines += [
        "",
        "The interval is a Student-t interval over the per-seed success rates: it says how much a new seed may "
        f"vary. Steps to a success rate: the first step at which {CURVE_WINDOW} consecutive in-run "
        f"evaluations on the hardest task ({settings['curve_episodes']} episodes each, every "
        f"{settings['curve_every']} iterations), pooled, reach it; a seed that never does counts as slowest. "
        + curve_seeds_note(results),
        "",
        *run_statistics_markdown(statistics, baseline, scored_policy(settings)),
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
            f"| {teacher_label(result.teacher)} (`{result.teacher}`) | {_format_return(result.returns)} "
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
        *placement_markdown(results, scripted),
    ]
    return "\n".join(lines)


def plot_learning_curves(path: Path, results: Sequence[TeacherResult]) -> None:
    """Hardest-task success during training. On top every teacher's mean over seeds, to compare
    them; below, one panel per teacher with each seed, to show the spread the means hide (with nine
    teachers, bands of seeds laid over each other could not be read)."""
    from matplotlib.figure import Figure

    curves_by_teacher = [
        (result, [learning_curve(run, "eval/success_rate") for run in result.runs]) for result in results
    ]
    columns = min(3, max(1, len(results)))
    rows = -(-len(results) // columns)
    figure = Figure(figsize=(4.2 * columns + 2.5, 3.6 + 2.4 * rows), layout="constrained")
    grid = figure.add_gridspec(1 + rows, columns, height_ratios=[1.5] + [1.0] * rows)
    overview = figure.add_subplot(grid[0, :])
    panels = [figure.add_subplot(grid[1 + index // columns, index % columns]) for index in range(len(results))]
    plotted = False
    for (result, curves), axes in zip(curves_by_teacher, panels, strict=True):
        label = teacher_label(result.teacher)
        common_steps = sorted(set.intersection(*(set(curve) for curve in curves)))
        if not common_steps:
            axes.set_title(f"{label}: no evaluations", fontsize="small")
            continue
        mean = np.array([[curve[step] for step in common_steps] for curve in curves]).mean(axis=0)
        (line,) = overview.plot(common_steps, mean, label=f"{label} ({counted(len(curves), 'seed', 'seeds')})")
        for curve in curves:
            steps = sorted(curve)
            axes.plot(steps, [curve[step] for step in steps], color=line.get_color(), alpha=0.35, linewidth=0.9)
        axes.plot(common_steps, mean, color=line.get_color(), linewidth=1.8)
        seeds = f"{len(curves)} seeds, mean in bold" if len(curves) > 1 else "1 seed"
        axes.set_title(f"{label} ({seeds})", fontsize="small")
        plotted = True
    if plotted:
        overview.legend(loc="center left", bbox_to_anchor=(1.01, 0.5))
    else:
        overview.text(
            0.5,
            0.5,
            "no evaluations were logged during training (--curve-every 0?)",
            ha="center",
            va="center",
            transform=overview.transAxes,
        )
    overview.set_title("Mean over seeds, every teacher")
    for index, axes in enumerate([overview, *panels]):
        axes.set_ylim(-0.03, 1.03)
        axes.set_xlabel("environment steps")
        if index == 0 or (index - 1) % columns == 0:
            axes.set_ylabel("hardest-task success")
        axes.grid(alpha=0.3)
    figure.suptitle("Hardest-task success during training (in-run evaluations)")
    save_png(figure, path, dpi=110)


def write_reports(
    out: Path,
    results: Sequence[TeacherResult],
    settings: dict[str, Any],
    episodes: int,
    seed: int,
    scripted: EvaluationResult | None = None,
    baseline: str = DEFAULT_BASELINE,
    reps: int = REPS,
) -> None:
    """Every report file; ``scripted`` is the scripted controller on the same episode seeds, for beside the
    teachers in the placement table; ``baseline`` the teacher the run statistics compare the others with, with
    ``reps`` bootstrap resamples per interval."""
    scores = seed_scores(results)
    statistics = seed_statistics(scores, baseline, reps)
    write_json(
        out / RESULTS_JSON,
        {
            "settings": settings,
            "evaluation": {
                "env": settings.get("env", ENV_ID),
                "task": family_for(settings.get("env", ENV_ID)).evaluation_task(
                    settings.get("env", ENV_ID), settings.get("levels", DEFAULT_LEVELS)
                ),
                "episodes": episodes,
                "seed": seed,
                "confidence": CONFIDENCE,
            },
            "teachers": [teacher_record(result) for result in results],
            "scripted": None
            if scripted is None
            else {
                "success_rate": scripted.success_rate.to_dict(),
                "return": scripted.returns.to_dict(),
                **placement_record(scripted.diagnosed()),
            },
            "run_statistics": statistics.to_dict(),
        },
    )
    (out / RESULTS_MARKDOWN).write_text(
        results_markdown(results, settings, episodes, seed, scripted, statistics, baseline), encoding="utf-8"
    )
    plot_learning_curves(out / LEARNING_CURVES, results)
    plot_profile(out / PERFORMANCE_PROFILE, scores, statistics)
    rows = placement_rows(results, scripted)
    if rows:
        plot_bands(out / PLACEMENT_PLOT, rows)


def plot_profile(path: Path, scores: dict[str, list[float]], statistics: RunStatistics) -> None:
    """The teachers' performance profiles, drawn as their run statistics were computed."""
    plot_performance_profile(
        path,
        scores,
        {teacher: teacher_label(teacher) for teacher in scores},
        "Final hardest-task success: the share of each teacher's seeds above each rate",
        statistics.reps,
        statistics.seed,
        statistics.confidence,
    )


def recompute_run_statistics(
    results_json: Path,
    out: Path | None = None,
    baseline: str = DEFAULT_BASELINE,
    reps: int = REPS,
    seed: int = SEED,
) -> RunStatistics:
    """The run statistics of a bake-off from its ``results.json`` alone (the per-seed success rates every
    version of it holds), for one written before them or against another baseline: ``run_statistics.json``,
    ``run_statistics.md`` and the performance profile in ``out`` (default: beside it). The results files
    themselves stay as they are."""
    data = json.loads(results_json.read_text(encoding="utf-8"))
    scores = {entry["teacher"]: [run["success_rate"] for run in entry["runs"]] for entry in data["teachers"]}
    statistics = seed_statistics(scores, baseline, reps, seed)
    out = results_json.parent if out is None else out
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / RUN_STATISTICS_JSON, statistics.to_dict())
    policy = scored_policy(data.get("settings", {}))
    section = run_statistics_markdown(statistics, baseline, policy)
    section[0] = f"# Run statistics of the bake-off in {results_json.parent.name}"
    section[2] = f"Recomputed from its `{results_json.name}`. {scores_sentence(policy)}"
    (out / RUN_STATISTICS_MARKDOWN).write_text("\n".join(section), encoding="utf-8")
    plot_profile(out / PERFORMANCE_PROFILE, scores, statistics)
    return statistics
