"""A level's layout, hashed: its initial grid (MiniGrid's encoding of each cell's object, colour and state)
and the agent's start pose, so that held-out levels can be checked to be layouts no training level holds.

DoorKey-8x8 draws about 300 distinct grids over 20,000 seeds, so most of its "held-out" seeds replay a
training grid; ``bench/level_layouts.py`` counts, for any level family, how many distinct layouts a training
set and a held-out set hold and how many held-out layouts occur in training.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from dataclasses import dataclass

from minigrid.minigrid_env import MiniGridEnv

from common.levels.env import make_level_env


@dataclass(frozen=True)
class Layout:
    """One level's layout as two hashes: the grid alone, and the grid with the agent's start pose."""

    grid: str
    with_pose: str


def layout_of(env: MiniGridEnv) -> Layout:
    """The layout of ``env`` just after a reset (before any step moves the agent or opens a door)."""
    grid = env.grid.encode().tobytes()
    x, y = (int(value) for value in env.agent_pos)
    pose = bytes([x, y, int(env.agent_dir)])
    return Layout(hashlib.sha1(grid).hexdigest(), hashlib.sha1(grid + pose).hexdigest())


def level_layouts(env_id: str, levels: Iterable[int]) -> list[Layout]:
    """The layout of each level of ``env_id``, a level being the reset seed (as training tasks and held-out
    evaluations both reset the environment)."""
    env = make_level_env(env_id)
    try:
        layouts = []
        for level in levels:
            env.reset(seed=int(level))
            unwrapped = env.unwrapped
            assert isinstance(unwrapped, MiniGridEnv), "a level family's environment is a MiniGrid one"
            layouts.append(layout_of(unwrapped))
        return layouts
    finally:
        env.close()  # type: ignore[no-untyped-call]  # gymnasium's Env.close is unannotated
