"""The level gamut: the tier follows the level number, every level can be solved by stepping the
environment as a policy would, and held-out levels are layouts that no training level holds, where
DoorKey's repeat."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest
from minigrid.core.actions import Actions
from minigrid.core.constants import DIR_TO_VEC
from minigrid.core.world_object import Door

from common.families import family_for
from common.families.base import held_out_seeds
from common.levels import GAMUT_ENV_ID
from common.levels.env import LevelEnv, make_level_env
from common.levels.gamut import GRID_SIZE, TIERS, GamutEnv, tier_of
from common.levels.layouts import level_layouts


def test_the_tier_cycles_with_the_level_number() -> None:
    assert [tier_of(level) for level in range(2 * len(TIERS))] == [*TIERS, *TIERS]
    env = make_level_env(GAMUT_ENV_ID)
    for level in (0, 3, 5, 1_000_002):
        env.reset(options={"task": {"level": level}})
        gamut = env.unwrapped
        assert isinstance(gamut, GamutEnv) and gamut.tier == tier_of(level)
        assert gamut.max_steps == 10 * gamut.tier.size**2 and gamut.grid.width == GRID_SIZE
    assert family_for(GAMUT_ENV_ID).policy_shape(GAMUT_ENV_ID).observation_dim == 147


def _walk(gamut: GamutEnv, wanted: set[tuple[int, int]], onto: bool) -> list[int]:
    """Turns and steps to reach a cell of ``wanted`` (``onto``) or to face one from beside it: a breadth-first
    search over positions and headings, through empty cells, open doors and the goal."""
    start = (int(gamut.agent_pos[0]), int(gamut.agent_pos[1]), int(gamut.agent_dir))
    paths: dict[tuple[int, int, int], list[int]] = {start: []}
    frontier = deque([start])
    while frontier:
        x, y, heading = frontier.popleft()
        dx, dy = DIR_TO_VEC[heading]
        ahead = (x + int(dx), y + int(dy))
        if (x, y) in wanted if onto else ahead in wanted:
            return paths[(x, y, heading)]
        cell = gamut.grid.get(*ahead)
        moves = [(Actions.left, (x, y, (heading - 1) % 4)), (Actions.right, (x, y, (heading + 1) % 4))]
        if cell is None or cell.type == "goal" or (isinstance(cell, Door) and cell.is_open):
            moves.append((Actions.forward, (*ahead, heading)))
        for action, state in moves:
            if state not in paths:
                paths[state] = [*paths[(x, y, heading)], int(action)]
                frontier.append(state)
    raise AssertionError("no way there")


def _cells(gamut: GamutEnv, kind: str) -> set[tuple[int, int]]:
    grid = gamut.grid
    return {(x, y) for x in range(grid.width) for y in range(grid.height) if (c := grid.get(x, y)) and c.type == kind}


def _solve(env: LevelEnv) -> bool:
    """Fetch the key, open the door, reach the goal, as far as the level has them; whether it succeeded."""
    gamut = env.unwrapped
    assert isinstance(gamut, GamutEnv)
    plan: list[tuple[str, int | None]] = []
    if gamut.tier.barrier == "locked":
        plan.append(("key", int(Actions.pickup)))
    if gamut.tier.barrier in ("door", "locked"):
        plan.append(("door", int(Actions.toggle)))
    plan.append(("goal", None))
    info: dict[str, object] = {}
    for kind, then in plan:
        actions = _walk(gamut, _cells(gamut, kind), onto=then is None)
        for action in [*actions, *([then] if then is not None else [])]:
            _, _, terminated, truncated, info = env.step(np.int64(action))
            if terminated or truncated:
                return bool(info["is_success"])
    return False


@pytest.mark.parametrize("tier", range(len(TIERS)))
def test_every_tier_s_levels_are_solved_by_walking_through(tier: int) -> None:
    env = make_level_env(GAMUT_ENV_ID)
    for level in range(tier, tier + 20 * len(TIERS), len(TIERS)):
        env.reset(options={"task": {"level": level}})
        assert _solve(env), f"level {level} ({TIERS[tier]})"


def test_held_out_levels_are_layouts_no_training_level_holds() -> None:
    training = level_layouts(GAMUT_ENV_ID, range(300))
    held_out = level_layouts(GAMUT_ENV_ID, held_out_seeds(60))
    assert len({layout.with_pose for layout in training}) == 300
    assert not {layout.with_pose for layout in held_out} & {layout.with_pose for layout in training}
    doorkey = level_layouts("MiniGrid-DoorKey-5x5-v0", range(60))
    assert len({layout.grid for layout in doorkey}) <= 6, "DoorKey-5x5 repeats a handful of grids"
    again = level_layouts(GAMUT_ENV_ID, [7, 7])
    assert again[0] == again[1] == training[7], "a level is one layout"
