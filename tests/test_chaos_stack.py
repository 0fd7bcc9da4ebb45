"""Faults during real training, one after another: ``bench/chaos.py`` on the shared Docker stack (issue 60).

The engine, the image and the compose project are the ones every Docker test shares (tests/docker_stack.py).
The bench starts a short KUKA run on the stack with its override (the teacher's data on a size-limited
volume, the workers' delivery log), then does the faults of ``SCHEDULE`` in order, each once the stack
is back from the last and has trained two iterations more: the teacher and a Ray worker killed from
inside and stopped and started, the learner stopped and started, the teacher's volume filled until
writes are refused, the Ray head killed (its death takes the learner down, which must start again and
carry on). Then the run reaches its budget, and every one of the bench's criteria must pass: the budget
is reached, every result the workers' log says was acknowledged is stored exactly once, writes get a
503 with the reason while the disk is full and the service recovers by itself, each curriculum's live
state equals a replay of its stored results, and no role needs a hand to come back. The 30-minute
version, with faults drawn at random every minute and the disk full for two, and what it measured, is
on the results page (docs/results/service.md).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.docker_stack import ROOT, SharedStack, chaos, require

pytestmark = [pytest.mark.docker, pytest.mark.timeout(1800)]

ARTIFACTS = ROOT / "test-artifacts" / "chaos"
SCHEDULE = (
    "teacher:kill",
    "teacher:restart",
    "ray-worker:kill",
    "ray-worker:restart",
    "learner:restart",
    "disk-full",
    "ray-head:kill",
)
"""Every role killed from inside or stopped and started: each fault the random five minutes of this test
did before (a Ray worker's, the learner's and the teacher's stop and start, the head's kill, the full
disk) and the teacher's and a Ray worker's kill besides. The head's comes last: its death takes the
learner down with it, which then starts again from its checkpoint and finishes the budget."""
STEPS_BETWEEN = 4_096
"""Two iterations from one fault to the next, besides the wait for the last fault's role to be back."""
STEPS = 200_000
"""More than a fast machine (2,000 steps/s) trains before the head's death stops the learner: it trains
on while the teacher and the Ray workers come back and while the disk is full (~80 s, 160,000 steps)."""
RUN_SEED = 2
"""Its run, alp-gmm-seed2, is not one of test_docker_stack.py's (seeds 0 and 1) on the same stack."""
DISK_FULL_REFUSALS = 10
"""The disk is freed once this many of the probe's writes were refused with a 503 (the service takes
writes for up to ~20 s after the fill, until its database needs a page the disk lacks)."""


def test_the_stack_trains_through_every_fault_and_a_full_disk_and_loses_no_result(docker_stack: SharedStack) -> None:
    require(shutil.which("mkfs.ext4") is not None, "missing mkfs.ext4 (Debian package e2fsprogs)")
    require(Path("/dev/loop-control").exists(), "no loop devices: the teacher's size-limited volume needs one")
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    argv = [
        "--schedule", ",".join(SCHEDULE), "--steps-between", str(STEPS_BETWEEN), "--fault-every", "3",
        "--steps", str(STEPS), "--run-seed", str(RUN_SEED), "--aftermath", "30", "--finish-timeout", "600",
        "--disk-full-for", "90", "--disk-full-refusals", str(DISK_FULL_REFUSALS),
        "--min-faults", str(len(SCHEDULE) - 1), "--volume-mb", str(docker_stack.volume_mb),
        "--project", docker_stack.project, "--artifacts", str(ARTIFACTS),
    ]  # fmt: skip
    report = chaos.run_chaos(docker_stack, chaos.parse_args(argv), argv)
    (ARTIFACTS / "chaos.json").write_text(json.dumps(report, indent=1) + "\n")
    chaos.print_report(report)

    done = [f"{fault['role']}:{fault['kind']}" for fault in report["faults"] if fault["done"]]
    assert done == [entry for entry in SCHEDULE if entry != "disk-full"], report["faults"]
    late = [fault for fault in report["faults"] if fault["step_before"] >= STEPS]
    assert not late, f"faults after the learner had trained its budget: {late}"
    [head] = [fault for fault in report["faults"] if fault["role"] == "ray-head"]
    starts = [death["restarted_at"] for death in report["learner_deaths"]]
    assert any(start > head["started"] for start in starts), f"the learner outlived the head: started at {starts}"
    assert report["disk_full"]["probe_statuses"].get("503", 0) >= DISK_FULL_REFUSALS, report["disk_full"]
    failed = {name: c["detail"] for name, c in report["criteria"].items() if not c["pass"]}
    assert not failed, json.dumps(failed, indent=1)
