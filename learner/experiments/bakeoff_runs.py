"""The bake-off's runs on disk: where each lives, training it to the budget, its final evaluation.

Each teacher x seed is an ordinary ``kuka-curriculum train`` run in ``DIR/runs/<teacher>-seed<k>``,
started as a child process: it brings its own teacher service and Ray connection, a crash stays
inside it, and its log goes to the run directory. Everything here can be resumed: a run whose
checkpoint reached the budget is skipped, a run with an earlier checkpoint continues from it with
``--resume`` (its raw files decompressed first when an earlier, smaller budget archived it), and each
final evaluation is cached next to its checkpoint. Ctrl-C is left to the
training child (it checkpoints and stops); running the same command again carries on.
"""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from common.kuka import ENV_ID
from common.levels import DEFAULT_LEVELS
from learner.commands.arguments import UsageError
from learner.core.checkpoint import latest_checkpoint, load_checkpoint
from learner.core.config import TEACHERS, TrainConfig
from learner.core.json_file import write_json
from learner.evaluation.checkpoint_evaluation import EvaluationResult, evaluate_checkpoint
from learner.evaluation.selection import run_policy
from learner.experiments.run_archive import (
    EVALUATION_FILE,
    TRAIN_LOG,
    compressed,
    exists,
    metrics_records,
    read_json,
    restore_run,
)
from learner.job.teacher_probe import TeacherProbe

RUNS_DIR = "runs"
SETTINGS_FILE = "bakeoff.json"
ARCHIVE_MARKER = "ARCHIVED_RUNS"
POLL_S = 1.0

TRAINING_FLAGS = {
    "env": "--env",
    "levels": "--levels",
    "workers": "--workers",
    "envs_per_worker": "--envs-per-worker",
    "rollout_length": "--rollout-length",
    "max_episode_steps": "--max-episode-steps",
    "checkpoint_every": "--checkpoint-every",
    "curve_every": "--eval-every",
    "curve_episodes": "--eval-episodes",
    "loop": "--loop",
    "policy_choice": "--policy-choice",
}
"""Bake-off options handed to every ``train`` run unchanged (its flag there): what makes the comparison fair."""
ADDED_SETTINGS = {
    "loop": "sync",
    "teacher_params": {},
    "ppo": {},
    "env": ENV_ID,
    "levels": DEFAULT_LEVELS,
    "policy_choice": "final",
}
"""Settings newer than some stored bake-offs, with the value their runs were trained with."""


class RunFailed(Exception):
    """A training child exited with an error."""


@dataclass(frozen=True)
class Run:
    teacher: str
    seed: int
    directory: Path

    @classmethod
    def in_bakeoff(cls, out: Path, teacher: str, seed: int) -> Run:
        """The run of ``teacher`` and ``seed`` in the bake-off directory ``out``."""
        return cls(teacher, seed, Path(out) / RUNS_DIR / f"{teacher}-seed{seed}")

    @classmethod
    def of_directory(cls, directory: Path) -> Run | None:
        """The run a bake-off keeps in ``directory``, read from its ``<teacher>-seed<k>`` name; None for
        a directory not named so."""
        match = re.fullmatch(r"(.+)-seed(\d+)", directory.name)
        return cls(match.group(1), int(match.group(2)), directory) if match else None

    @property
    def name(self) -> str:
        return self.directory.name

    def steps_done(self) -> int:
        """Steps of the budget spent by the run's latest checkpoint, counted as its trainer counts them
        (``Counters.budget_spent``: every step played, or for a budget of trained steps, played less
        score-only), so a run the trainer calls finished is never resumed; 0 before the first checkpoint."""
        path = latest_checkpoint(self.directory)
        if path is None:
            return 0
        return load_checkpoint(path).budget_spent


def plan_runs(out: Path, teachers: Sequence[str], seeds: int) -> list[Run]:
    return [Run.in_bakeoff(out, teacher, seed) for teacher in teachers for seed in range(seeds)]


def teacher_params_by_kind(
    pairs: Sequence[tuple[str, Any]], teachers: Sequence[str], kinds: Collection[str]
) -> dict[str, dict[str, Any]]:
    """``--teacher-param`` pairs as each teacher's parameters: ``KIND.NAME`` sets one teacher's (and
    is left out when that kind is not among ``teachers``, so one script can name every teacher's
    parameters and run a few teachers), a plain ``NAME`` every teacher's. A ``KIND`` outside ``kinds``,
    the service's (``TeacherProbe.kinds``), is refused; ``check_curricula`` checks the values."""
    params: dict[str, dict[str, Any]] = {teacher: {} for teacher in teachers}
    for target, value in pairs:
        kind, dot, name = target.rpartition(".")
        if dot and kind not in kinds:
            raise UsageError(f"--teacher-param {target}: no teacher kind {kind!r}; known: {', '.join(kinds)}")
        for teacher in ([kind] if kind in params else []) if dot else teachers:
            params[teacher][name] = value
    return params


