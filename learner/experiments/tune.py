"""``kuka-curriculum tune``: a hyperparameter search with Ray Tune, every trial a curriculum on one teacher service.

Each trial is the project's own training loop (``Trainer``) run by a Tune function trainable,
against its own curriculum on the one service this command starts (or joins with
``--teacher-url``), so the service's dashboard shows every trial's curriculum side by side. A
trial claims its learner and its rollout actors as one placement group, so trials that do not fit
the machine wait for one another instead of sharing its cores. After each iteration a trial
reports the latest in-run evaluation at its family's hardest task (success rate and return) with
the steps it has trained; ASHA stops the trials that trail. A trial that raises is recorded as
failed and the others go on; ``--resume`` continues an interrupted tune, each unfinished trial
from its own last checkpoint.

Everything lands in ``--out``: the search's settings (``tune.json``), Tune's experiment
(``tune/``), each trial's run directory (``runs/<trial>``), and the results (``tune_report``). Once the
results are written, each trial that will not train again is archived (``run_archive``): its metrics
compressed, only its final checkpoint kept.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from pydantic import SecretStr

from learner.commands.arguments import UsageError, add_override_flags, positive_int, run_command
from learner.commands.training_flags import env_id
from learner.core.config import LISTED_ENV_IDS, TEACHERS, TrainConfig
from learner.core.json_file import write_json
from learner.experiments.tune_settings import (
    ASHA_REDUCTION,
    DEFAULTS,
    EXPERIMENT,
    MAX_TRIALS,
    METRICS,
    RUNS_DIR,
    SCHEDULERS,
    SETTINGS_FILE,
    TuneSettings,
)
from learner.experiments.tune_space import SearchSpace, SearchSpaceError, apply_settings
from learner.job import session
from learner.job.teacher_probe import TeacherProbe, teacher_probe


def add_arguments(parser: argparse.ArgumentParser) -> None:
    search = parser.add_argument_group("search")
    search.add_argument(
        "--env",
        type=env_id,
        metavar="ENV",
        help=f"the environment: {', '.join(LISTED_ENV_IDS)}, or module:EnvId (default {DEFAULTS.env})",
    )
    search.add_argument("--teacher", choices=TEACHERS, help=f"curriculum teacher (default {DEFAULTS.teacher})")
    search.add_argument(
        "--search-space",
        type=Path,
        help="JSON or YAML file: setting name -> {choice: [...]} | {grid: [...]} | {uniform: [lo, hi]} "
        "| {loguniform: [lo, hi]} | {randint: [lo, hi]}; names are PPOConfig fields, the teacher's parameters "
        "or max_episode_steps (see docs/tune.md)",
    )
    search.add_argument("--trials", type=positive_int, help="trials to sample, each once per grid point (default 8)")
    search.add_argument("--total-steps", type=positive_int, help="environment steps per trial (default 200_000)")
    search.add_argument("--scheduler", choices=SCHEDULERS, help="asha stops trailing trials early (default asha)")
    search.add_argument(
        "--grace-steps",
        type=positive_int,
        help="steps every trial trains before ASHA may stop it, its first rung (default a ninth of --total-steps)",
    )
    search.add_argument(
        "--metric", choices=tuple(METRICS), help="in-run evaluation on the hardest task to rank by (default success)"
    )
    search.add_argument("--max-concurrent", type=positive_int, help="most trials at once (default: as resources allow)")
    search.add_argument("--seed", type=int, help="seeds the sampling of trials and every trial's training (default 0)")
    trial = parser.add_argument_group("each trial")
    trial.add_argument("--workers", type=positive_int, help=f"rollout actors per trial (default {DEFAULTS.workers})")
    trial.add_argument(
        "--envs-per-worker", type=positive_int, help=f"environments per actor (default {DEFAULTS.envs_per_worker})"
    )
    trial.add_argument(
        "--eval-every", type=positive_int, help="iterations between in-run evaluations, the reported metric (default 1)"
    )
    trial.add_argument("--eval-episodes", type=positive_int, help="episodes per in-run evaluation (default 10)")
    trial.add_argument(
        "--checkpoint-every",
        type=positive_int,
        help="iterations between a trial's checkpoints, where --resume picks it up (default 1)",
    )
    add_override_flags(trial, "for every trial, unless searched")
    where = parser.add_argument_group("where")
    where.add_argument("--out", type=Path, default=Path("runs/tune"), help="tune directory (default runs/tune)")
    where.add_argument(
        "--resume",
        action="store_true",
        help="continue the interrupted tune in --out with its saved settings (flags given must match them)",
    )
    where.add_argument("--ray-address", help="a running Ray cluster, host:port (default: start a local one)")
    where.add_argument("--teacher-url", help="a running teacher service for every trial (default: start one)")
    where.add_argument("--public-url", help="the teacher's address in the printed dashboard link")


_SETTING_FLAGS = (
    "env",
    "teacher",
    "trials",
    "total_steps",
    "scheduler",
    "grace_steps",
    "metric",
    "max_concurrent",
    "seed",
    "workers",
    "envs_per_worker",
    "eval_every",
    "eval_episodes",
    "checkpoint_every",
)


def _settings(args: argparse.Namespace) -> TuneSettings:
    """New settings from the flags, or with ``--resume`` the saved ones (flags given must agree)."""
    given: dict[str, Any] = {name: getattr(args, name) for name in _SETTING_FLAGS if getattr(args, name) is not None}
    if args.ppo:
        given["ppo"] = dict(args.ppo)
    if args.teacher_params:
        given["teacher_params"] = dict(args.teacher_params)
    path = args.out / SETTINGS_FILE
    if args.resume:
        if not path.exists():
            raise UsageError(f"--resume: no tune in {args.out} (no {SETTINGS_FILE})")
        saved = TuneSettings(**json.loads(path.read_text(encoding="utf-8")))
        if args.search_space is not None:
            given["search_space"] = _read_space(args.search_space)
        differences = [
            f"{name} {getattr(saved, name)!r} saved, {value!r} given"
            for name, value in given.items()
            if getattr(saved, name) != value
        ]
        if differences:
            raise UsageError(f"--resume continues the tune in {args.out} as it started: {'; '.join(differences)}")
        return saved
    if args.search_space is None:
        raise UsageError("--search-space is needed to start a tune")
    if path.exists():
        raise UsageError(f"{args.out} already holds a tune; pass --resume to continue it or choose another --out")
    return TuneSettings(search_space=_read_space(args.search_space), **given)


def _read_space(path: Path) -> dict[str, Any]:
    from learner.experiments.tune_space import load_raw_search_space

    try:
        return load_raw_search_space(path)
    except SearchSpaceError as error:
        raise UsageError(str(error)) from None


def run(args: argparse.Namespace) -> int:
    return run_command("tune", _tune, args, "stopped at once; --resume continues it")


def _tune(args: argparse.Namespace) -> int:
    settings = _settings(args)
    try:
        base = settings.base_config()
    except ValueError as error:
        raise UsageError(str(error)) from None
    with teacher_probe() as probe:  # the service says what the tuned kind takes, before anything starts
        _check_teacher_params(probe, base)
        try:
            space = settings.space(probe.parameters(base.teacher, base.task_space()))
        except SearchSpaceError as error:
            raise UsageError(f"{args.search_space or args.out / SETTINGS_FILE}: {error}") from None
    if settings.trials * space.grid_size > MAX_TRIALS:
        raise UsageError(
            f"{settings.trials} trials × {space.grid_size} grid points is more than {MAX_TRIALS} trials; "
            "sample fewer or shorten the grids"
        )
    if settings.grace_steps is not None and settings.grace_steps > settings.total_steps:
        raise UsageError(f"--grace-steps {settings.grace_steps} is beyond --total-steps {settings.total_steps}")
    token = session.token_from_environment()
    if args.ray_address is not None:
        session.check_ray_reachable(args.ray_address)
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    if not args.resume:
        write_json(out / SETTINGS_FILE, asdict(settings))

    with contextlib.ExitStack() as stack:
        teacher_ready = session.launch_teacher(args.teacher_url, out, stack)
        # A local cluster counts at least one trial's CPUs, so one trial always fits and the others queue.
        session.connect_ray(args.ray_address, base.workers + 1, stack)
        teacher_url = teacher_ready()
        public_url = (args.public_url or os.environ.get(session.PUBLIC_URL_VARIABLE) or teacher_url).rstrip("/")
        from learner.experiments.run_archive import archive_run  # imports torch, which the flags do not need
        from learner.experiments.tune_report import (
            write_reports,  # imports Ray, so after connect_ray has chosen its auth mode
        )

        print(f"tune directory: {out}")
        print(f"dashboard:      {public_url}/  (every trial's curriculum)")
        setup = TrialSetup(base, teacher_url, out / RUNS_DIR, out.name, token)
        started = time.perf_counter()
        _fit(settings, space, setup, out, args.resume)
        elapsed = time.perf_counter() - started
        report = write_reports(out, settings, space, elapsed)  # while Ray is up: Tune reads trial errors through it
    for run_dir in report.settled_runs:
        if run_dir.is_dir():  # a trial that failed before its first iteration has none
            archive_run(run_dir)
    print(report.summary)
    if report.unfinished:
        print(f"{report.unfinished} trial(s) unfinished; the same command with --resume continues them")
        return 130
    return 0 if report.best is not None else 1


def _check_teacher_params(probe: TeacherProbe, base: TrainConfig) -> None:
    """The curriculum every trial starts from (the family's teacher parameters and ``--teacher-param``, over
    its task space), registered with ``probe``'s throwaway service: what the service refuses is refused here,
    with its reason, rather than in every trial."""
    refusal = probe.run_refusal(base)
    if refusal is not None:
        raise UsageError(refusal.line(base.teacher, base.env))


@dataclass(frozen=True)
class TrialSetup:
    """What every trial shares: handed to the trainable through the object store, not its config."""

    base: TrainConfig
    teacher_url: str
    runs_dir: Path
    prefix: str
    token: SecretStr | None


def train_trial(sampled: dict[str, Any], setup: TrialSetup) -> None:
    """One trial: its own curriculum and run directory, trained by the project's loop, reporting as it goes.

    A trial started again (``--resume``) continues from its run's latest checkpoint."""
    from ray import tune

    from learner.core.checkpoint import latest_checkpoint, load_checkpoint
    from learner.core.trainer import IterationReport, Trainer

    trial_id = tune.get_context().get_trial_id()
    config = apply_settings(setup.base, sampled)
    run_dir = setup.runs_dir / trial_id
    name = session.curriculum_name(Path(f"{setup.prefix}-{trial_id}"))
    session.register_curriculum(setup.teacher_url, name, config, setup.token)
    path = latest_checkpoint(run_dir)
    checkpoint = load_checkpoint(path) if path is not None else None
    trainer = Trainer(
        config,
        run_dir,
        setup.teacher_url,
        name,
        teacher_token=setup.token,
        resume_from=checkpoint,
        actor_name_prefix=name,
    )
    evaluations = EvaluationLog(run_dir)

    def on_iteration(report: IterationReport) -> None:
        for result in evaluations.new_results(report.recent_success_rate, report.recent_reward):
            tune.report(result)

    trainer.run(on_iteration)


