"""A settings file for ``train --config`` and ``bakeoff --config``, such as the ``best.json`` that
``tune`` writes: the chosen settings travel from a search to the runs that use them, and flags
given on the command line still override them.

The file is a JSON object whose keys are among ``SETTINGS`` (each the ``TrainConfig`` field of that
name), ``ppo`` (PPOConfig fields) and ``teacher_params`` (parameters of the file's ``teacher``);
``tune`` and ``about`` record where the settings came from and are not read. Other keys are refused by
name, so a typo never passes silently.

A recipe is such a file shipped with the package (``RECIPE_DIR``), named rather than found by path: the
settings the measurements chose for a task, so a user trains them with one flag (``--config hard-grasp-v1``).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from learner.core.config import TrainConfig

SETTINGS = (
    "teacher",
    "env",
    "total_steps",
    "workers",
    "envs_per_worker",
    "max_episode_steps",
    "loop",
    "policy_choice",
)
"""``TrainConfig`` fields a settings file may set."""
NOTES_KEY = "tune"
ABOUT_KEY = "about"
"""A recipe's note of what it is and which runs chose it."""
KNOWN_KEYS = (*SETTINGS, "ppo", "teacher_params", NOTES_KEY, ABOUT_KEY)
"""Every key a settings file may hold, in the order an error lists them."""
RECIPE_DIR = Path(__file__).parent / "recipes"
RECIPES = tuple(sorted(path.stem for path in RECIPE_DIR.glob("*.json")))
"""The shipped recipes' names, each the stem of its file in ``RECIPE_DIR``."""
CONFIG_HELP = (
    "a settings file, such as the best.json of `kuka-curriculum tune`, or a shipped recipe by name: "
    + ", ".join(RECIPES)
    + " (docs/commands.md#recipes; a file of that name in this folder is ./NAME)"
)


def config_path(text: str) -> Path:
    """``--config``'s argument: a recipe's name gives its shipped file, anything else is a path."""
    return RECIPE_DIR / f"{text}.json" if text in RECIPES else Path(text)


@dataclass(frozen=True)
class ConfigFile:
    settings: dict[str, Any] = field(default_factory=dict)
    ppo: dict[str, Any] = field(default_factory=dict)
    teacher_params: dict[str, Any] = field(default_factory=dict)

    @property
    def teacher(self) -> str | None:
        teacher = self.settings.get("teacher")
        return str(teacher) if teacher is not None else None

    def applied_to(self, base: TrainConfig, teacher: str | None = None) -> TrainConfig:
        """``base`` with the file's settings on top. ``teacher`` is the kind the run will use after its
        flags: the file's teacher parameters belong to the file's teacher and are left out for another."""
        teacher_params = self.teacher_params if teacher is None or teacher == self.teacher else {}
        return replace(
            base,
            **self.settings,
            ppo=base.ppo.with_overrides(self.ppo),
            teacher_overrides={**base.teacher_overrides, **teacher_params},
        )


SHOWN_CHARACTERS = 120
"""How much of a settings file's name an error repeats: the name is the user's text, of any length."""


def shortened(text: str) -> str:
    """``text`` as an error shows it, cut to ``SHOWN_CHARACTERS`` with an ellipsis."""
    return text if len(text) <= SHOWN_CHARACTERS else text[: SHOWN_CHARACTERS - 1] + "…"


def read_config_file(path: Path) -> ConfigFile:
    """The file's settings, checked by name and built into a ``TrainConfig`` once; ``ValueError`` says what is wrong."""
    path = Path(path)
    shown = shortened(str(path))
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"no settings file {shown}, and no recipe of that name: {', '.join(RECIPES)}") from None
    except OSError as error:
        raise ValueError(f"cannot read the settings file {shown}: {error.strerror}") from None
    except json.JSONDecodeError as error:
        raise ValueError(f"the settings file {shown} is not valid JSON: {error}") from None
    if not isinstance(data, dict):
        raise ValueError(f"the settings file {shown} must hold a JSON object")
    unknown = shortened(", ".join(sorted(set(data) - set(KNOWN_KEYS))))
    if unknown:
        raise ValueError(f"the settings file {shown} has unknown key(s) {unknown}; known: {', '.join(KNOWN_KEYS)}")
    for key in ("ppo", "teacher_params"):
        if not isinstance(data.get(key, {}), dict):
            raise ValueError(f"the settings file {shown}: {key} must be an object of name to value")
    config_file = ConfigFile(
        settings={key: data[key] for key in SETTINGS if key in data},
        ppo=dict(data.get("ppo", {})),
        teacher_params=dict(data.get("teacher_params", {})),
    )
    try:
        config_file.applied_to(TrainConfig())
    except (TypeError, ValueError) as error:
        raise ValueError(f"the settings file {shown}: {error}") from None
    return config_file


class BakeoffConfigAction(argparse.Action):
    """``bakeoff --config FILE``: the file's settings become the defaults of the bake-off's flags.

    A flag that still holds its default takes the file's value, so a flag given after ``--config``,
    or before it with another value, overrides the file. The file's PPO values go before any
    ``--ppo`` (the later wins), its teacher's parameters apply to that teacher only (``KIND.NAME``),
    and its teacher itself is not used: a bake-off names its own teachers.
    """

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        path = Path(str(values))
        try:
            config_file = read_config_file(path)
        except ValueError as error:
            parser.error(str(error))
        ppo = dict(config_file.ppo)
        flags = {name: value for name, value in config_file.settings.items() if name != "teacher"}
        if "rollout_length" in ppo:
            flags["rollout_length"] = ppo.pop("rollout_length")  # the bake-off's own flag, which train puts last
        for name, value in flags.items():
            if getattr(namespace, name, None) == parser.get_default(name):
                setattr(namespace, name, value)
        namespace.ppo = [*ppo.items(), *(namespace.ppo or [])]
        kind = config_file.teacher
        if config_file.teacher_params and kind is None:
            parser.error(f"the settings file {shortened(str(path))} has teacher_params but no teacher they belong to")
        teacher_params = [(f"{kind}.{name}", value) for name, value in config_file.teacher_params.items()]
        namespace.teacher_params = [*teacher_params, *(namespace.teacher_params or [])]
        setattr(namespace, self.dest, path)
