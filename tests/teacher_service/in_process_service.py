"""The teacher service served in this process: a real uvicorn on a free port serving the real app
over a real SQLite file, on an event loop of its own thread, so a test can reach into its store
(a full disk through SQLite's ``max_page_count``, injected failures)."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import uvicorn

from teacher_service.app import create_app
from teacher_service.core.config import Settings
from teacher_service.process import free_port
from teacher_service.store import Store

ANSWER_WITHIN_S = 10.0
"""Every request must be answered this soon, failure or not."""

T = TypeVar("T")

UNLIMITED_PAGES = 1073741823
"""SQLite's default ``max_page_count``."""


class InProcessService:
    """uvicorn serving ``create_app`` on a loop of its own thread; ``on_loop`` runs code there."""

    def __init__(self, db: Path, token: str | None = None, allowed_hosts: list[str] | None = None) -> None:
        self.app = create_app(Settings(db=db, teacher_token=token, allowed_hosts=allowed_hosts, log_level="warning"))
        self.port = free_port()
        self.server = uvicorn.Server(
            uvicorn.Config(self.app, host="127.0.0.1", port=self.port, log_level="warning", access_log=False)
        )
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_until_complete, args=(self.server.serve(),))

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def store(self) -> Store:
        store: Store = self.app.state.registry._store
        return store

    def on_loop(self, function: Callable[[], T]) -> T:
        """Run ``function`` on the service's event loop thread, where the store's connection lives."""

        async def call() -> T:
            return function()

        return asyncio.run_coroutine_threadsafe(call(), self.loop).result(ANSWER_WITHIN_S)

    def __enter__(self) -> InProcessService:
        self.thread.start()
        while not self.server.started:
            if not self.thread.is_alive():
                raise RuntimeError("the in-process service did not start")
            self.thread.join(0.05)
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.server.should_exit = True
        self.thread.join(30)
        self.loop.close()

    def fill_disk(self) -> None:
        """No room for new database pages (``max_page_count`` never goes below the current size)."""
        self.on_loop(lambda: self.store._db.execute("PRAGMA max_page_count = 1"))

    def free_disk(self) -> None:
        self.on_loop(lambda: self.store._db.execute(f"PRAGMA max_page_count = {UNLIMITED_PAGES}"))
