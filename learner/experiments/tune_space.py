"""The search space of ``kuka-curriculum tune``: read from a file, checked before anything trains.

A search space file (JSON, or YAML when its name ends in .yaml or .yml) maps a setting's name to
one distribution::

    {"learning_rate": {"loguniform": [1e-4, 1e-3]}, "fit_rate": {"choice": [100, 250]}}

A ``grid`` entry is not drawn: every trial sample runs once with each of its values (every
combination where there are several grids), so a tune can compare settings side by side.

A name is a ``PPOConfig`` field, a parameter of the tuned teacher kind, or a task-family option
(``max_episode_steps``, the episode limit); a prefix (``ppo.``, ``teacher.``, ``env.``) picks one
where a bare name would be ambiguous. Every value a distribution can draw is checked against the
setting's own bounds: both ends of a range, every choice; the bounds are the ones ``PPOConfig`` and
``TrainConfig`` enforce, and for a teacher parameter the teacher service's, so a refusal names the
setting and the reason. What the tuned kind takes is the service's to say (``TeacherParameters``,
which ``learner.job.teacher_probe`` answers from a real service). Each value is checked on its own,
the kind's defaults for its other parameters: a combination of values that the service refuses (two
ratios adding up to more than 1) fails only the trials that draw it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Literal, Protocol

from learner.commands.config_file import ConfigFile
from learner.core.config import PPOConfig, TrainConfig

Target = Literal["ppo", "teacher", "env"]
Distribution = Literal["choice", "grid", "uniform", "loguniform", "randint"]
DISTRIBUTIONS: tuple[Distribution, ...] = ("choice", "grid", "uniform", "loguniform", "randint")
TASK_FAMILY_OPTIONS = ("max_episode_steps",)
"""``TrainConfig`` fields that shape the task family's episodes."""
MAX_CHOICES = 100


class SearchSpaceError(ValueError):
    """The search space file is unreadable, names an unknown setting, or reaches outside its bounds."""


class TeacherParameters(Protocol):
    """The tuned teacher kind's parameters as the teacher service has them (``teacher_probe.KindParameters``
    asks a real one)."""

    @property
    def kind(self) -> str: ...

    @property
    def names(self) -> tuple[str, ...]:
        """The kind's parameter names, as ``GET /api/v1/teachers`` lists them."""
        ...

    def problem(self, name: str, value: Any) -> str | None:
        """Why the service refuses ``value`` for the parameter ``name`` (the others at the kind's
        defaults); None when it takes it."""
        ...


@dataclass(frozen=True)
class Dimension:
    """One searched setting: where it goes, under what name, drawn how."""

    target: Target
    name: str
    distribution: Distribution
    values: tuple[Any, ...]
    """choice and grid: the options; uniform and loguniform: (low, high); randint: (low, high), both included."""

    @property
    def key(self) -> str:
        """The trial configuration's key, which also names the setting in trials.json."""
        return f"{self.target}.{self.name}"

    def extremes(self) -> tuple[Any, ...]:
        """The values that decide whether every draw is in bounds."""
        if self.distribution == "uniform" or self.distribution == "loguniform":
            return tuple(float(value) for value in self.values)
        return self.values

    def to_tune(self) -> Any:
        from ray import tune

        if self.distribution == "choice":
            return tune.choice(list(self.values))
        if self.distribution == "grid":
            return tune.grid_search(list(self.values))
        if self.distribution == "uniform":
            return tune.uniform(*self.values)
        if self.distribution == "loguniform":
            return tune.loguniform(*self.values)
        low, high = self.values
        return tune.randint(low, high + 1)  # Tune's upper end is excluded; ours is included


@dataclass(frozen=True)
class SearchSpace:
    teacher: str
    dimensions: tuple[Dimension, ...]

    def param_space(self) -> dict[str, Any]:
        """The space as Tune samples it: one flat key per setting."""
        return {dimension.key: dimension.to_tune() for dimension in self.dimensions}

    @property
    def grid_size(self) -> int:
        """Trials each sample becomes: the product of the grids' lengths (1 without a grid)."""
        return math.prod(len(dimension.values) for dimension in self.dimensions if dimension.distribution == "grid")


def apply_settings(base: TrainConfig, settings: Mapping[str, Any]) -> TrainConfig:
    """``base`` with ``{"ppo.NAME": v, "teacher.NAME": v, "env.NAME": v}`` on top (``ValueError`` if one is bad)."""
    grouped = grouped_settings(settings)
    return ConfigFile(grouped["env"], grouped["ppo"], grouped["teacher"]).applied_to(base)


def grouped_settings(settings: Mapping[str, Any]) -> dict[Target, dict[str, Any]]:
    """A trial's ``{"ppo.NAME": v, "teacher.NAME": v, "env.NAME": v}`` grouped by where each goes."""
    grouped: dict[Target, dict[str, Any]] = {"ppo": {}, "teacher": {}, "env": {}}
    for key, value in settings.items():
        target, _, name = key.partition(".")
        grouped[target][name] = python_value(value)  # type: ignore[index]  # keys are Dimension.key
    return grouped


def python_value(value: Any) -> Any:
    """Tune draws numpy numbers; the configs and JSON take Python ones."""
    return value.item() if hasattr(value, "item") else value


