"""Client of the teacher service, for rollout workers and the learner.

    client = TeacherClient("http://127.0.0.1:8000", "kuka", token=os.environ.get("KC_TEACHER_TOKEN"))
    client.register("alp-gmm", KUKA_TASK_SPACE, params={"fit_rate": 250}, seed=0)  # idempotent
    assignment = client.next_task()          # Assignment(task_id, params)
    ...run an episode with assignment.params...
    client.report(assignment, reward, success=True, length=412)  # returns at once
    client.close()                           # delivers what is left

What it guarantees:

- One pooled HTTP connection per client, and retries with exponential backoff and jitter on
  connection errors, timeouts, 5xx, 408 and 429. Results are idempotent per task id on the
  service, so resending after a lost answer is safe. A 503 is what the service answers when its
  database refuses a write (disk full, read-only file): nothing of that request was stored, so it
  is retried like an outage, and the service's reason is logged.
- ``report`` never waits for the network: results go into a buffer that a background thread
  delivers in batches. Through a teacher outage the buffer keeps them and the thread keeps
  retrying until the teacher is back, so no result the caller handed over is lost while the
  process lives, up to ``max_buffered_results`` of them. Two exceptions:

  - A result the service rejects as invalid (a 422 naming it, such as a task id from a wiped
    database) can never be accepted, so it is logged, counted in ``rejected`` and dropped, and the
    rest of its batch is resent.
  - An outage long enough to fill the buffer: from then on each new result pushes out the oldest
    one waiting, counted in ``dropped_results``. The oldest go because the teacher learns from how
    the *current* policy does on its tasks, which the newest results tell best; and there is a
    bound because an outage of days would otherwise take the worker's memory (about 0.6 KB a
    result: 60 MB at the default 100,000). A warning is logged when a burst of drops starts, and
    one with the burst's count when the teacher takes results again. The service keeps the tasks
    of dropped results as issued and unanswered.
- ``next_task`` serves tasks from a prefetched batch. When the batch is used up and the teacher
  cannot be reached within ``task_timeout``, it returns an *offline* assignment
  (``task_id is None``): the recent tasks the teacher issued, taken in turn, so a worker keeps
  producing experience for the learner instead of stalling. From then on each call tries the
  teacher once, without waiting, until it answers: an outage costs a worker ``task_timeout`` once,
  not per episode. ``report`` counts results of offline assignments in ``offline_results`` but
  does not send them: the teacher never issued those tasks, and learning progress is only
  meaningful for the tasks it chose.
- Errors that retrying cannot fix (401 bad token, 404 unknown curriculum, 409 name taken, other
  4xx) raise ``TeacherRequestError`` with the service's explanation; if the background thread meets
  one, results stay buffered and the next ``report``/``flush`` raises it.

Use one client per process (a Ray actor builds its own); it is safe to share between threads.

A delivery log, for fault benches (``bench/chaos.py``), off unless asked for: with
``KC_RESULT_LOG`` naming a file (or ``result_log`` given), every client appends one JSON line per
acknowledged delivery (``"acknowledged"``: the task ids the service answered for, with its
``accepted``, ``duplicates`` and ``expired`` counts) and one per 5xx answer (``"status"``, the
request and the service's reason). Each line is one ``write`` to the file opened for appending, so
the clients of several processes can share the file. A line is written after the answer came, so
a process killed in between leaves out a delivery the service did acknowledge, never the reverse.
"""

from __future__ import annotations

import itertools
import json
import logging
import math
import os
import random
import threading
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import httpx
from pydantic import SecretStr

from common.client.schemas import (
    API_PREFIX,
    MAX_RESULTS_PER_REQUEST,
    MAX_TASKS_PER_REQUEST,
    CurriculumInfo,
    CurriculumSpec,
    CurriculumState,
    ParameterSpec,
    ResultAck,
    ResultItem,
    TaskBatch,
    TeacherKind,
)
from common.client.task_space import Task, TaskSpace

log = logging.getLogger(__name__)

