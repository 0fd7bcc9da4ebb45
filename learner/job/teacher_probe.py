"""Ask a real teacher service which teacher kinds, parameters and curricula it takes, before a command's first run.

``bakeoff`` and ``tune`` refuse a bad ``--teacher-param`` or search-space entry before anything trains. What
is right is the service's to say, so they ask one instead of reading its internals: the kinds and each
kind's parameter names come from ``GET /api/v1/teachers``, and a value is checked by registering a probe
curriculum with it, so the service's own models (bounds, choices and the validators that a JSON schema
cannot express, such as a range's low below its high, or a kind that does not take the task space) give
the verdict and the message. The probe curricula go to a throwaway service on a temporary SQLite file
(``teacher_probe``), never to the one the runs use, whose dashboard and database they would clutter.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import tempfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from common.client.schemas import API_PREFIX, TeacherKindInfo, TeacherKindList
from common.client.task_space import TaskSpace
from common.client.teacher_client import TeacherClient, TeacherClientError, TeacherRequestError
from common.client.write_token import TOKEN_VARIABLE
from learner.commands.arguments import UsageError
from learner.core.config import TrainConfig
from teacher_service.process import ServiceProcess

STARTUP_TIMEOUT_S = 60.0
SHUTDOWN_TIMEOUT_S = 15.0
REQUEST_TIMEOUT_S = 10.0
PROBE_SERVICE_ENV = {TOKEN_VARIABLE: "", "KC_ALLOWED_HOSTS": "127.0.0.1", "KC_SQLITE_SYNCHRONOUS": "NORMAL"}
"""The throwaway service's settings over the caller's ``KC_`` ones: no write token and the loopback host only
(it is private to this process, whatever the deployment's settings say), no sync to disk per curriculum."""


class UnknownTeacherKind(ValueError):
    """The service has no teacher kind of this name."""


@dataclass(frozen=True)
class Reason:
    """One of the service's reasons for a refusal, as its 422 gives it."""

    parameter: str | None
    """The teacher parameter it names (``start``, ``reward_range.1``); None when it is about the parameters
    together, the kind or the task space."""
    message: str
    """The service's own words."""

    def __str__(self) -> str:
        return f"{self.parameter}: {self.message}" if self.parameter else self.message


@dataclass(frozen=True)
class Refusal:
    """Why the service refused a curriculum."""

    reasons: tuple[Reason, ...]
    about_parameters: bool
    """Whether the service blames the teacher's parameters (rather than the kind or the task space)."""

    @classmethod
    def from_detail(cls, detail: Any) -> Refusal:
        """From a 422's ``detail``: pydantic's list of errors, each with its ``loc`` (``body``, the kind, then
        ``params`` and the parameter's name when a parameter is to blame) and ``msg``; anything else as text."""
        if not isinstance(detail, list):
            return cls((Reason(None, _one_line(detail)),), False)
        reasons, about_parameters = [], False
        for error in detail:
            location = [str(part) for part in error.get("loc", [])] if isinstance(error, dict) else []
            message = _one_line(error.get("msg", error) if isinstance(error, dict) else error)
            parameter = None
            if "params" in location:
                about_parameters = True
                parameter = ".".join(location[location.index("params") + 1 :]) or None
            reasons.append(Reason(parameter, message))
        return cls(tuple(reasons), about_parameters)

    def line(self, kind: str, env: str) -> str:
        """The refusal for a command's user, in one line: what to change (a ``--teacher-param``, or the kind
        on the environment ``env``), then the service's reasons."""
        where = f"--teacher-param for {kind}" if self.about_parameters else f"{kind} on {env}"
        return f"{where}: {self}"

    @property
    def messages(self) -> str:
        """The service's messages alone, for a caller that already names the parameter."""
        return "; ".join(reason.message for reason in self.reasons)

    def __str__(self) -> str:
        return "; ".join(str(reason) for reason in self.reasons)


def _one_line(value: Any) -> str:
    return " ".join(str(value).split())


class TeacherProbe:
    """Questions to the teacher service at ``url``. ``refusal`` registers curricula there, so ``url`` should be
    a service of its own (``teacher_probe``)."""

    def __init__(self, url: str) -> None:
        self.url = url.rstrip("/")
        self._names = (f"probe-{number}" for number in itertools.count())

    @functools.cached_property
    def kinds(self) -> dict[str, TeacherKindInfo]:
        """Every kind the service offers, by name, with its parameters (``GET /api/v1/teachers``)."""
        try:
            response = httpx.get(f"{self.url}{API_PREFIX}/teachers", timeout=REQUEST_TIMEOUT_S)
            response.raise_for_status()
        except httpx.HTTPError as error:
            raise UsageError(f"cannot list the teacher kinds of the service at {self.url}: {error}") from None
        return {info.kind: info for info in TeacherKindList.model_validate_json(response.content).teachers}

    def kind(self, kind: str) -> TeacherKindInfo:
        """The kind's description; ``UnknownTeacherKind`` when the service has none of this name."""
        try:
            return self.kinds[kind]
        except KeyError:
            raise UnknownTeacherKind(f"no teacher kind {kind!r}; known: {', '.join(self.kinds)}") from None

    def refusal(self, kind: str, space: TaskSpace, params: Mapping[str, Any], seed: int = 0) -> Refusal | None:
        """Register a curriculum of ``kind`` over ``space`` with ``params`` (each left out at the kind's
        default): None when the service takes it, else its reasons. Another answer than a 422 (the service
        gone, a write refused) is a ``UsageError``."""
        with TeacherClient(self.url, next(self._names), request_timeout=REQUEST_TIMEOUT_S) as client:
            try:
                client.register(kind, space, params=params, seed=seed, timeout=REQUEST_TIMEOUT_S)
            except TeacherClientError as error:
                if isinstance(error, TeacherRequestError) and error.status == 422:
                    return Refusal.from_detail(error.detail)
                raise UsageError(f"the teacher service at {self.url} could not check a curriculum: {error}") from None
        return None

    def run_refusal(self, config: TrainConfig) -> Refusal | None:
        """``refusal`` of the curriculum a run of ``config`` registers (as ``session.register_curriculum`` does):
        its kind over its family's task space, with the family's parameters and its overrides."""
        return self.refusal(config.teacher, config.task_space(), config.teacher_params, config.seed)

    def parameters(self, kind: str, space: TaskSpace) -> KindParameters:
        """The kind's parameters over ``space``, each value to be checked on its own (``KindParameters``)."""
        info = self.kind(kind)
        return KindParameters(kind, tuple(parameter.name for parameter in info.parameters), self, space)


@dataclass(frozen=True)
class KindParameters:
    """One kind's parameter names as the service lists them, and a check of one value by the service: a
    curriculum over ``space`` with that value alone, the kind's defaults for the others."""

    kind: str
    names: tuple[str, ...]
    probe: TeacherProbe
    space: TaskSpace

    def problem(self, name: str, value: Any) -> str | None:
        """The service's reason for refusing ``value`` for ``name``; None when it takes it."""
        refusal = self.probe.refusal(self.kind, self.space, {name: value})
        return None if refusal is None else refusal.messages


@contextlib.contextmanager
def teacher_probe() -> Iterator[TeacherProbe]:
    """A ``TeacherProbe`` on a throwaway service: ``kuka-curriculum serve`` on a temporary SQLite file
    (``PROBE_SERVICE_ENV``), stopped and deleted after the block. It starts in a few seconds, most of them
    the service's imports; a failed start is a ``UsageError`` with the service's log."""
    with tempfile.TemporaryDirectory(prefix="kuka-curriculum-probe-") as directory:
        service = ServiceProcess(Path(directory) / "probe.sqlite", env=PROBE_SERVICE_ENV)
        try:  # stopped however the block ends, a Ctrl-C while it starts included
            try:
                service.start(STARTUP_TIMEOUT_S)
            except RuntimeError as error:
                raise UsageError(f"cannot start a teacher service to check the teacher's parameters: {error}") from None
            yield TeacherProbe(service.url)
        finally:
            service.stop(SHUTDOWN_TIMEOUT_S)
