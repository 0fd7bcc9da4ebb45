"""The task families the trainer teaches, one registry: ``family_for(env_id)`` answers everything the
trainer, its workers and its evaluations need to know of an environment (``common.families.base``).

Adding a family is one module and its line in ``FAMILIES``. An id with a colon is any gymnasium environment
with a task space (``module:EnvId``, ``common.families.gymnasium_env``).
"""

from __future__ import annotations

from common.families.base import TaskFamily, UnusableEnvironment
from common.families.gymnasium_env import GymnasiumFamily
from common.families.kuka import KukaFamily
from common.families.minigrid import MiniGridFamily

FAMILIES: tuple[TaskFamily, ...] = (
    KukaFamily(),
    MiniGridFamily(),
    GymnasiumFamily(),
)
"""Every family, in the order ``train --env``'s help lists their environments."""


def family_for(env_id: str) -> TaskFamily:
    """The family of ``env_id``, or an ``UnusableEnvironment`` that lists the ids there are."""
    for family in FAMILIES:
        if family.owns(env_id):
            return family
    raise UnusableEnvironment(
        f"unknown environment {env_id!r}; expected one of {', '.join(listed_env_ids())}, or any gymnasium "
        "environment with a task space as module:EnvId"
    )


def listed_env_ids() -> tuple[str, ...]:
    """The ids the families list by name, for help texts."""
    return tuple(env_id for family in FAMILIES for env_id in family.env_ids())


__all__ = ["FAMILIES", "TaskFamily", "UnusableEnvironment", "family_for", "listed_env_ids"]
