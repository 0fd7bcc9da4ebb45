"""The flags that set how one run trains, defined once for ``train`` and ``bakeoff``: the same names,
types and help, with ``TrainConfig``'s defaults."""

from __future__ import annotations

import argparse

from common.kuka import ENV_IDS
from common.levels import LEVEL_ENV_IDS, MAX_LEVELS
from learner.arguments import positive_int
from learner.core.config import LOOPS, TRAIN_ENV_IDS, TrainConfig

DEFAULTS = TrainConfig()


def add_training_flags(group: argparse._ArgumentGroup, *, defaults_given: bool, level_families: bool = False) -> None:
    """``--env``, ``--workers``, ``--envs-per-worker``, ``--rollout-length``, ``--max-episode-steps``,
    ``--checkpoint-every`` and ``--loop``. With ``defaults_given`` a flag left out takes its default (a
    bake-off's runs all train alike); without, it is None, so ``train --resume`` keeps a run's saved value.
    ``level_families``: ``--env`` also takes the MiniGrid level families, and ``--levels`` sets their
    training set (``train``; a bake-off evaluates the KUKA families' hardest task)."""

    whole_numbers = (
        ("--workers", DEFAULTS.workers, "rollout actors"),
        ("--envs-per-worker", DEFAULTS.envs_per_worker, "environments per actor"),
        ("--rollout-length", DEFAULTS.ppo.rollout_length, "steps per environment per iteration"),
        ("--max-episode-steps", DEFAULTS.max_episode_steps, "episode step limit"),
        ("--checkpoint-every", DEFAULTS.checkpoint_every, "iterations between checkpoints"),
    )
    group.add_argument(
        "--env",
        choices=TRAIN_ENV_IDS if level_families else ENV_IDS,
        default=DEFAULTS.env if defaults_given else None,
        help=f"task family: the environment and its task space, whose hardest task is evaluated "
        f"(default {DEFAULTS.env})"
        + (
            f"; a MiniGrid level family ({', '.join(LEVEL_ENV_IDS)}) takes its tasks as levels, the reset seeds "
            "0 to --levels - 1, and is evaluated on held-out seeds from 1,000,000"
            if level_families
            else ""
        ),
    )
    if level_families:
        group.add_argument(
            "--levels",
            type=positive_int,
            default=DEFAULTS.levels if defaults_given else None,
            help=f"a level family's training levels, at most {MAX_LEVELS:,} (default {DEFAULTS.levels:,})",
        )
    for flag, default, what in whole_numbers:
        group.add_argument(
            flag, type=positive_int, default=default if defaults_given else None, help=f"{what} (default {default})"
        )
    group.add_argument(
        "--loop",
        choices=LOOPS,
        default=DEFAULTS.loop if defaults_given else None,
        help="async: workers sample while the learner updates, one update behind; sync: strictly on-policy, "
        f"evaluations pause training (default {DEFAULTS.loop})",
    )
