"""The flags that set how one run trains, defined once for ``train`` and ``bakeoff``: the same names,
types and help, with ``TrainConfig``'s defaults."""

from __future__ import annotations

import argparse

from common.client.task_space import MAX_LEVELS
from common.families import family_for
from common.kuka import ENV_IDS
from learner.commands.arguments import positive_int
from learner.core.config import LISTED_ENV_IDS, LOOPS, POLICY_CHOICES, TrainConfig

DEFAULTS = TrainConfig()


def env_id(text: str) -> str:
    """An ``--env`` some family owns (a listed id, or ``module:EnvId``); whether a user's module imports and
    declares a task space is checked once the run's settings are known."""
    try:
        family_for(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return text


def add_training_flags(group: argparse._ArgumentGroup, *, defaults_given: bool, level_families: bool = False) -> None:
    """``--env``, ``--workers``, ``--envs-per-worker``, ``--rollout-length``, ``--max-episode-steps``,
    ``--checkpoint-every``, ``--loop`` and ``--policy-choice``. With ``defaults_given`` a flag left out takes its
    default (a bake-off's runs all train alike); without, it is None, so ``train --resume`` keeps a run's saved
    value.
    ``level_families``: ``--env`` also takes the MiniGrid level families and any ``module:EnvId``, and
    ``--levels`` sets a MiniGrid family's training set (``train``; a bake-off plays the KUKA families)."""

    whole_numbers = (
        ("--workers", DEFAULTS.workers, "rollout actors"),
        ("--envs-per-worker", DEFAULTS.envs_per_worker, "environments per actor"),
        ("--rollout-length", DEFAULTS.ppo.rollout_length, "steps per environment per iteration"),
        ("--max-episode-steps", DEFAULTS.max_episode_steps, "episode step limit"),
        ("--checkpoint-every", DEFAULTS.checkpoint_every, "iterations between checkpoints"),
    )
    group.add_argument(
        "--env",
        **({"type": env_id, "metavar": "ENV"} if level_families else {"choices": ENV_IDS}),
        default=DEFAULTS.env if defaults_given else None,
        help=f"the environment, whose task space the teacher draws from and whose hardest task (or held-out "
        f"levels) is evaluated: {', '.join(LISTED_ENV_IDS if level_families else ENV_IDS)}"
        + (
            ", or any gymnasium environment with a task space as module:EnvId (docs/own-environment.md); a "
            "MiniGrid level family takes its tasks as levels, the reset seeds 0 to --levels - 1"
            if level_families
            else ""
        )
        + f" (default {DEFAULTS.env})",
    )
    if level_families:
        group.add_argument(
            "--levels",
            type=positive_int,
            default=DEFAULTS.levels if defaults_given else None,
            help=f"a MiniGrid level family's training levels, at most {MAX_LEVELS:,} (default {DEFAULTS.levels:,})",
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
    group.add_argument(
        "--policy-choice",
        choices=POLICY_CHOICES,
        default=DEFAULTS.policy_choice if defaults_given else None,
        help="the run's policy, which evaluate, render and a bake-off's evaluation play: its last checkpoint, or "
        "'validated', the best of its second half's checkpoints on 200 validation episodes, chosen when it "
        f"finishes (default {DEFAULTS.policy_choice})",
    )
