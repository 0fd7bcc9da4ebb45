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

    def default(value: object) -> object:
        return value if defaults_given else None

    group.add_argument(
        "--env",
        choices=ENV_IDS,
        default=default(DEFAULTS.env),
        help=f"task family: the environment and its task space, whose hardest task is evaluated "
        f"(default {DEFAULTS.env})",
    )
    group.add_argument(
        "--workers",
        type=positive_int,
        default=default(DEFAULTS.workers),
        help=f"rollout actors (default {DEFAULTS.workers})",
    )
    group.add_argument(
        "--envs-per-worker",
        type=positive_int,
        default=default(DEFAULTS.envs_per_worker),
        help=f"environments per actor (default {DEFAULTS.envs_per_worker})",
    )
    group.add_argument(
        "--rollout-length",
        type=positive_int,
        default=default(DEFAULTS.ppo.rollout_length),
        help=f"steps per environment per iteration (default {DEFAULTS.ppo.rollout_length})",
    )
    group.add_argument(
        "--max-episode-steps",
        type=positive_int,
        default=default(DEFAULTS.max_episode_steps),
        help=f"episode step limit (default {DEFAULTS.max_episode_steps})",
    )
    group.add_argument(
        "--checkpoint-every",
        type=positive_int,
        default=default(DEFAULTS.checkpoint_every),
        help=f"iterations between checkpoints (default {DEFAULTS.checkpoint_every})",
    )
    group.add_argument(
        "--loop",
        choices=LOOPS,
        default=default(DEFAULTS.loop),
        help="async: workers sample while the learner updates, one update behind; sync: strictly on-policy, "
        f"evaluations pause training (default {DEFAULTS.loop})",
    )
