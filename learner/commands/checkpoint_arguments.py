"""What ``evaluate`` and ``render`` read from their command line: a checkpoint (or a run directory's
policy) and a task of the environment it was trained on. Bad input is a ``UsageError``.
"""

from __future__ import annotations

import pickle
from pathlib import Path

from common.client.task_space import Task, TaskSpace
from common.kuka.task_space import KUKA_TASK_SPACE
from learner.commands.arguments import UsageError
from learner.core.checkpoint import Checkpoint, load_checkpoint
from learner.evaluation.selection import UnreadableRecord, run_policy

CHECKPOINT_HELP = (
    "a checkpoint file, or a run directory (its policy: the validated one where train chose one, else its latest "
    "checkpoint)"
)
TASK_HELP = (
    "'hardest' (the evaluation setting of the checkpoint's environment: for KukaGrasp-v0 the book's, on a level "
    "space held-out levels), 'easiest', or name=value overrides on the hardest task, e.g. 'jp2=1.0,rnd_obj_ang=0.5' "
    "(start with 'easiest,' to override the easiest one; on a level space 'level=5' plays that level)"
)


def parse_task(text: str, space: TaskSpace = KUKA_TASK_SPACE, evaluation: Task | None = None) -> Task:
    """A task of ``space`` from the command line: an anchor name, optionally followed by ``name=value`` overrides.
    'hardest' is ``evaluation`` where given (the family's evaluation task: none for held-out levels)."""
    items = [item.strip() for item in text.split(",") if item.strip()]
    if not items:
        raise ValueError(f"empty task; expected {TASK_HELP}")
    hardest = space.hardest() if evaluation is None else evaluation
    base = hardest
    if "=" not in items[0]:
        anchor = items.pop(0)
        if anchor not in ("hardest", "easiest"):
            raise ValueError(f"unknown task {anchor!r}; expected {TASK_HELP}")
        base = hardest if anchor == "hardest" else space.easiest()
    overrides: dict[str, float] = {}
    for item in items:
        name, separator, value = (part.strip() for part in item.partition("="))
        if not separator or not name:
            names = ", ".join(space.names)
            raise ValueError(f"bad task item {item!r}: expected name=value; names are {names}")
        if name in overrides:
            raise ValueError(f"task parameter {name!r} is given twice")
        integer = any(p.name == name and p.type == "integer" for p in space.parameters)
        try:
            overrides[name] = int(value) if integer else float(value)
        except ValueError:
            kind = "a whole number" if integer else "a number"
            raise ValueError(f"task parameter {name!r} must be {kind}, got {value!r}") from None
    task = {**base, **overrides}
    return space.validate(task) if task else task


def checkpoint_task(text: str, checkpoint: Checkpoint) -> Task:
    """``parse_task`` in the task space of the environment the checkpoint was trained on (a user's
    ``module:EnvId`` imported again); a bad task, or an environment that no longer loads, is a usage error."""
    config = checkpoint.config
    try:
        config.family.check(config.env)
    except ValueError as error:
        raise UsageError(f"{checkpoint.path} was trained on {config.env}: {error}") from None
    try:
        return parse_task(text, config.task_space(), config.evaluation_task())
    except ValueError as error:
        raise UsageError(f"--task: {error}") from None


def read_checkpoint(path: Path) -> Checkpoint:
    """A checkpoint file as given, or a run directory's policy: its validated policy where the run recorded one
    (``train --policy-choice validated``), else its latest checkpoint."""
    path = Path(path)
    if path.is_dir():
        try:
            policy = run_policy(path)
        except UnreadableRecord as error:
            raise UsageError(str(error)) from None
        if policy is None:
            raise UsageError(f"{path} is a directory without checkpoints (expected a run directory or a .pt file)")
        path = policy
    elif not path.is_file():
        raise UsageError(f"no checkpoint at {path}")
    try:
        return load_checkpoint(path)
    except (RuntimeError, pickle.UnpicklingError, KeyError, TypeError, ValueError) as error:
        raise UsageError(f"{path} is not a checkpoint this version can read ({error})") from None
