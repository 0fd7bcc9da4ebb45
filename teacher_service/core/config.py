"""Service settings: defaults, overridden by ``KC_``-prefixed environment variables, overridden by flags."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from common.client.write_token import check_token

LOOPBACK_HOSTS = ("localhost", "127.0.0.1", "[::1]")
ANY_HOST = "*"


class Settings(BaseSettings):
    model_config = SettingsConfigDict(
        env_prefix="KC_", extra="ignore", hide_input_in_errors=True, use_attribute_docstrings=True
    )
    """Inputs stay out of error messages: one of them may be the token."""

    host: str = "127.0.0.1"
    """Interface to bind; the default keeps the service private to this machine."""
    port: int = Field(default=8000, ge=0, le=65535)
    db: Path = Path("runs/teacher.db")
    """SQLite database holding every curriculum's history; a restart loads its newest snapshots."""
    teacher_token: SecretStr | None = None
    """When set, every PUT and POST must carry ``Authorization: Bearer <token>``. A placeholder or
    a token shorter than 16 characters is refused at start-up; empty means none."""
    allowed_hosts: Annotated[list[str] | None, NoDecode] = None
    """Host names (the ``Host`` header without its port) the service answers; others get 400.
    Comma-separated or a JSON list; ``*`` allows any, ``*.example.org`` the subdomains of one. By default the
    loopback names without a token, so that no web page can reach a private service by DNS
    rebinding, and any host with one."""
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
    snapshot_every: int = Field(default=1000, ge=1, le=1_000_000)
    """Results between two stored teacher snapshots: a restart replays at most about this many."""
    rate_window_s: float = Field(default=10.0, gt=0)
    """Window over which ``results_per_second`` is measured."""
    fit_processes: int = Field(default=2, ge=1, le=8)
    """Processes running teacher model fits; a curriculum runs one fit at a time, so with a process
    per busy curriculum no curriculum's long fit delays another's."""
    fit_timeout_s: float = Field(default=60.0, ge=1.0, le=3600.0)
    """A fit running longer is abandoned and its process killed; the teacher keeps its last model."""
    log_level: Literal["critical", "error", "warning", "info", "debug"] = "info"

    @field_validator("teacher_token")
    @classmethod
    def _refuse_guessable_token(cls, token: SecretStr | None) -> SecretStr | None:
        if token is None or not token.get_secret_value():
            return None
        check_token(token.get_secret_value())
        return token

    @field_validator("allowed_hosts", mode="before")
    @classmethod
    def _split_host_list(cls, value: Any) -> Any:
        if isinstance(value, str):
            text = value.strip()
            return json.loads(text) if text.startswith("[") else [name for name in text.split(",") if name.strip()]
        return value

    @field_validator("allowed_hosts")
    @classmethod
    def _normalize_host_names(cls, names: list[str] | None) -> list[str] | None:
        if names is None:
            return None
        normalized = [_bracket_ipv6(name.strip().lower()) for name in names if name.strip()]
        if not normalized:
            raise ValueError(f"name at least one host, or {ANY_HOST!r} for any")
        return normalized

    def host_names(self) -> list[str]:
        """The host names answered: ``allowed_hosts``, or its default for the token setting."""
        if self.allowed_hosts is not None:
            return self.allowed_hosts
        return [ANY_HOST] if self.teacher_token is not None else list(LOOPBACK_HOSTS)


def _bracket_ipv6(name: str) -> str:
    """``::1`` as a ``Host`` header writes it, ``[::1]``."""
    return f"[{name}]" if ":" in name and not name.startswith("[") else name
