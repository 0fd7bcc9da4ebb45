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
    """SQLite database holding every curriculum's history; a restart loads its newest snapshots."""
    teacher_token: SecretStr | None = None
    """When set, every PUT and POST must carry ``Authorization: Bearer <token>``."""
    max_body_bytes: int = Field(default=1 << 20, ge=1024)
    """Larger request bodies are refused with 413 before they are read."""
    sqlite_synchronous: Literal["FULL", "NORMAL"] = "FULL"
    """FULL syncs every commit to disk (survives power loss); NORMAL survives process crashes only."""
    recent_results: int = Field(default=2000, ge=0)
    """Results per curriculum kept in memory for ``/state``."""
    snapshot_every: int = Field(default=1000, ge=1, le=1_000_000)
    """Results between two stored teacher snapshots: a restart replays at most about this many."""
    rate_window_s: float = Field(default=10.0, gt=0)
    """Window over which ``results_per_second`` is measured."""
    log_level: Literal["critical", "error", "warning", "info", "debug"] = "info"
