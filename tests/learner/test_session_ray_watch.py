"""The learner's watch on a joined Ray cluster (``learner.job.session.watch_ray_cluster``): a job whose
cluster was replaced under it (a Ray head restarted) exits with 75 for its supervisor to restart it,
where it used to wait for ever on actors the new head does not know (found by bench/chaos.py)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _watched(nodes: str, stop_first: bool = False) -> subprocess.CompletedProcess[str]:
    """A process watching with ``nodes`` as the cluster's answer, which then sleeps 3 s and exits 0."""
    program = textwrap.dedent(f"""
        import time
        from learner.job.session import watch_ray_cluster

        def nodes():
            {nodes}

        stop = watch_ray_cluster("mine", nodes, interval_s=0.05)
        if {stop_first}:
            stop.set()
        time.sleep(3)
    """)
    return subprocess.run([sys.executable, "-c", program], cwd=ROOT, capture_output=True, text=True, timeout=60)


def test_a_node_the_cluster_counts_alive_keeps_running() -> None:
    watched = _watched('return [{"NodeID": "other", "Alive": True}, {"NodeID": "mine", "Alive": True}]')
    assert watched.returncode == 0, watched.stderr


@pytest.mark.parametrize(
    "nodes",
    [
        'return [{"NodeID": "other", "Alive": True}]',  # a new head: this node unknown
        'return [{"NodeID": "mine", "Alive": False}]',
        'raise ConnectionError("GCS unreachable")',
    ],
)
def test_a_lost_cluster_ends_the_process_with_75_and_says_why(nodes: str) -> None:
    watched = _watched(nodes)
    assert watched.returncode == 75
    assert "lost the Ray cluster" in watched.stderr and "resumes from the last checkpoint" in watched.stderr


def test_a_stopped_watch_does_nothing() -> None:
    assert _watched('raise ConnectionError("shut down")', stop_first=True).returncode == 0
