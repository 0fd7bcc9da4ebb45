"""examples/sb3_kuka_alp_gmm.py: real SB3 PPO with 2 SubprocVecEnv workers, and a teacher restart mid-run.

SB3's Monitor files count the episodes independently of the wrapper, each with its task id; the
service must hold a result for exactly the episodes that ran a task it issued.
"""

from __future__ import annotations

import csv
import time
from pathlib import Path

from example_runner import curriculum_state, finish, results_received, start_example

from common.families.kuka import KUKA_TEACHER_PARAMS

CURRICULUM = "kuka-sb3-alp-gmm"
TOTAL_STEPS = 8_192
EPISODE_STEPS = 100
RESULTS_BEFORE_RESTART = 10


def monitor_task_ids(log_dir: Path) -> list[str]:
    """The task id of every episode SB3's Monitor recorded ("" for an offline task)."""
    ids = []
    for path in sorted(log_dir.glob("env-*.monitor.csv")):
        with path.open() as file:
            next(file)  # Monitor's JSON header line
            ids += [row["task_id"] for row in csv.DictReader(file)]
    return ids


def test_sb3_ppo_reports_every_episode_across_a_teacher_restart(teacher, tmp_path):
    log_dir = tmp_path / "run"
    example = start_example(
        "sb3_kuka_alp_gmm.py",
        *("--teacher-url", teacher.url, "--total-steps", str(TOTAL_STEPS), "--envs", "2"),
        *("--n-steps", "512", "--max-episode-steps", str(EPISODE_STEPS), "--log-dir", str(log_dir)),
    )
    deadline = time.monotonic() + 120
    while results_received(teacher, CURRICULUM) < RESULTS_BEFORE_RESTART:
        assert example.poll() is None and time.monotonic() < deadline, "the example ended before the restart"
        time.sleep(0.2)
    teacher.kill()
    assert example.poll() is None, "the restart happens in the middle of training"
    time.sleep(1.0)
    teacher.start()
    before_close = results_received(teacher, CURRICULUM)

    output = finish(example, timeout=300)
    assert f"watch the curriculum at {teacher.url}/curricula/{CURRICULUM}" in output
    assert (log_dir / "ppo_kuka.zip").exists()

    episodes = monitor_task_ids(log_dir)
    issued = [task_id for task_id in episodes if task_id]
    assert len(episodes) >= TOTAL_STEPS // EPISODE_STEPS - 2, "SB3 finished its episodes"
    assert len(episodes) - len(issued) <= len(episodes) // 4, "offline episodes only while the teacher was down"
    state = curriculum_state(teacher, CURRICULUM)
    assert state["curriculum"]["counters"]["results_received"] == len(issued) > before_close
    assert sorted(result["task_id"] for result in state["recent_results"]) == sorted(issued)
    assert state["curriculum"]["config"]["teacher"] == "alp-gmm"
    kuka_defaults = KUKA_TEACHER_PARAMS["alp-gmm"]
    registered = state["curriculum"]["config"]["params"]
    assert {name: registered.get(name) for name in kuka_defaults} == kuka_defaults, "the training CLI's defaults"