def kinds_for_family(probe: TeacherProbe, env: str, levels: int) -> list[str]:
    """The kinds the service accepts over the family's task space with the family's parameters: a bake-off's
    default teachers (KUKA's box refuses the level kinds; a level space refuses the kinds that need a hardest
    or easiest point)."""
    kinds = (kind for kind in TEACHERS if kind in probe.kinds)
    return [kind for kind in kinds if probe.run_refusal(TrainConfig(teacher=kind, env=env, levels=levels)) is None]


def check_curricula(probe: TeacherProbe, teacher_params: Mapping[str, dict[str, Any]], env: str, levels: int) -> None:
    """Register each teacher's curriculum as its runs will (its parameters on top of the family's, over the
    family's task space) with ``probe``, a throwaway service: a parameter, or a kind that does not take the
    space, that the service refuses stops the bake-off before its first run rather than in one of them,
    with the service's reason."""
    for teacher, values in teacher_params.items():
        try:
            config = TrainConfig(teacher=teacher, env=env, levels=levels, teacher_overrides=values)
        except ValueError as error:
            raise UsageError(str(error)) from None
        refusal = probe.run_refusal(config)
        if refusal is not None:
            raise UsageError(refusal.line(teacher, env))


def further_finished_runs(out: Path, teacher: str, seeds: int, total_steps: int) -> list[Run]:
    """The teacher's runs in DIR beyond the first ``seeds`` (seeds ``seeds``, ``seeds + 1``, ... up
    to the first missing one) that reached ``total_steps``: an earlier invocation's extra seeds,
    which the report counts too, so a teacher rerun with more seeds keeps them in the table."""
    runs, seed = [], seeds
    while (run := Run.in_bakeoff(out, teacher, seed)).directory.is_dir():
        if run.steps_done() >= total_steps:
            runs.append(run)
        seed += 1
    return runs


def archives_runs(out: Path) -> bool:
    """Whether this bake-off archives its finished runs (``run_archive``): a new directory does, and is
    marked so for its later invocations; one started before archiving existed (the committed v1
    bake-offs) keeps its runs as they are, so rerunning its report rewrites none of them."""
    marker = Path(out) / ARCHIVE_MARKER
    if not (Path(out) / SETTINGS_FILE).exists():
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text(
            "Finished runs here are archived: for git evaluation.json.xz, metrics.jsonl.xz and the evaluated "
            "checkpoint alone; the teacher database and logs xz-compressed, on disk only (git-ignored).\n",
            encoding="utf-8",
        )
    return marker.exists()


def check_settings(out: Path, settings: dict[str, Any], teachers: Sequence[str]) -> dict[str, Any]:
    """Runs in one directory must share their hyperparameters and each teacher its parameters; only
    the step budget may grow. Returns the settings to report: these, with the parameters of teachers
    stored by earlier invocations.

    The settings of the first invocation are stored in DIR, and a later invocation that differs is
    refused instead of silently comparing runs trained differently. A teacher that no earlier
    invocation ran may join with its own parameters.
    """
    path = Path(out) / SETTINGS_FILE
    if path.exists():
        stored = ADDED_SETTINGS | json.loads(path.read_text(encoding="utf-8"))
        differences = [
            f"{name}: {stored.get(name)!r} before, {value!r} now"
            for name, value in settings.items()
            if name not in ("total_steps", "teacher_params") and stored.get(name) != value
        ]
        stored_params = stored["teacher_params"]
        differences += [
            f"{teacher} parameters: {stored_params[teacher]!r} before, {settings['teacher_params'][teacher]!r} now"
            for teacher in teachers
            if teacher in stored_params and stored_params[teacher] != settings["teacher_params"][teacher]
        ]
        settings = settings | {"teacher_params": stored_params | settings["teacher_params"]}
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
    return settings


