"""Service settings: defaults, overridden by ``KC_``-prefixed environment variables, overridden by flags."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="KC_", extra="ignore")

    host: str = "127.0.0.1"
    """Interface to bind; the default keeps the service private to this machine."""
    port: int = Field(default=8000, ge=0, le=65535)
    db: Path = Path("runs/teacher.db")
    """SQLite database holding every curriculum's history; a restart replays it."""
    teacher_token: SecretStr | None = None
    """When set, every PUT and POST must carry ``Authorization: Bearer <token>``."""
    max_body_bytes: int = Field(default=1 << 20, ge=1024)
    """Larger request bodies are refused with 413 before they are read."""
    sqlite_synchronous: Literal["FULL", "NORMAL"] = "FULL"
    """FULL syncs every commit to disk (survives power loss); NORMAL survives process crashes only."""
    recent_results: int = Field(default=2000, ge=0)
    """Results per curriculum kept in memory for ``/state``."""
    task_ttl_s: float = Field(default=3600.0, gt=0, le=30 * 86400)
    """A task handed out this many seconds ago with no result expires: a late result for it is
    counted as ``expired`` and ignored (the teacher already moved on)."""
    task_window: int = Field(default=10_000, ge=1, le=1_000_000)
    """A task also expires once this many later tasks of its curriculum have been handed out, which
    bounds each curriculum's memory of tasks awaiting results."""
    rate_window_s: float = Field(default=10.0, gt=0)
    """Window over which ``results_per_second`` is measured."""
    fit_processes: int = Field(default=2, ge=1, le=8)
    """Processes running teacher model fits; a curriculum runs one fit at a time, so with a process
    per busy curriculum no curriculum's long fit delays another's."""
    fit_timeout_s: float = Field(default=60.0, ge=1.0, le=3600.0)
    """A fit running longer is abandoned and its process killed; the teacher keeps its last model."""
    log_level: Literal["critical", "error", "warning", "info", "debug"] = "info"
