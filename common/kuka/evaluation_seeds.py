"""The in-run evaluation's seeds on a KUKA family: consecutive ones, or ``stratified`` ones whose blocks lie
as the final evaluation's do (``TrainConfig.eval_seeds``).

- ``consecutive``: 10,000, 10,001, ... (every run before issue 59). Its first 20 episodes put 10 blocks
  inside the arm's x clamp where the bake-off's final evaluation (seeds from 100,000) puts 38 of 100 and 206
  of 500, so a curve read off it over-stated hardest-point success.
- ``stratified`` (the default since issue 59; ``stratified_seeds``): as many episodes, drawn like the final
  evaluation's (the same task, placement rule and step limit, each one an ordinary seed), but picked once by a
  fixed rule so that how far their blocks lie beyond the clamp is spread as in the final evaluation's episodes:
  each placement band (``common.kuka.diagnostics``) holds its share of them to within one or two episodes,
  and half the blocks lie turned each way. It costs no more episodes than the old seeds, so an evaluation
  costs what it did (docs/results/bakeoff-hard.md says how much); more episodes (``--eval-episodes``) still
  lower the curve's noise, about 9 points at 20 episodes and 80% success.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

from common.kuka.task_space import task_space_for

EVALUATION_SEED_OFFSET = 10_000
"""Consecutive evaluation seeds are EVALUATION_SEED_OFFSET + 0, 1, 2, ... (as every family's,
``common.families.base``); stratified ones are picked from here up."""
CANDIDATES_PER_EPISODE = 50
"""A stratified set of N episodes is picked from the N x this seeds from ``EVALUATION_SEED_OFFSET``."""
FINAL_EVALUATION_SEED = 100_000
"""Where a bake-off's final evaluation's seeds start (``bakeoff --eval-seed``): candidates stay below it."""
MAX_STRATIFIED_EPISODES = (FINAL_EVALUATION_SEED - EVALUATION_SEED_OFFSET) // CANDIDATES_PER_EPISODE
"""The most episodes a stratified set may have: 1,800, whose candidates end at seed 99,999."""


def clockwise(block_yaw: float) -> bool:
    """Whether a block lies turned clockwise (seen from above): its yaw modulo a half turn, in [-pi/2, pi/2),
    below 0, as ``bench.success_by_turn`` counts it."""
    return (block_yaw + math.pi / 2) % math.pi - math.pi / 2 < 0


def candidate_placements(env_id: str, seeds: Sequence[int]) -> list[tuple[float, float]]:
    """Per seed, where the family's hardest task puts the block: (its x, its yaw), read right after the
    environment's reset with that seed, as an evaluation episode starts."""
    from common.kuka.env import make_kuka_env  # here: the environment module loads pybullet

    env = make_kuka_env(env_id)
    task = task_space_for(env_id).hardest()
    try:
        placements = []
        for seed in seeds:
            env.reset(seed=int(seed), options={"task": task})
            x, _, yaw = env.block_pose()
            placements.append((x, yaw))
        return placements
    finally:
        env.close()


@functools.cache
def stratified_seeds(env_id: str, episodes: int) -> tuple[int, ...]:
    """``episodes`` seeds of the family's hardest task whose blocks lie as the final evaluation's do.

    Why this rule. The final evaluation plays consecutive seeds from 100,000, so its placements are a plain
    random sample of the hardest task's; what decides a student's success there is mostly how far the block
    lies beyond the arm's x clamp (the placement bands) and which way it lies turned. A curve of N episodes
    drawn the same way differs from that sample by chance, by about sqrt(share / N) in each band's share (10
    of the old 20 in-run episodes lay inside the clamp against 41% of the final 500), and being fixed for the
    whole run, the difference biases every point of the curve alike. Picking the N seeds by quantiles of
    the placement instead fixes the bands' shares at those of the hardest task itself, which the final
    evaluation's share to within its own sampling noise, at no extra episodes: cheaper than the hundreds of
    episodes that plain sampling would need for the same match.

    The rule, deterministic and done once per run. The candidates are the N x ``CANDIDATES_PER_EPISODE``
    seeds from ``EVALUATION_SEED_OFFSET`` (below the final evaluation's 100,000; training seeds its
    environments with 32-bit draws of numpy's SeedSequence). They are sorted by how far their block lies
    beyond the clamp (``common.kuka.diagnostics.beyond_clamp``; seed breaks ties) and cut into N equal runs
    of consecutive candidates; from run i the candidate nearest its middle whose block lies clockwise (i
    even) or anticlockwise (i odd) is kept, the middle one if the run holds none so turned. So the kept
    blocks are the candidates' N quantiles of distance beyond the clamp, and each band keeps its share of
    the candidates to within about one episode at each of its edges, half the blocks turned each way.
    Returned from the nearest to the farthest, which the pool's round-robin shares out evenly over its
    workers.
    """
    from common.kuka.diagnostics import beyond_clamp  # here: the diagnostics module loads the environment's

    if not 1 <= episodes <= MAX_STRATIFIED_EPISODES:
        raise ValueError(f"a stratified evaluation takes 1 to {MAX_STRATIFIED_EPISODES:,} episodes, got {episodes}")
    candidates = range(EVALUATION_SEED_OFFSET, EVALUATION_SEED_OFFSET + episodes * CANDIDATES_PER_EPISODE)
    placed = candidate_placements(env_id, candidates)
    order = sorted(range(len(candidates)), key=lambda index: (beyond_clamp(placed[index][0]), candidates[index]))
    chosen = []
    for run in range(episodes):
        members = order[run * CANDIDATES_PER_EPISODE : (run + 1) * CANDIDATES_PER_EPISODE]
        middle = (len(members) - 1) / 2
        wanted = run % 2 == 0
        turned = [rank for rank, index in enumerate(members) if clockwise(placed[index][1]) == wanted]
        rank = min(turned, key=lambda each: (abs(each - middle), each)) if turned else int(middle)
        chosen.append(candidates[members[rank]])
    return tuple(chosen)
