"""What ``evaluate`` and ``render`` read from their command line: a checkpoint (or a run directory's
latest) and a task of the environment it was trained on. Bad input is a ``UsageError``.
"""

from __future__ import annotations

import pickle
from pathlib import Path

from common.client.task_space import Task, TaskSpace
from common.kuka.task_space import KUKA_TASK_SPACE, task_space_for
from common.levels import is_level_env
from learner.arguments import UsageError
from learner.core.checkpoint import Checkpoint, latest_checkpoint, load_checkpoint

TASK_HELP = (
    "'hardest' (the evaluation setting of the checkpoint's environment; for KukaGrasp-v0 the book's), 'easiest', "
    "or name=value overrides on the hardest task, e.g. 'jp2=1.0,rnd_obj_ang=0.5' (start with 'easiest,' to "
    "override the easiest one)"
)


def parse_task(text: str, space: TaskSpace = KUKA_TASK_SPACE) -> Task:
    """A task of ``space`` from the command line: an anchor name, optionally followed by ``name=value`` overrides."""
    items = [item.strip() for item in text.split(",") if item.strip()]
    if not items:
        raise ValueError(f"empty task; expected {TASK_HELP}")
    base = space.hardest()
    if "=" not in items[0]:
        anchor = items.pop(0)
        if anchor not in ("hardest", "easiest"):
            raise ValueError(f"unknown task {anchor!r}; expected {TASK_HELP}")
        base = space.hardest() if anchor == "hardest" else space.easiest()
    overrides: dict[str, float] = {}
    for item in items:
        name, separator, value = (part.strip() for part in item.partition("="))
        if not separator or not name:
            names = ", ".join(space.names)
            raise ValueError(f"bad task item {item!r}: expected name=value; names are {names}")
        if name in overrides:
            raise ValueError(f"task parameter {name!r} is given twice")
        try:
            overrides[name] = float(value)
        except ValueError:
            raise ValueError(f"task parameter {name!r} must be a number, got {value!r}") from None
    return space.validate({**base, **overrides})


def checkpoint_task(text: str, checkpoint: Checkpoint) -> Task:
    """``parse_task`` in the task space of the environment the checkpoint was trained on; a bad task,
    or a checkpoint of a level family (which ``evaluate`` and ``render`` do not play), is a usage error."""
    if is_level_env(checkpoint.config.env):
        raise UsageError(
            f"{checkpoint.path} was trained on the level family {checkpoint.config.env}; evaluate and render play "
            "the KUKA families (its held-out success is eval/success_rate in the run's metrics.jsonl)"
        )
    try:
        return parse_task(text, task_space_for(checkpoint.config.env))
    except ValueError as error:
        raise UsageError(f"--task: {error}") from None


def read_checkpoint(path: Path) -> Checkpoint:
    """A checkpoint file as given, or the latest checkpoint of a run directory."""
    path = Path(path)
    if path.is_dir():
        latest = latest_checkpoint(path)
        if latest is None:
            raise UsageError(f"{path} is a directory without checkpoints (expected a run directory or a .pt file)")
        path = latest
    elif not path.is_file():
        raise UsageError(f"no checkpoint at {path}")
    try:
        return load_checkpoint(path)
    except (RuntimeError, pickle.UnpicklingError, KeyError, TypeError, ValueError) as error:
        raise UsageError(f"{path} is not a checkpoint this version can read ({error})") from None
