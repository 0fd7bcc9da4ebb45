"""``kuka-curriculum bakeoff``: every teacher, several seeds, one budget, one table.

The command trains every teacher x seed as its own ``train`` run (``bakeoff_runs``: resumable at
every point, so running the same command again carries on after Ctrl-C or a crash), evaluates each
final policy on the hardest task as soon as that run is trained (then compresses its raw files and
keeps only that evaluated checkpoint), plays the scripted controller on the
same episode seeds, sums the runs up per teacher (``bakeoff_statistics``; over seeds, with rliable's ``run_statistics``
against a baseline teacher) and writes the results (``bakeoff_report``).
"""

from __future__ import annotations

import argparse
import functools
from pathlib import Path

from common.families import family_for
from learner.commands.arguments import add_override_flags, int_at_least, positive_int, run_command
from learner.commands.config_file import CONFIG_HELP, BakeoffConfigAction, config_path
from learner.commands.training_flags import add_training_flags
from learner.core.config import TEACHERS, TrainConfig
from learner.evaluation.checkpoint_evaluation import EvaluationResult, scripted_evaluation
from learner.experiments.bakeoff_report import (
    LEARNING_CURVES,
    PERFORMANCE_PROFILE,
    PLACEMENT_PLOT,
    RESULTS_JSON,
    RESULTS_MARKDOWN,
    SCRIPTED_EVALUATION,
    write_reports,
)
from learner.experiments.bakeoff_runs import (
    TRAINING_FLAGS,
    Run,
    RunFailed,
    archives_runs,
    check_curricula,
    check_settings,
    evaluate_run,
    further_finished_runs,
    kinds_for_family,
    plan_runs,
    teacher_params_by_kind,
    train_runs,
)
from learner.experiments.bakeoff_statistics import DEFAULT_BASELINE, TeacherResult
from learner.experiments.run_archive import archive_run
from learner.experiments.run_statistics import REPS, REPS_HELP, bootstrap_reps
from learner.job.teacher_probe import teacher_probe


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = TrainConfig()
    parser.add_argument(
        "--teachers",
        nargs="+",
        choices=TEACHERS,
        metavar="TEACHER",
        help=f"teachers to compare, of {' '.join(TEACHERS)} (default: every kind that takes the environment's "
        "task space, as the service lists them)",
    )
    parser.add_argument(
        "--seeds",
        type=positive_int,
        default=3,
        help="seeds per teacher to train: 0, 1, ... (default 3); the report also counts a teacher's further "
        "seeds that an earlier invocation trained to the budget",
    )
    parser.add_argument(
        "--total-steps",
        type=positive_int,
        default=defaults.total_steps,
        help=f"environment steps per run (default {defaults.total_steps:_})",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("runs/bakeoff"), help="bake-off directory (default runs/bakeoff)"
    )
    parser.add_argument(
        "--baseline",
        choices=TEACHERS,
        default=DEFAULT_BASELINE,
        metavar="TEACHER",
        help=f"the teacher the report's probability of improvement compares every other with, seed by seed "
        f"(default {DEFAULT_BASELINE}: uniform random tasks); left out when it is not among the teachers. "
        "A report setting only: changing it retrains nothing",
    )
    parser.add_argument(
        "--bootstrap-reps",
        type=bootstrap_reps,
        default=REPS,
        help=f"{REPS_HELP} for the run statistics: fewer for a quick look. A report setting only, as --baseline",
    )
    evaluation = parser.add_argument_group("final evaluation (hardest task)")
    evaluation.add_argument(
        "--eval-episodes", type=positive_int, default=100, help="episodes per final policy (default 100)"
    )
    evaluation.add_argument("--eval-seed", type=int, default=0, help="episode i is seeded eval-seed + i (default 0)")
    evaluation.add_argument("--eval-processes", type=positive_int, help="evaluation processes (default: one per CPU)")
    training = parser.add_argument_group("training, the same for every run")
    add_training_flags(training, defaults_given=True, level_families=True)
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
        "--config",
        type=config_path,
        metavar="FILE_OR_RECIPE",
        action=BakeoffConfigAction,
        help=f"{CONFIG_HELP}, for every run: its budget, its PPO values, its layout and its teacher's parameters (for "
        "that teacher); flags given override it",
    )
    add_override_flags(
        training,
        "for every run",
        teacher_param="a teacher parameter: KIND.NAME=VALUE for one teacher (e.g. currot.start=easiest), "
        "NAME=VALUE for every teacher compared,",
    )
    training.add_argument(
        "--ray-address", help="a running Ray cluster for the runs (default: each run starts a local one)"
    )


def has_scripted_controller(env_id: str) -> bool:
    """Whether the family has a hand-made controller to play beside the teachers (KUKA's)."""
    try:
        family_for(env_id).scripted_controller(env_id)
    except ValueError:
        return False
    return True


def run(args: argparse.Namespace) -> int:
    return run_command(
        "bakeoff", _bakeoff, args, "stopped; the same command resumes where it stopped", failures=(RunFailed,)
    )


def _bakeoff(args: argparse.Namespace) -> int:
    settings = {name: getattr(args, name) for name in TRAINING_FLAGS} | {"total_steps": args.total_steps}
    with teacher_probe() as probe:  # the service says which kinds, parameters and spaces it takes
        teachers = list(dict.fromkeys(args.teachers or kinds_for_family(probe, args.env, args.levels)))
        teacher_params = teacher_params_by_kind(args.teacher_params, teachers, probe.kinds)
        check_curricula(probe, teacher_params, args.env, args.levels)
    settings |= {"ppo": dict(args.ppo), "teacher_params": teacher_params}
    archive = archives_runs(args.out)
    settings = check_settings(args.out, settings, teachers)
    runs = plan_runs(args.out, teachers, args.seeds)

    @functools.cache
    def evaluate(run: Run) -> EvaluationResult:
        """Each run's final evaluation, computed (or read from its cache file) once per invocation; the
        run, now finished and evaluated, is then archived to what the report reads (``run_archive``)."""
        result = evaluate_run(run, args.eval_episodes, args.eval_seed, args.eval_processes, args.env)
        if archive:
            archive_run(run.directory)
        return result

    if not train_runs(runs, args.total_steps, settings, args.ray_address, lambda run: evaluate(run).summary()):
        return 130

    results = []
    for teacher in teachers:
        further = tuple(further_finished_runs(args.out, teacher, args.seeds, args.total_steps))
        for run in further:
            print(f"{run.name}: {evaluate(run).summary()}")
        teacher_runs = tuple(run for run in runs if run.teacher == teacher) + further
        evaluations = tuple(evaluate(run) for run in teacher_runs)
        results.append(TeacherResult(teacher, teacher_runs, evaluations, args.env))
    scripted = None
    if has_scripted_controller(args.env):
        scripted = scripted_evaluation(
            args.out / SCRIPTED_EVALUATION,
            args.env,
            args.eval_episodes,
            args.eval_seed,
            args.eval_processes,
            args.max_episode_steps,
        )
        print(f"scripted controller: {scripted.summary()}")
    write_reports(
        args.out, results, settings, args.eval_episodes, args.eval_seed, scripted, args.baseline, args.bootstrap_reps
    )
    for name in (RESULTS_MARKDOWN, RESULTS_JSON, LEARNING_CURVES, PERFORMANCE_PROFILE, PLACEMENT_PLOT):
        print(args.out / name)
    return 0