def train_command(
    run: Run, total_steps: int, settings: dict[str, Any], resume: bool, ray_address: str | None
) -> list[str]:
    command = [
        sys.executable,
        "-m",
        "kuka_curriculum",
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
        command += [flag, str(settings.get(name, ADDED_SETTINGS.get(name)))]  # settings stored before it: its value
    for key, value in settings["ppo"].items():
        command += ["--ppo", f"{key}={json.dumps(value)}"]
    for key, value in settings["teacher_params"].get(run.teacher, {}).items():
        command += ["--teacher-param", f"{key}={json.dumps(value)}"]
    if ray_address is not None:
        command += ["--ray-address", ray_address]
    return command + (["--resume"] if resume else [])


def _clear_unfinished_start(run: Run) -> None:
    """A run that stopped before its first checkpoint restarts from nothing; keep only its log."""
    if run.directory.is_dir():
        for entry in run.directory.iterdir():
            if entry.name != TRAIN_LOG:
                shutil.rmtree(entry) if entry.is_dir() else entry.unlink()


def _logged_steps(run: Run) -> int:
    records = metrics_records(run.directory)
    return int(records[-1]["step"]) if records else 0


def learning_curve(run: Run, metric: str = "eval/return") -> dict[int, float]:
    """A hardest-task evaluation metric by environment step, from the run's metrics log.

    An interrupted run repeats the iterations after its last checkpoint, so a step logged twice
    keeps its latest record.
    """
    records = metrics_records(run.directory)
    return {int(record["step"]): float(record[metric]) for record in records if record.get(metric) is not None}


def curve_seeds(run: Run) -> str | None:
    """Which seeds the run's in-run evaluations played, as its latest checkpoint's config says
    (``TrainConfig.eval_seeds``): ``stratified``, or ``consecutive`` for a run started before issue 59,
    whose curve's blocks lay nearer the arm than the final evaluation's; None before its first checkpoint."""
    path = latest_checkpoint(run.directory)
    return load_checkpoint(path).config.eval_seeds if path is not None else None


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


def train_runs(
    runs: Sequence[Run],
    total_steps: int,
    settings: dict[str, Any],
    ray_address: str | None,
    on_finished: Callable[[Run], str],
) -> bool:
    """Bring every run to ``total_steps``, one after the other: finished runs are skipped, started ones
    resumed from their checkpoint. False when interrupted (Ctrl-C); the same call later carries on.

    ``on_finished`` sees each run as soon as it reaches the budget (the final evaluation, which
    then lands in the run's directory hours before the bake-off ends) and its line is written
    under the progress bar.
    """
    done = {run.name: run.steps_done() for run in runs}

    def counted(run: Run) -> int:
        return min(done[run.name], total_steps)

    # Steps trained in earlier sessions start the bar, so its rate and ETA count this session's steps only.
    total = len(runs) * total_steps
    already = sum(counted(run) for run in runs)
    with tqdm(
        total=total, initial=already, unit="step", unit_scale=True, desc="bake-off", dynamic_ncols=True
    ) as progress:
        for run in runs:
            if done[run.name] >= total_steps:
                progress.write(f"{run.name}: finished at {done[run.name]:_} steps, skipped")
                progress.write(f"{run.name}: {on_finished(run)}")
                continue
            resume = done[run.name] > 0
            if resume:
                restore_run(run.directory)  # which leaves the evaluation raw
                (run.directory / EVALUATION_FILE).unlink(missing_ok=True)
            else:
                _clear_unfinished_start(run)
            progress.write(
                f"{run.name}: {'resuming at ' + format(done[run.name], '_') if resume else 'training'} "
                f"(log: {run.directory / TRAIN_LOG})"
            )
            command = train_command(run, total_steps, settings, resume, ray_address)
            steps_of_other_runs = sum(counted(other) for other in runs if other is not run)
            finished = train_run(run, command, progress, steps_of_other_runs) and run.steps_done() >= total_steps
            if not finished:
                progress.write("interrupted; run the same command again to resume")
                return False
            done[run.name] = run.steps_done()
            progress.write(f"{run.name}: {on_finished(run)}")
    return True


def evaluate_run(run: Run, episodes: int, seed: int, processes: int | None, env_id: str = ENV_ID) -> EvaluationResult:
    """The run's policy (its final checkpoint, or the validated one it chose) on its environment's evaluation task
    (the hardest, or held-out levels), cached with the checkpoint it came from."""
    checkpoint = run_policy(run.directory)
    assert checkpoint is not None, f"{run.name} finished training, so it has written a checkpoint"
    cache = run.directory / EVALUATION_FILE
    if exists(cache):  # raw, or compressed once the run was archived
        cached = read_json(cache)
        if (
            cached["checkpoint"] == checkpoint.name
            and cached["episodes"] == episodes
            and cached["seed"] == seed
            and cached.get("env", ENV_ID) == env_id
        ):
            return EvaluationResult.from_dict(cached)
    trained = load_checkpoint(checkpoint)
    result = evaluate_checkpoint(trained, trained.config.evaluation_task(), episodes, seed, processes)
    write_json(cache, {"checkpoint": checkpoint.name, **result.to_dict()})
    compressed(cache).unlink(missing_ok=True)  # an archived run's earlier evaluation, now superseded
    return result