def load_raw_search_space(path: Path) -> dict[str, Any]:
    """The file's mapping, unchecked (``parse_search_space`` checks it); ``SearchSpaceError`` when unreadable."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise SearchSpaceError(f"cannot read the search space {path}: {error.strerror}") from None
    try:
        raw = _parse(text, path)
    except ValueError as error:
        raise SearchSpaceError(f"{path} is not valid {_format(path)}: {error}") from None
    if not isinstance(raw, dict) or not raw:
        raise SearchSpaceError(f"{path}: expected a mapping of setting name to distribution, with at least one")
    return {str(name): spec for name, spec in raw.items()}


def _format(path: Path) -> str:
    return "YAML" if path.suffix.lower() in (".yaml", ".yml") else "JSON"


def _parse(text: str, path: Path) -> Any:
    if _format(path) == "JSON":
        return json.loads(text)
    import yaml  # type: ignore[import-untyped]  # PyYAML, which Ray installs, ships no types

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise ValueError(str(error)) from None


def parse_search_space(raw: Any, teacher: TeacherParameters) -> SearchSpace:
    """The search space ``raw`` (``load_raw_search_space``'s) for a tune of ``teacher``, every value checked."""
    if not isinstance(raw, dict) or not raw:
        raise SearchSpaceError("expected a mapping of setting name to distribution, with at least one setting")
    dimensions = tuple(_dimension(str(name), spec, teacher) for name, spec in raw.items())
    keys = [dimension.key for dimension in dimensions]
    repeated = sorted({key for key in keys if keys.count(key) > 1})
    if repeated:
        raise SearchSpaceError(f"{', '.join(repeated)} named more than once")
    return SearchSpace(teacher.kind, dimensions)


def _settings_by_target(teacher: TeacherParameters) -> dict[Target, tuple[str, ...]]:
    return {"ppo": tuple(f.name for f in fields(PPOConfig)), "teacher": teacher.names, "env": TASK_FAMILY_OPTIONS}


def _resolve(name: str, teacher: TeacherParameters) -> tuple[Target, str]:
    known = _settings_by_target(teacher)
    prefix, dot, rest = name.partition(".")
    if dot:
        if prefix not in known:
            raise SearchSpaceError(f"{name}: unknown prefix {prefix!r}; expected ppo., teacher. or env.")
        target: Target = prefix
        if rest not in known[target]:
            known_names = ", ".join(known[target])
            raise SearchSpaceError(f"{name}: no such setting; known {_describe(target, teacher)}: {known_names}")
        return target, rest
    owners = [target for target, names in known.items() if name in names]
    if not owners:
        raise SearchSpaceError(
            f"{name}: no such setting; expected a PPOConfig field ({', '.join(known['ppo'])}), a parameter of "
            f"{teacher.kind} ({', '.join(known['teacher'])}) or a task-family option ({', '.join(known['env'])})"
        )
    if len(owners) > 1:
        raise SearchSpaceError(f"{name}: ambiguous; write {' or '.join(f'{owner}.{name}' for owner in owners)}")
    return owners[0], name


def _describe(target: Target, teacher: TeacherParameters) -> str:
    return {"ppo": "PPOConfig fields", "teacher": f"parameters of {teacher.kind}", "env": "task-family options"}[target]


def _dimension(name: str, spec: Any, teacher: TeacherParameters) -> Dimension:
    target, field_name = _resolve(name, teacher)
    if not isinstance(spec, dict) or len(spec) != 1:
        raise SearchSpaceError(f'{name}: expected one distribution, such as {{"uniform": [low, high]}}; got {spec!r}')
    [(distribution, values)] = spec.items()
    if distribution not in DISTRIBUTIONS:
        expected = ", ".join(DISTRIBUTIONS)
        raise SearchSpaceError(f"{name}: unknown distribution {distribution!r}; expected one of {expected}")
    dimension = Dimension(target, field_name, distribution, _values(name, distribution, values))
    for value in dimension.extremes():
        problem = _value_problem(dimension, value, teacher)
        if problem is not None:
            raise SearchSpaceError(f"{name}: cannot be {value!r}: {problem}")
    return dimension


def _values(name: str, distribution: Distribution, values: Any) -> tuple[Any, ...]:
    if distribution == "choice" or distribution == "grid":
        if not isinstance(values, list) or not 1 <= len(values) <= MAX_CHOICES:
            raise SearchSpaceError(f"{name}: {distribution} takes a list of 1 to {MAX_CHOICES} values, got {values!r}")
        return tuple(tuple(value) if isinstance(value, list) else value for value in values)
    numbers = isinstance(values, list) and len(values) == 2 and all(_is_number(value) for value in values)
    if not numbers or not values[0] < values[1]:
        raise SearchSpaceError(f"{name}: {distribution} takes [low, high] with low < high, got {values!r}")
    if distribution == "randint" and not all(isinstance(value, int) for value in values):
        raise SearchSpaceError(f"{name}: randint takes whole numbers, got {values!r}")
    if distribution == "loguniform" and values[0] <= 0:
        raise SearchSpaceError(f"{name}: loguniform needs low > 0, got {values!r}")
    return tuple(values)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _value_problem(dimension: Dimension, value: Any, teacher: TeacherParameters) -> str | None:
    """Why the setting cannot take ``value`` on its own, as its config or the teacher service says; None if it can."""
    value = list(value) if isinstance(value, tuple) else value
    if dimension.target == "teacher":
        return teacher.problem(dimension.name, value)
    try:
        if dimension.target == "ppo":
            PPOConfig().with_overrides({dimension.name: value})
        elif dimension.target == "env":
            if not (isinstance(value, int) and not isinstance(value, bool)):
                return "a whole number is needed"
            options: dict[str, Any] = {dimension.name: value}
            replace(TrainConfig(), **options)
    except ValueError as error:
        return " ".join(str(error).split()) or type(error).__name__
    return None
