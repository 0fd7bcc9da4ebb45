"""MiniGrid level families: their ids, task space and environment, whose level is the reset seed.

A level family's task is one integer parameter, ``level``: the environment resets with that number as
its seed, so a training set of N levels is the seeds 0 to N - 1, and held-out evaluation plays seeds from
``common.families.base.HELD_OUT_FIRST_SEED`` up, outside every training set (the family,
``common.families.minigrid``, says so). Importing this package needs neither minigrid nor pybullet;
``common.levels.env`` makes the environments (minigrid, the ``levels`` extra).
"""

from __future__ import annotations

from common.client.task_space import MAX_LEVELS, Parameter, TaskSpace

GAMUT_ENV_ID = "MiniGrid-Gamut-v0"
"""The level gamut (``common.levels.gamut``): rooms of graded difficulty, the tier from the level number."""

LEVEL_ENV_IDS = (
    "MiniGrid-DoorKey-5x5-v0",
    "MiniGrid-DoorKey-8x8-v0",
    "MiniGrid-MultiRoom-N4-S5-v1",
    "MiniGrid-KeyCorridorS3R2-v0",
    GAMUT_ENV_ID,
)
"""The MiniGrid environments ``train --env`` lists: each draws its whole layout (walls, doors, keys, goal)
from the reset seed, and pays a positive reward only for reaching its goal. DoorKey-5x5 learns in
minutes on two cores; MultiRoom and KeyCorridor need millions of steps. DoorKey's layouts are few (about
300 grids at 8x8), so its held-out seeds mostly replay training grids; the gamut's levels differ in
difficulty by design and its held-out levels are layouts of their own."""

DEFAULT_LEVELS = 1000
"""Training levels of a run unless it sets ``TrainConfig.levels``."""


def level_task_space(levels: int) -> TaskSpace:
    """One integer parameter, ``level``, from 0 to ``levels - 1``: the training set's reset seeds."""
    if not 1 <= levels <= MAX_LEVELS:
        raise ValueError(f"levels must be between 1 and {MAX_LEVELS:,} (the level kinds' cap), got {levels}")
    return TaskSpace([Parameter("level", 0, levels - 1, type="integer", doc="The environment's reset seed.")])


__all__ = ["DEFAULT_LEVELS", "GAMUT_ENV_ID", "LEVEL_ENV_IDS", "level_task_space"]
