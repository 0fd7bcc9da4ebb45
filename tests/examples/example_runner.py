"""Run an example as a user would: as a script, with the teacher's token exported."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import httpx

from common.client.curriculum_wrapper import TOKEN_VARIABLE
from common.client.schemas import API_PREFIX
from teacher_service.process import ServiceProcess

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
TOKEN = "examples-test-token"


def start_example(script: str, *args: str) -> subprocess.Popen[str]:
    """``python examples/SCRIPT ARGS`` (``bash`` for a shell script), output merged into stdout."""
    interpreter = "bash" if script.endswith(".sh") else sys.executable
    return subprocess.Popen(
        [interpreter, str(EXAMPLES / script), *args],
        env={**os.environ, TOKEN_VARIABLE: TOKEN},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def finish(example: subprocess.Popen[str], timeout: float) -> str:
    """Wait for an example and return its output; fail with that output if it did not succeed."""
    try:
        output, _ = example.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        example.kill()
        output, _ = example.communicate()
        raise AssertionError(f"the example ran longer than {timeout} s:\n{output[-4000:]}") from None
    assert example.returncode == 0, f"the example exited with {example.returncode}:\n{output[-4000:]}"
    return output


def curriculum_state(teacher: ServiceProcess, curriculum: str) -> dict[str, Any]:
    return httpx.get(f"{teacher.url}{API_PREFIX}/curricula/{curriculum}/state", timeout=10).raise_for_status().json()


def results_received(teacher: ServiceProcess, curriculum: str) -> int:
    """0 until the curriculum exists."""
    response = httpx.get(f"{teacher.url}{API_PREFIX}/curricula/{curriculum}", timeout=10)
    return response.json()["counters"]["results_received"] if response.status_code == 200 else 0
