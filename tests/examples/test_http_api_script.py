"""examples/http_api.sh: the HTTP API with curl and jq, run as a user would, with the token."""

from __future__ import annotations

import json
import os
import shutil
import subprocess

import pytest
from example_runner import EXAMPLES, curriculum_state, finish, start_example

from common.client.curriculum_wrapper import TOKEN_VARIABLE
from teacher_service.teachers import TEACHER_KINDS

pytestmark = pytest.mark.skipif(not (shutil.which("curl") and shutil.which("jq")), reason="needs curl and jq")


def test_the_script_registers_takes_tasks_posts_results_and_reads_the_state(teacher):
    output = finish(start_example("http_api.sh", teacher.url, "shell"), timeout=60)
    lines = output.splitlines()
    assert lines[0] == f"watch the curriculum at {teacher.url}/curricula/shell"
    tasks = [json.loads(line) for line in lines if line.startswith('{"task_id"')]
    assert len(tasks) == 3
    kinds = [line.split(":")[0].strip() for line in lines if line.startswith("  ")]
    assert kinds == sorted(TEACHER_KINDS), "step 0 lists every teacher kind"
    assert {"accepted": 3, "duplicates": 0, "expired": 0} in [
        json.loads(line) for line in lines if line.startswith("{")
    ]

    state = curriculum_state(teacher, "shell")
    assert state["curriculum"]["config"]["teacher"] == "alp-gmm"
    assert {r["task_id"]: r["reward"] for r in state["recent_results"]} == {
        task["task_id"]: pytest.approx(-10 * task["params"]["gravity"]) for task in tasks
    }
    finish(start_example("http_api.sh", teacher.url, "shell"), timeout=60)
    assert curriculum_state(teacher, "shell")["curriculum"]["counters"]["results_received"] == 6, "run again: joins"


def test_the_script_stops_at_a_refused_token_and_shows_why(teacher):
    script = subprocess.run(
        ["bash", str(EXAMPLES / "http_api.sh"), teacher.url, "shell-refused"],
        env={**os.environ, TOKEN_VARIABLE: "not-the-token"},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert script.returncode != 0
    assert "401" in script.stderr and "KC_TEACHER_TOKEN" in script.stderr, "the service's explanation is shown"
    assert "2. take 3 tasks" not in script.stdout, "nothing runs after the refusal"
