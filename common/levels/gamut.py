"""The level gamut: MiniGrid rooms of designed, graded difficulty, the tier taken from the level number.

Level ``n`` is tier ``n % len(TIERS)`` (so any training set of consecutive levels holds every tier evenly),
its layout drawn from ``n`` as the reset seed. A tier is a room's size and what stands between the agent and
the goal: nothing, a wall with a gap, a closed door, or a locked door whose key lies on the agent's side (as
DoorKey). Every room also holds ``BLOCKS`` loose wall blocks (two or three), and the goal, the agent (position and
heading), the dividing wall, its opening and the key are all placed at random: every tier has tens of
thousands of layouts or more, so held-out levels (seeds from 1,000,000) are layouts no training set holds,
where DoorKey-8x8 has about 300 grids (``bench/level_layouts.py`` counts them). A layout is redrawn, from the
same generator, until the goal (and the key) can be reached. The grid is always ``GRID_SIZE`` cells a side,
walls beyond the room, so every level renders at one size; episodes last ``10 * size ** 2`` steps, as
DoorKey's, and pay MiniGrid's ``1 - 0.9 * steps / limit`` for reaching the goal.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Literal

import gymnasium
from minigrid.core.grid import Grid
from minigrid.core.mission import MissionSpace
from minigrid.core.world_object import Door, Goal, Key, Wall
from minigrid.minigrid_env import MiniGridEnv

from common.levels import GAMUT_ENV_ID

Barrier = Literal["none", "gap", "door", "locked"]


@dataclass(frozen=True)
class Tier:
    """One difficulty of the gamut: the room's side (walls included) and what divides it."""

    size: int
    barrier: Barrier


TIERS = (
    Tier(7, "none"),
    Tier(7, "gap"),
    Tier(7, "door"),
    Tier(6, "locked"),
    Tier(8, "locked"),
    Tier(10, "locked"),
    Tier(12, "locked"),
    Tier(14, "locked"),
)
"""Easiest first: an open room; a wall to pass through its gap; a door to open; DoorKey rooms from 6 to 14 cells a
side, where the key, the door and the goal lie ever further beyond the agent's 7 x 7 view. Uniform levels learn
the tiers up to DoorKey-8x8 within a few hundred thousand steps; the larger rooms are where a teacher can matter
(``docs/results/levels.md``)."""

GRID_SIZE = max(tier.size for tier in TIERS)
BLOCKS = (2, 3)
"""The fewest and the most loose wall blocks in a room: many layouts to tell apart, hardly any harder."""


def tier_of(level: int) -> Tier:
    """The tier of level ``level``."""
    return TIERS[level % len(TIERS)]


class GamutEnv(MiniGridEnv):
    """A MiniGrid environment whose reset seed is the level: its tier (``tier_of``) and its layout."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(
            mission_space=MissionSpace(mission_func=lambda: "get to the green goal square"),
            grid_size=GRID_SIZE,
            max_steps=10 * GRID_SIZE**2,
            **kwargs,
        )
        self.tier = TIERS[0]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Level ``seed``; without one, a level drawn from the environment's generator."""
        if seed is None:
            seed = int(self.np_random.integers(2**31))
        self.tier = tier_of(seed)
        self.max_steps = 10 * self.tier.size**2
        return super().reset(seed=seed, options=options)

    def _gen_grid(self, width: int, height: int) -> None:
        while not self._draw_layout(width, height):
            pass  # redrawn from the same generator: the level stays one layout

    def _draw_layout(self, width: int, height: int) -> bool:
        """One draw of the tier's layout; whether the agent can reach the goal and any key."""
        size, barrier = self.tier.size, self.tier.barrier
        self.grid = Grid(width, height)
        for x in range(width):
            for y in range(height):
                if x in (0, size - 1) or y in (0, size - 1) or x >= size or y >= size:
                    self.grid.set(x, y, Wall())
        near = far = (1, size - 2)  # the columns of the agent's side and of the goal's
        if barrier != "none":
            split = self._rand_int(2, size - 2)
            near, far = (1, split - 1), (split + 1, size - 2)
            self.grid.vert_wall(split, 1, size - 2)
            opening = self._rand_int(1, size - 1)
            self.grid.set(split, opening, None if barrier == "gap" else Door("yellow", is_locked=barrier == "locked"))
        targets = [self.place_obj(Goal(), *_box(far, size))]
        self.place_agent(*_box(near, size))  # type: ignore[no-untyped-call]  # minigrid leaves it unannotated
        if barrier == "locked":
            targets.append(self.place_obj(Key("yellow"), *_box(near, size)))
        for _ in range(self._rand_int(BLOCKS[0], BLOCKS[1] + 1)):
            self.place_obj(Wall(), *_box((1, size - 2), size))
        reachable = _reachable(self.grid, (int(self.agent_pos[0]), int(self.agent_pos[1])))
        return all((int(x), int(y)) in reachable for x, y in targets)


def _box(columns: tuple[int, int], size: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """The top-left cell and the size of the room's interior between ``columns`` (inclusive)."""
    return (columns[0], 1), (columns[1] - columns[0] + 1, size - 2)


def _reachable(grid: Grid, start: tuple[int, int]) -> set[tuple[int, int]]:
    """The cells the agent can walk to from ``start``, doors counted open (a locked one once its key is held)
    and a key's cell counted as reached (it is picked up from beside it)."""
    seen = {start}
    frontier = deque([start])
    while frontier:
        x, y = frontier.popleft()
        for nx, ny in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if (nx, ny) in seen:
                continue
            cell = grid.get(nx, ny)
            if cell is None or isinstance(cell, (Goal, Door, Key)):
                seen.add((nx, ny))
                if not isinstance(cell, Key):
                    frontier.append((nx, ny))
    return seen


gymnasium.register(GAMUT_ENV_ID, entry_point=GamutEnv)