class EvaluationLog:
    """Follows a run's ``metrics.jsonl``: each record written once its in-run evaluation is in (the
    trainer holds it until then) becomes one Tune result, with the latest evaluation carried over
    records that have none. Records before the first evaluation are not reported."""

    def __init__(self, run_dir: Path) -> None:
        from learner.core.metrics import METRICS_FILE

        self.path = Path(run_dir) / METRICS_FILE
        self.offset = self.path.stat().st_size if self.path.exists() else 0
        self.latest: dict[str, float] | None = None

    def new_results(self, train_success: float, train_return: float) -> list[dict[str, float]]:
        if not self.path.exists():
            return []
        with self.path.open("rb") as file:
            file.seek(self.offset)
            data = file.read()
        complete = data[: data.rfind(b"\n") + 1]
        self.offset += len(complete)
        results = []
        for line in complete.decode("utf-8").splitlines():
            record = json.loads(line)
            if record.get(METRICS["success"]) is not None:
                self.latest = {name: float(record[key]) for name, key in METRICS.items()}
                self.latest["eval_steps"] = float(record["step"])
            if self.latest is not None:
                results.append(
                    {
                        "steps": float(record["step"]),
                        **self.latest,
                        "train_success": train_success,
                        "train_return": train_return,
                    }
                )
        return results


