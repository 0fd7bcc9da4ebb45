"""Take every episode's task from the teacher service, in any gymnasium training loop.

    env = CurriculumWrapper(
        gymnasium.make("KukaGrasp-v0"),
        "http://127.0.0.1:8000",
        "kuka-sb3",
        register=CurriculumRegistration("alp-gmm", KUKA_TASK_SPACE),  # idempotent; leave out to join one
    )

At each ``reset`` the wrapper takes the curriculum's next task and applies it, by default as
``env.reset(options={"task": task})`` (what ``KukaGrasp-v0`` reads), or through ``apply_task(env,
task)`` for an environment that takes its parameters another way. When an episode ends it reports
the return, the length and, when the environment puts ``is_success`` in ``info``, the success. The
task and its id (``None`` for an offline task, see below) are in the ``info`` of the reset and of
the step that ends the episode, with ``score_only`` (robust PLR's: leave the episode out of the
update). An episode cut short by an early ``reset`` is not reported.

With ``scores_from_learner=True`` an ended episode waits for its score instead of being reported at
once: the learner computes it once its advantages are known (robust PLR's positive value loss, the mean
over the episode's steps of max(GAE advantage, 0)) and hands each environment's scores, in the order its
episodes ended, to ``report_scores`` (through ``VecEnv.env_method`` from a Stable-Baselines3 callback:
``examples/sb3_minigrid_plr.py``). At most ``MAX_UNSCORED`` episodes wait; past that, and at
``close``, the oldest go without a score, and the teacher falls back on the return or success.

The constructor checks the curriculum at once, so a typo in the name, a wrong token or a teacher
that does not answer fails with ``CurriculumError`` where the environment is made, not in the
middle of training. After that the teacher may come and go: the process's ``TeacherClient``
buffers results and resends them, and when no task can be had within ``task_timeout`` it runs the
tasks the teacher issued recently (offline tasks, whose results it does not send) until the teacher
answers again. ``close()`` delivers what is buffered, waiting up to ``close_timeout``.

Each process has one client per curriculum, made at the first ``reset`` after any fork, so the
wrapper works inside ``SubprocVecEnv`` workers and Ray env runners, and the environments of one
process share one connection and one prefetched batch of tasks. This module imports neither
torch, nor Ray, nor PyBullet.
"""

from __future__ import annotations

import atexit
import logging
import os
import threading
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, SupportsFloat

import gymnasium
from gymnasium.core import ActType, ObsType
from pydantic import SecretStr

from common.client.schemas import TeacherKind
from common.client.task_space import Task, TaskSpace
from common.client.teacher_client import (
    Assignment,
    TeacherClient,
    TeacherRequestError,
    TeacherUnavailable,
)
from common.client.write_token import TOKEN_VARIABLE

log = logging.getLogger(__name__)

ApplyTask = Callable[[gymnasium.Env[Any, Any], Task], None]
"""Sets a task's parameters on an environment before its reset, e.g. ``env.unwrapped.g = task["gravity"]``."""


class CurriculumError(RuntimeError):
    """The wrapper cannot use this curriculum: unknown name, refused token, unreachable teacher."""


class TaskRejected(CurriculumError):
    """The environment refused a task from the curriculum (its task space does not fit the env)."""


@dataclass(frozen=True)
class CurriculumRegistration:
    """What to create the curriculum with when it does not exist yet (the same as ``PUT`` takes)."""

    teacher: TeacherKind
    space: TaskSpace
    params: Mapping[str, Any] = field(default_factory=dict)
    seed: int = 0


MAX_UNSCORED = 1024
"""Ended episodes that wait for a score, per environment; the oldest is reported without one beyond."""


@dataclass(frozen=True)
class _EndedEpisode:
    assignment: Assignment
    episode_return: float
    success: bool | None
    length: int


