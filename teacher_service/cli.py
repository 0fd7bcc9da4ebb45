"""``kuka-curriculum serve``: run the teacher service."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from teacher_service.core.config import Settings


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", help="interface to bind (default 127.0.0.1, env KC_HOST)")
    parser.add_argument("--port", type=int, help="port (default 8000, env KC_PORT)")
    parser.add_argument("--db", type=Path, help="SQLite database (default runs/teacher.db, env KC_DB)")
    parser.add_argument(
        "--fit-processes",
        type=int,
        help="processes running teacher model fits, 1 to 8; each curriculum fits one at a time (default 2, "
        "env KC_FIT_PROCESSES)",
    )
    parser.add_argument(
        "--fit-timeout",
        type=float,
        metavar="SECONDS",
        help="abandon a fit running longer, 1 to 3600; the teacher keeps its last model (default 60, "
        "env KC_FIT_TIMEOUT_S)",
    )
    parser.add_argument(
        "--log-level",
        choices=["critical", "error", "warning", "info", "debug"],
        help="log level (default info, env KC_LOG_LEVEL)",
    )


def settings_from(args: argparse.Namespace) -> Settings:
    """Flags override ``KC_`` environment variables, which override the defaults."""
    flags = {
        "host": args.host,
        "port": args.port,
        "db": args.db,
        "fit_processes": args.fit_processes,
        "fit_timeout_s": args.fit_timeout,
        "log_level": args.log_level,
    }
    return Settings(**{name: value for name, value in flags.items() if value is not None})


def _explain(problem: Mapping[str, Any]) -> str:
    """One settings error in a line, named by its environment variable."""
    message = str(problem["msg"]).removeprefix("Value error, ")
    variable = "KC_" + "_".join(str(part) for part in problem["loc"][:1]).upper()
    return message if message.startswith(variable) else f"{variable}: {message}"


def run(args: argparse.Namespace) -> int:
    import uvicorn
    from pydantic import ValidationError

    from teacher_service.app import create_app

    try:
        settings = settings_from(args)
    except ValidationError as error:
        for problem in error.errors():
            print(f"kuka-curriculum serve: error: {_explain(problem)}", file=sys.stderr)
        return 2
    logging.basicConfig(level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    uvicorn.run(
        create_app(settings),
        host=settings.host,
        port=settings.port,
        log_level=settings.log_level,
        access_log=False,
    )
    return 0
