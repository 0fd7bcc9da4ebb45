"""The teacher's status for the progress bar, read off the training loop.

Asked on the loop, a status request to a teacher that is down costs an iteration its timeout. A
thread asks instead, every few seconds with a short timeout, and the bar shows its latest answer,
so the loop never waits on HTTP for it.
"""

from __future__ import annotations

import threading
import time
from types import TracebackType

from common.client.teacher_client import TeacherClient, TeacherRequestError, TeacherUnavailable

POLL_INTERVAL_S = 5.0
STATUS_TIMEOUT_S = 2.0


class TeacherStatus:
    """Polls one curriculum's counters in a background thread; ``summary`` is the latest, at once.

    Reads need no token, so this client holds none.
    """

    def __init__(
        self, url: str, curriculum: str, interval_s: float = POLL_INTERVAL_S, timeout_s: float = STATUS_TIMEOUT_S
    ) -> None:
        self.interval_s = interval_s
        self.timeout_s = timeout_s
        self._client = TeacherClient(url, curriculum, request_timeout=timeout_s)
        self._summary = "teacher: no answer yet"
        self._down_since: float | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll_forever, name="teacher-status", daemon=True)

    @property
    def summary(self) -> str:
        """One line for the progress bar; never waits."""
        return self._summary

    def start(self) -> TeacherStatus:
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop polling; waits for a request in flight, at most ``timeout_s``."""
        self._stop.set()
        self._thread.join(self.timeout_s + 1.0)
        self._client.close(timeout=0)

    def __enter__(self) -> TeacherStatus:
        return self.start()

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, traceback: TracebackType | None
    ) -> None:
        self.close()

    def _poll_forever(self) -> None:
        while not self._stop.is_set():
            self._summary = self._poll()
            self._stop.wait(self.interval_s)

    def _poll(self) -> str:
        try:
            info = self._client.info(timeout=self.timeout_s)
        except TeacherUnavailable:
            if self._down_since is None:
                self._down_since = time.time()
            return f"teacher unreachable since {time.strftime('%H:%M:%S', time.localtime(self._down_since))}"
        except TeacherRequestError as error:
            return f"teacher answered HTTP {error.status}"
        self._down_since = None
        counters = info.counters
        summary = f"{info.config.teacher}: {counters.results_received:_} results"
        # Teachers without model fits (random, ADR, self-paced, CURROT, ...) would only ever show "0 fits".
        if counters.fits_completed or counters.fits_pending:
            summary += f", {counters.fits_completed} fits"
        return summary