def _fit(settings: TuneSettings, space: SearchSpace, setup: TrialSetup, out: Path, resume: bool) -> None:
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search import BasicVariantGenerator

    from learner.experiments.tune_report import TuneProgress

    # The first bundle runs the trainable (the learner); the rollout actors it starts take the others.
    bundles: list[dict[str, int | float]] = [{"CPU": 1} for _ in range(1 + setup.base.workers)]
    trainable = tune.with_resources(tune.with_parameters(train_trial, setup=setup), tune.PlacementGroupFactory(bundles))
    path = str(out / EXPERIMENT)
    if resume and tune.Tuner.can_restore(path):
        tuner = tune.Tuner.restore(path, trainable, resume_unfinished=True, resume_errored=False)
    else:
        scheduler = None
        if settings.scheduler == "asha":
            scheduler = ASHAScheduler(
                time_attr="steps",
                max_t=settings.total_steps,
                grace_period=settings.grace_steps or max(1, settings.total_steps // ASHA_REDUCTION**2),
                reduction_factor=ASHA_REDUCTION,
            )
        tuner = tune.Tuner(
            trainable,
            param_space=space.param_space(),
            tune_config=tune.TuneConfig(
                metric=settings.metric,
                mode="max",
                num_samples=settings.trials,
                max_concurrent_trials=settings.max_concurrent,
                scheduler=scheduler,
                search_alg=BasicVariantGenerator(random_state=settings.seed),
            ),
            run_config=tune.RunConfig(
                name=EXPERIMENT,
                storage_path=str(out),
                failure_config=tune.FailureConfig(max_failures=0, fail_fast=False),
                verbose=0,
                callbacks=[TuneProgress(settings.metric, settings.trials * space.grid_size, settings.total_steps)],
            ),
        )
    tuner.fit()
