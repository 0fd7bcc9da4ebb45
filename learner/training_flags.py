"""The flags that set how one run trains, defined once for ``train`` and ``bakeoff``: the same names,
types and help, with ``TrainConfig``'s defaults."""

from __future__ import annotations

import argparse

from common.kuka import ENV_IDS
from learner.arguments import positive_int
from learner.core.config import LOOPS, TrainConfig

DEFAULTS = TrainConfig()


def add_training_flags(group: argparse._ArgumentGroup, *, defaults_given: bool) -> None:
    """``--env``, ``--workers``, ``--envs-per-worker``, ``--rollout-length``, ``--max-episode-steps``,
    ``--checkpoint-every`` and ``--loop``. With ``defaults_given`` a flag left out takes its default (a
    bake-off's runs all train alike); without, it is None, so ``train --resume`` keeps a run's saved value."""

    whole_numbers = (
        ("--workers", DEFAULTS.workers, "rollout actors"),
        ("--envs-per-worker", DEFAULTS.envs_per_worker, "environments per actor"),
        ("--rollout-length", DEFAULTS.ppo.rollout_length, "steps per environment per iteration"),
        ("--max-episode-steps", DEFAULTS.max_episode_steps, "episode step limit"),
        ("--checkpoint-every", DEFAULTS.checkpoint_every, "iterations between checkpoints"),
    )
    group.add_argument(
        "--env",
        choices=ENV_IDS,
        default=DEFAULTS.env if defaults_given else None,
        help=f"task family: the environment and its task space, whose hardest task is evaluated "
        f"(default {DEFAULTS.env})",
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
