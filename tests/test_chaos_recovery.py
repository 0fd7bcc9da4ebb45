"""When ``bench/chaos.py`` counts a learner as back after a fault, and when its schedule's next fault may
come, on containers' states as Docker reports them and the run's real metrics file; the Docker run
itself is tests/test_chaos_stack.py."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import chaos  # noqa: E402  (bench/ is scripts, not a package)

CONTAINER = "learner-1"


class InspectedStack(chaos.Stack):
    """A stack whose ``docker inspect`` answer is given: the learner container's state alone."""

    def __init__(self, scratch: Path, state: dict[str, Any]) -> None:
        super().__init__(scratch, "kcchaos", volume_mb=16)
        self.run_name = "run"
        self.state = state

    def containers(self, service: str) -> list[str]:
        return [CONTAINER] if service == "learner" else []

    def inspect(self, *containers: str) -> dict[str, dict[str, Any]]:
        return {CONTAINER: self.state} if CONTAINER in containers else {}


def learner_state(status: str, exit_code: int, started_at: float) -> dict[str, Any]:
    return {"status": status, "running": status == "running", "exit_code": exit_code, "started_at": started_at}


def log_record(stack: chaos.Stack, at: float, step: int = 1000) -> None:
    (stack.runs / stack.run_name).mkdir(parents=True, exist_ok=True)
    with (stack.runs / stack.run_name / "metrics.jsonl").open("a") as metrics:
        metrics.write(json.dumps({"step": step, "time": at}) + "\n")


@pytest.fixture
def fault() -> chaos.Fault:
    return chaos.Fault(at_s=180.0, role="learner", kind="restart", container=CONTAINER, started=time.time() - 20)


def test_a_learner_that_restarted_and_logged_an_iteration_is_back(tmp_path: Path, fault: chaos.Fault) -> None:
    stack = InspectedStack(tmp_path, learner_state("running", 0, fault.started + 5))
    assert not chaos.role_is_back(stack, fault)
    log_record(stack, fault.started + 10)
    assert chaos.role_is_back(stack, fault)


def test_a_learner_stopped_in_its_last_iteration_is_back_when_its_restart_finds_nothing_left(
    tmp_path: Path, fault: chaos.Fault
) -> None:
    """Started again after the fault, it exited 0 with no new record: its budget was spent (CI, 2026-12-03)."""
    stack = InspectedStack(tmp_path, learner_state("exited", 0, fault.started + 5))
    log_record(stack, fault.started - 1)
    assert chaos.role_is_back(stack, fault)


@pytest.mark.parametrize(
    ("status", "exit_code", "started_after_fault_s"),
    [("exited", 143, 5.0), ("exited", 0, -30.0), ("restarting", 0, 5.0), ("running", 0, -30.0)],
    ids=["failed-after-restart", "exited-before-the-fault", "restarting", "never-restarted"],
)
def test_a_learner_that_failed_or_never_restarted_is_not_back(
    tmp_path: Path, fault: chaos.Fault, status: str, exit_code: int, started_after_fault_s: float
) -> None:
    stack = InspectedStack(tmp_path, learner_state(status, exit_code, fault.started + started_after_fault_s))
    log_record(stack, time.time())  # even with an iteration logged since the fault
    assert not chaos.role_is_back(stack, fault)


def test_the_next_scheduled_fault_waits_for_the_last_ones_role_and_for_the_learner_to_train_on(
    tmp_path: Path, fault: chaos.Fault
) -> None:
    stack = InspectedStack(tmp_path, learner_state("running", 0, fault.started + 5))
    fault.done = True
    log_record(stack, fault.started + 10, step=9000)
    assert not chaos.ready_for_next(stack, fault, step=9000), "the learner is not back yet"
    fault.back_s = 10.0
    assert chaos.ready_for_next(stack, fault, step=9000)
    assert not chaos.ready_for_next(stack, fault, step=9001), "the learner has not trained that far yet"


def test_a_learner_that_finished_its_run_holds_no_scheduled_fault_up(tmp_path: Path) -> None:
    """Its faults are then skipped and counted as not done, which fails the run: its budget was too small."""
    stack = InspectedStack(tmp_path, learner_state("exited", 0, time.time()))
    assert chaos.ready_for_next(stack, None, step=10**9)


def test_a_schedule_names_the_faults_the_bench_knows() -> None:
    schedule = chaos.parse_schedule("teacher:kill, disk-full,ray-head:restart")
    assert schedule == [("teacher", "kill"), ("disk-full", ""), ("ray-head", "restart")]
    for wrong in ("teacher", "teacher:explode", "tensorboard:kill", "disk-full:kill", ""):
        with pytest.raises(argparse.ArgumentTypeError):
            chaos.parse_schedule(wrong)