class CurriculumWrapper(gymnasium.Wrapper[ObsType, ActType, ObsType, ActType]):
    """Runs each episode on the next task of a teacher-service curriculum and reports its result."""

    def __init__(
        self,
        env: gymnasium.Env[ObsType, ActType],
        teacher_url: str,
        curriculum: str,
        *,
        register: CurriculumRegistration | None = None,
        apply_task: ApplyTask | None = None,
        token: str | SecretStr | None = None,
        prefetch: int = 16,
        task_timeout: float = 5.0,
        report_interval: float = 1.0,
        startup_timeout: float = 10.0,
        close_timeout: float = 30.0,
        scores_from_learner: bool = False,
    ) -> None:
        """``token`` defaults to ``$KC_TEACHER_TOKEN``. ``prefetch`` tasks are drawn per request for
        the whole process, whose results are sent together every ``report_interval`` seconds (see
        ``TeacherClient``). ``startup_timeout`` bounds the check made here. ``scores_from_learner``:
        hold each ended episode until ``report_scores`` gives its score (see the module doc)."""
        super().__init__(env)
        self.teacher_url = teacher_url.rstrip("/")
        self.curriculum = curriculum
        self.apply_task = apply_task
        self.close_timeout = close_timeout
        self._client_key = _ClientKey(
            url=self.teacher_url,
            curriculum=curriculum,
            token=_secret(token if token is not None else os.environ.get(TOKEN_VARIABLE)),
            prefetch=prefetch,
            task_timeout=task_timeout,
            report_interval=report_interval,
        )
        self._client: TeacherClient | None = None
        self._client_pid: int | None = None
        self._assignment: Assignment | None = None
        self._episode_return = 0.0
        self._episode_length = 0
        self.scores_from_learner = scores_from_learner
        self._unscored: deque[_EndedEpisode] = deque()
        _check_curriculum(self._client_key, register, startup_timeout)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[ObsType, dict[str, Any]]:
        assignment = self._teacher().next_task()
        try:
            if self.apply_task is None:
                observation, info = self.env.reset(seed=seed, options={**(options or {}), "task": assignment.params})
            else:
                self.apply_task(self.env, dict(assignment.params))
                observation, info = self.env.reset(seed=seed, options=options)
        except (ValueError, KeyError, TypeError) as error:
            raise TaskRejected(
                f"the environment refused task {assignment.params} of curriculum {self.curriculum!r} at "
                f"{self.teacher_url}: {error}. Does the curriculum's task space fit this environment?"
            ) from error
        self._assignment = assignment
        self._episode_return = 0.0
        self._episode_length = 0
        return observation, self._with_task(info, assignment)

    def step(self, action: ActType) -> tuple[ObsType, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        assignment = self._assignment
        if assignment is None:
            return observation, reward, terminated, truncated, info
        self._episode_return += float(reward)
        self._episode_length += 1
        if terminated or truncated:
            success = info.get("is_success")
            ended = _EndedEpisode(
                assignment, self._episode_return, None if success is None else bool(success), self._episode_length
            )
            if self.scores_from_learner:
                self._unscored.append(ended)
                if len(self._unscored) > MAX_UNSCORED:
                    self._report(self._unscored.popleft(), None)
            else:
                self._report(ended, None)
            self._assignment = None
            info = self._with_task(info, assignment)
        return observation, reward, terminated, truncated, info

    def report_scores(self, scores: Sequence[float]) -> int:
        """Report the oldest ended episodes still waiting, one per score, in the order they ended;
        returns how many wait after them. More scores than waiting episodes is a ``ValueError``."""
        if len(scores) > len(self._unscored):
            raise ValueError(f"{len(scores)} scores for {len(self._unscored)} ended episodes waiting for one")
        for score in scores:
            self._report(self._unscored.popleft(), float(score))
        return len(self._unscored)

    def _report(self, ended: _EndedEpisode, score: float | None) -> None:
        self._teacher().report(
            ended.assignment, ended.episode_return, success=ended.success, length=ended.length, score=score
        )

    def close(self) -> None:
        """Report episodes still waiting for a score without one, deliver this process's buffered
        results (up to ``close_timeout``), then close the env."""
        while self._unscored:
            self._report(self._unscored.popleft(), None)
        if self._client is not None and self._client_pid == os.getpid():
            _release_client(self._client_key, self.close_timeout)
        self._client = None
        super().close()  # type: ignore[no-untyped-call]  # gymnasium leaves Wrapper.close untyped

    def _teacher(self) -> TeacherClient:
        """This process's client, made on first use so that a forked child never uses its parent's."""
        if self._client is None or self._client_pid != os.getpid():
            self._client = _acquire_client(self._client_key)
            self._client_pid = os.getpid()
        return self._client

    @staticmethod
    def _with_task(info: dict[str, Any], assignment: Assignment) -> dict[str, Any]:
        return {
            **info,
            "task": dict(assignment.params),
            "task_id": assignment.task_id,
            "score_only": assignment.score_only,
        }


@dataclass(frozen=True)
class _ClientKey:
    url: str
    curriculum: str
    token: SecretStr | None
    """A ``SecretStr``, so that a repr of the key (in a traceback, a log) does not show it."""
    prefetch: int
    task_timeout: float
    report_interval: float

    def client(self, request_timeout: float = 10.0) -> TeacherClient:
        return TeacherClient(
            self.url,
            self.curriculum,
            token=self.token,
            prefetch=self.prefetch,
            task_timeout=self.task_timeout,
            request_timeout=request_timeout,
            report_interval=self.report_interval,
        )


def _secret(token: str | SecretStr | None) -> SecretStr | None:
    """The token as a ``SecretStr``; an empty one is none."""
    if isinstance(token, str):
        token = SecretStr(token)
    return token if token is not None and token.get_secret_value() else None


def _check_curriculum(key: _ClientKey, register: CurriculumRegistration | None, timeout: float) -> None:
    """Create or find the curriculum and prove the token may write to it, with a short-lived client
    (no thread of it survives to be forked)."""
    with key.client(request_timeout=timeout) as client:
        try:
            if register is not None:
                client.register(register.teacher, register.space, register.params, register.seed, timeout=timeout)
                return
            config = client.info(timeout=timeout).config
            # Registering the existing configuration again changes nothing, but needs write access.
            client.register(config.teacher, config.task_space(), config.params, config.seed, timeout=timeout)
        except TeacherUnavailable as error:
            raise CurriculumError(
                f"cannot reach the teacher service at {key.url} within {timeout} s ({error}); "
                "is `kuka-curriculum serve` running there?"
            ) from None
        except TeacherRequestError as error:
            raise CurriculumError(_explain(error, key, register)) from None


def _explain(error: TeacherRequestError, key: _ClientKey, register: CurriculumRegistration | None) -> str:
    where = f"curriculum {key.curriculum!r} at {key.url}"
    if error.status == 404:
        return f"no {where}: check the name, or pass register=CurriculumRegistration(...) to create it"
    if error.status == 401:
        given = "a token that it refused" if key.token else "no token"
        return f"the teacher requires a write token and got {given} ({TOKEN_VARIABLE} or token=): {error.detail}"
    if error.status == 409:
        return f"{where} exists with a different configuration than {register}: {error.detail}"
    return f"{where}: {error}"


@dataclass
class _SharedClient:
    client: TeacherClient
    users: int


_clients: dict[_ClientKey, _SharedClient] = {}
_clients_lock = threading.Lock()


def _acquire_client(key: _ClientKey) -> TeacherClient:
    with _clients_lock:
        shared = _clients.get(key)
        if shared is None:
            shared = _clients[key] = _SharedClient(key.client(), users=0)
        shared.users += 1
        return shared.client


def _release_client(key: _ClientKey, timeout: float) -> None:
    """Flush the shared client; the last wrapper of the process to let go closes it."""
    with _clients_lock:
        shared = _clients.get(key)
        if shared is None:
            return
        shared.users -= 1
        last = shared.users <= 0
        if last:
            del _clients[key]
    if last:
        shared.client.close(timeout)
    elif not shared.client.flush(timeout):
        log.warning("%d results for %r still pending after %s s", shared.client.pending, key.curriculum, timeout)


def _forget_inherited_clients() -> None:
    """In a forked child the parent's clients have no sender thread: start from none."""
    global _clients_lock
    _clients.clear()
    _clients_lock = threading.Lock()


def _close_left_open(timeout: float = 10.0) -> None:
    """At exit, deliver the results of wrappers nobody closed."""
    with _clients_lock:
        left = list(_clients.values())
        _clients.clear()
    for shared in left:
        shared.client.close(timeout)


os.register_at_fork(after_in_child=_forget_inherited_clients)
atexit.register(_close_left_open)