_RETRYABLE_STATUS = frozenset({408, 429})
RESULT_LOG_VARIABLE = "KC_RESULT_LOG"
"""Names the file a client appends its delivery log to (see the module doc); unset or empty: no log."""


class TeacherClientError(RuntimeError):
    """Base class of the client's errors."""


class TeacherUnavailable(TeacherClientError):
    """The teacher could not be reached (or kept failing) within the time allowed."""


class TeacherRequestError(TeacherClientError):
    """The service refused a request in a way that retrying cannot fix."""

    def __init__(self, status: int, detail: Any, method: str, path: str) -> None:
        super().__init__(f"{method} {path} -> {status}: {detail}")
        self.status = status
        self.detail = detail


@dataclass(frozen=True)
class Assignment:
    """A task to run an episode on. ``task_id`` is None for an offline assignment (see module doc)."""

    task_id: str | None
    params: Task
    score_only: bool = False
    """Play the episode and report it, but leave its transitions out of the policy update (robust
    PLR's new levels)."""

    @property
    def offline(self) -> bool:
        return self.task_id is None


@dataclass(frozen=True)
class Backoff:
    """Exponential backoff with jitter: attempt n waits between half and all of min(cap, base * 2**n)."""

    base_s: float = 0.05
    cap_s: float = 5.0

    def delay(self, attempt: int) -> float:
        ceiling = min(self.cap_s, self.base_s * 2.0 ** min(attempt, 30))
        return ceiling * random.uniform(0.5, 1.0)


class _Transient(Exception):
    """A failure worth retrying (connection error, timeout, 5xx, 408, 429)."""


class _DeliveryLog:
    """The opt-in delivery log (see the module doc): JSON lines appended, each with one ``write``."""

    def __init__(self, path: str | os.PathLike[str], curriculum: str) -> None:
        self.path = os.fspath(path)
        self.curriculum = curriculum
        self._failed = False

    def write(self, **record: Any) -> None:
        line = json.dumps({"at": time.time(), "pid": os.getpid(), "curriculum": self.curriculum, **record})
        try:
            descriptor = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
            try:
                os.write(descriptor, (line + "\n").encode())
            finally:
                os.close(descriptor)
        except OSError as error:
            if not self._failed:  # once: a log for benches must not flood a worker's own
                log.warning("cannot append to the delivery log %s: %s", self.path, error)
            self._failed = True


