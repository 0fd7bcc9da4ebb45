"""examples/rllib_kuka_alp_gmm.py: real RLlib PPO with 2 env runners, on the session's Ray cluster.

RLlib counts the episodes its env runners finished; the service must hold a result for each.
"""

from __future__ import annotations

import json

from example_runner import curriculum_state, finish, start_example

CURRICULUM = "kuka-rllib-alp-gmm"
TOTAL_STEPS = 3000


def test_rllib_ppo_with_two_env_runners_reports_every_episode(teacher, ray_cluster):
    example = start_example(
        "rllib_kuka_alp_gmm.py",
        *("--teacher-url", teacher.url, "--ray-address", ray_cluster, "--env-runners", "2"),
        *("--total-steps", str(TOTAL_STEPS), "--batch-steps", "1000", "--max-episode-steps", "100"),
    )
    output = finish(example, timeout=480)
    assert f"watch the curriculum at {teacher.url}/curricula/{CURRICULUM}" in output

    summary = json.loads(output.strip().splitlines()[-1])
    assert summary["env_steps"] >= TOTAL_STEPS
    assert summary["episodes"] >= TOTAL_STEPS // 100 - 2, "RLlib finished its episodes"
    counters = curriculum_state(teacher, CURRICULUM)["curriculum"]["counters"]
    assert counters["results_received"] == summary["episodes"] == summary["results_received"]