class TeacherClient:
    """Draws tasks from and reports results to one curriculum of a teacher service."""

    def __init__(
        self,
        base_url: str,
        curriculum: str,
        *,
        token: str | SecretStr | None = None,
        prefetch: int = 8,
        task_timeout: float = 10.0,
        request_timeout: float = 10.0,
        recent_tasks: int = 64,
        backoff: Backoff = Backoff(),
        report_interval: float = 0.0,
        max_buffered_results: int = 100_000,
        result_log: str | os.PathLike[str] | None = None,
    ) -> None:
        """``prefetch`` tasks are drawn per request; ``task_timeout`` bounds how long ``next_task``
        keeps retrying before it hands out an offline assignment; ``recent_tasks`` issued tasks are
        remembered for those. After each delivery the sender waits ``report_interval`` seconds, so
        that the results reported meanwhile go out in one request (``flush`` and ``close`` cut the
        wait short): one request per result costs a producer of short episodes a few milliseconds each.
        At most ``max_buffered_results`` results wait for delivery; beyond that the oldest are dropped
        (see the module doc). ``result_log`` (default: ``KC_RESULT_LOG``) names a delivery log to
        append to (see the module doc)."""
        if not 1 <= prefetch <= MAX_TASKS_PER_REQUEST:
            raise ValueError(f"prefetch must be in [1, {MAX_TASKS_PER_REQUEST}], got {prefetch}")
        if max_buffered_results < 1:
            raise ValueError(f"max_buffered_results must be at least 1, got {max_buffered_results}")
        self.curriculum = curriculum
        self.prefetch = prefetch
        self.task_timeout = task_timeout
        self.backoff = backoff
        self.report_interval = report_interval
        self.max_buffered_results = max_buffered_results
        secret = token.get_secret_value() if isinstance(token, SecretStr) else token
        # httpx masks the Authorization header in its reprs; the client keeps no other copy.
        headers = {"Authorization": f"Bearer {secret}"} if secret else {}
        self._http = httpx.Client(base_url=base_url.rstrip("/"), headers=headers, timeout=request_timeout)
        self._path = f"{API_PREFIX}/curricula/{curriculum}"
        log_path = os.environ.get(RESULT_LOG_VARIABLE) if result_log is None else result_log
        self._delivery_log = _DeliveryLog(log_path, curriculum) if log_path else None

        self._task_lock = threading.Lock()
        self._tasks: deque[Assignment] = deque()
        self._recent: deque[Task] = deque(maxlen=recent_tasks)
        self._offline_turn = itertools.count()
        self._offline = False

        self._results: deque[ResultItem] = deque()
        self._burst_dropped = 0
        self._results_changed = threading.Condition()
        self._stop = threading.Event()
        self._flushing = 0
        self._fatal: TeacherRequestError | None = None
        self.delivered = 0
        """Results the service has acknowledged (accepted or already known)."""
        self.already_stored = 0
        """Acknowledged results the service already held: resends after an answer that was lost (the
        service stored the batch, then died or the connection dropped before the answer came)."""
        self.rejected = 0
        """Results the service refused as invalid; dropped (see module doc)."""
        self.offline_results = 0
        """Results of offline assignments; not sent."""
        self.dropped_results = 0
        """Results dropped, oldest first, because ``max_buffered_results`` were waiting (see module doc)."""
        self._sender = threading.Thread(target=self._deliver_forever, name="teacher-results", daemon=True)
        self._sender.start()

    def register(
        self,
        teacher: TeacherKind,
        space: TaskSpace,
        params: Mapping[str, Any] | None = None,
        seed: int = 0,
        timeout: float = 30.0,
    ) -> CurriculumInfo:
        """Create the curriculum, or confirm the identical one exists (a restart can call this again)."""
        spec = CurriculumSpec(
            teacher=teacher,
            space=[ParameterSpec.from_parameter(p) for p in space.parameters],
            params=dict(params or {}),
            seed=seed,
        )
        answer = self._call("PUT", self._path, spec.model_dump(mode="json"), deadline=time.monotonic() + timeout)
        return CurriculumInfo.model_validate(answer)

    def info(self, timeout: float = 10.0) -> CurriculumInfo:
        return CurriculumInfo.model_validate(self._call("GET", self._path, deadline=time.monotonic() + timeout))

    def state(self, recent: int | None = None, timeout: float = 10.0) -> CurriculumState:
        path = f"{self._path}/state" + ("" if recent is None else f"?recent={recent}")
        return CurriculumState.model_validate(self._call("GET", path, deadline=time.monotonic() + timeout))

    def next_task(self) -> Assignment:
        """The next task: prefetched, freshly drawn, or offline when the teacher is unreachable."""
        with self._task_lock:
            if not self._tasks:
                self._refill()
            if self._tasks:
                return self._tasks.popleft()
            if not self._recent:
                raise TeacherUnavailable(
                    f"no task from {self._http.base_url} within {self.task_timeout} s, and none issued before"
                )
            recent = list(self._recent)
            return Assignment(None, dict(recent[next(self._offline_turn) % len(recent)]))

    def _refill(self) -> None:
        patience = 0.0 if self._offline else self.task_timeout
        try:
            answer = self._call(
                "POST", f"{self._path}/tasks", {"count": self.prefetch}, deadline=time.monotonic() + patience
            )
        except TeacherUnavailable as error:
            if not self._offline:
                log.warning("teacher unreachable; running offline episodes until it answers: %s", error)
            self._offline = True
            return
        self._offline = False
        for task in TaskBatch.model_validate(answer).tasks:
            self._tasks.append(Assignment(task.task_id, task.params, task.score_only))
            self._recent.append(task.params)

    def report(
        self,
        assignment: Assignment,
        reward: float,
        success: bool | None = None,
        length: int | None = None,
        score: float | None = None,
    ) -> None:
        """Queue an episode's result for delivery, with the learner's ``score`` for the level kinds
        when it has one (see ``ResultItem.score``); raises ``ValueError`` for a non-finite reward or score."""
        if self._fatal is not None:
            raise self._fatal
        if not math.isfinite(reward):
            raise ValueError(f"reward must be finite, got {reward}")
        if score is not None and not math.isfinite(score):
            raise ValueError(f"score must be finite, got {score}")
        with self._results_changed:
            if assignment.task_id is None:
                self.offline_results += 1
                return
            self._results.append(
                ResultItem(task_id=assignment.task_id, reward=reward, success=success, length=length, score=score)
            )
            burst_starts = len(self._results) > self.max_buffered_results and self._drop_oldest()
            self._results_changed.notify_all()
        if burst_starts:
            log.warning(
                "%d results are waiting for the teacher at %s, the most this client keeps (max_buffered_results): "
                "dropping the oldest for each new one until it takes results again",
                self.max_buffered_results,
                self._http.base_url,
            )

    def _drop_oldest(self) -> bool:
        """Drop the oldest result (with the lock held); True if a burst of drops starts.

        The oldest may be in the batch the sender is delivering. It still goes out with it, and
        settling the batch then pops as many results from the head, the next oldest: what stays
        waiting is the newest, and the count of lost results is the same."""
        self._results.popleft()
        self.dropped_results += 1
        self._burst_dropped += 1
        return self._burst_dropped == 1

    @property
    def pending(self) -> int:
        """Results handed over and not yet acknowledged by the service."""
        with self._results_changed:
            return len(self._results)

    def flush(self, timeout: float | None = None) -> bool:
        """Wait until every queued result is delivered; False if some are still pending at timeout."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._results_changed:
            self._flushing += 1
            self._results_changed.notify_all()
            try:
                while self._results:
                    if self._fatal is not None:
                        raise self._fatal
                    remaining = None if deadline is None else deadline - time.monotonic()
                    if remaining is not None and remaining <= 0:
                        return False
                    self._results_changed.wait(remaining)
            finally:
                self._flushing -= 1
        return True

    def close(self, timeout: float = 30.0) -> int:
        """Deliver what is left (up to ``timeout``), stop, and return how many results were not delivered."""
        try:
            self.flush(timeout)
        except TeacherRequestError as error:
            log.error("closing with undeliverable results: %s", error)
        self._stop.set()
        with self._results_changed:
            self._results_changed.notify_all()
        self._sender.join()
        self._http.close()
        left = len(self._results)
        if left:
            log.warning("%d results were not delivered to %s", left, self._http.base_url)
        return left

    def __enter__(self) -> TeacherClient:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _deliver_forever(self) -> None:
        attempt = 0
        while not self._stop.is_set():
            with self._results_changed:
                while not self._results and not self._stop.is_set():
                    self._results_changed.wait()
                batch = list(itertools.islice(self._results, MAX_RESULTS_PER_REQUEST))
            if not batch:
                continue
            try:
                ack = ResultAck.model_validate(
                    self._send("POST", f"{self._path}/results", {"results": [item.model_dump() for item in batch]})
                )
            except _Transient as error:
                log.info("results not delivered yet (%d pending): %s", self.pending, error)
                self._stop.wait(self.backoff.delay(attempt))
                attempt += 1
                continue
            except TeacherRequestError as error:
                invalid = _invalid_items(error, len(batch))
                if not invalid:
                    self._fail(error)
                    self._stop.wait(self.backoff.cap_s)
                    continue
                log.error("the teacher rejected %d result(s) as invalid: %s", len(invalid), error)
                self._settle(batch, keep=[item for i, item in enumerate(batch) if i not in invalid])
                self.rejected += len(invalid)
                continue
            except Exception:  # this thread must outlive any surprise, or results would stop moving
                log.exception("unexpected failure delivering results; retrying")
                self._stop.wait(self.backoff.delay(attempt))
                attempt += 1
                continue
            attempt = 0
            self._fatal = None
            if self._delivery_log is not None:
                self._delivery_log.write(
                    acknowledged=[item.task_id for item in batch],
                    accepted=ack.accepted,
                    duplicates=ack.duplicates,
                    expired=ack.expired,
                )
            self.delivered += len(batch)
            self.already_stored += ack.duplicates
            self._settle(batch, keep=[])
            self._end_drop_burst()
            self._let_results_gather()

    def _let_results_gather(self) -> None:
        """Wait ``report_interval`` before the next delivery; a flush, a close or a full batch ends it."""
        deadline = time.monotonic() + self.report_interval
        with self._results_changed:
            while not (self._stop.is_set() or self._flushing or len(self._results) >= MAX_RESULTS_PER_REQUEST):
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return
                self._results_changed.wait(remaining)

    def _settle(self, batch: list[ResultItem], keep: list[ResultItem]) -> None:
        """Drop a sent batch from the head of the buffer, putting back what is to be resent."""
        with self._results_changed:
            for _ in batch:
                self._results.popleft()
            self._results.extendleft(reversed(keep))
            self._results_changed.notify_all()

    def _end_drop_burst(self) -> None:
        with self._results_changed:
            dropped, self._burst_dropped = self._burst_dropped, 0
        if dropped:
            log.warning(
                "the teacher takes results again; %d results were dropped while it did not (%d by this client in all)",
                dropped,
                self.dropped_results,
            )

    def _fail(self, error: TeacherRequestError) -> None:
        log.error("results cannot be delivered: %s", error)
        with self._results_changed:
            self._fatal = error
            self._results_changed.notify_all()

    def _call(self, method: str, path: str, payload: Any = None, *, deadline: float) -> Any:
        """One request, retried on transient failures until ``deadline``."""
        for attempt in itertools.count():
            try:
                return self._send(method, path, payload)
            except _Transient as error:
                wait = self.backoff.delay(attempt)
                if time.monotonic() + wait > deadline:
                    raise TeacherUnavailable(f"{method} {path}: {error}") from None
                time.sleep(wait)
        raise AssertionError("unreachable")

    def _send(self, method: str, path: str, payload: Any = None) -> Any:
        try:
            response = self._http.request(method, path, json=payload)
        except httpx.TransportError as error:
            raise _Transient(f"{type(error).__name__}: {error}") from None
        if response.status_code >= 500 and self._delivery_log is not None:
            self._delivery_log.write(status=response.status_code, method=method, path=path, detail=_detail(response))
        if response.status_code >= 500 or response.status_code in _RETRYABLE_STATUS:
            raise _Transient(f"HTTP {response.status_code}: {_detail(response)}")
        if response.status_code >= 400:
            raise TeacherRequestError(response.status_code, _detail(response), method, path)
        try:
            return response.json()
        except ValueError:
            raise _Transient(f"HTTP {response.status_code} with a body that is not JSON") from None


def _detail(response: httpx.Response) -> Any:
    """The service's explanation (FastAPI's ``detail``), else the body as text."""
    try:
        answer = response.json()
    except ValueError:
        return response.text
    return answer.get("detail", response.text) if isinstance(answer, dict) else response.text


def _invalid_items(error: TeacherRequestError, batch_size: int) -> set[int]:
    """Indexes of the batch items a 422 names (``loc`` = body, results, index, ...)."""
    if error.status != 422 or not isinstance(error.detail, list):
        return set()
    named = set()
    for entry in error.detail:
        loc = entry.get("loc", []) if isinstance(entry, dict) else []
        if len(loc) >= 3 and loc[:2] == ["body", "results"] and isinstance(loc[2], int) and loc[2] < batch_size:
            named.add(loc[2])
    return named
