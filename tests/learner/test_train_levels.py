"""``kuka-curriculum train --env MiniGrid-...``: the project's PPO learner on a MiniGrid level family, as a
user runs it (the CLI, real Ray, the run's own teacher service), with robust PLR choosing the levels.

Every result reaches the teacher with its level (an int of the training set) and its score (PLR's positive
value loss); robust PLR's score-only episodes are played and reported but counted out of the update; the
evaluations play held-out levels; the checkpoint's policy is categorical."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

from test_train_e2e import metrics

from common.client.teacher_client import TeacherClient
from learner.core.checkpoint import latest_checkpoint, load_checkpoint
from learner.core.policy import policy_snapshot
from learner.job.session import curriculum_name
from learner.job.teacher_process import local_teacher_service

ENV_ID = "MiniGrid-DoorKey-5x5-v0"
LEVELS = 50
BATCH = 2 * 4 * 128


def test_train_on_minigrid_levels_with_robust_plr_sends_scores_and_keeps_score_only_out(tmp_path, ray_cluster):
    run_dir = tmp_path / "levels"
    command = [
        *(sys.executable, "-m", "kuka_curriculum", "train", "--env", ENV_ID, "--levels", str(LEVELS)),
        *("--teacher", "plr", "--teacher-param", "robust=true", "--total-steps", str(4 * BATCH)),
        *("--workers", "2", "--envs-per-worker", "4", "--rollout-length", "128", "--max-episode-steps", "60"),
        *("--eval-every", "2", "--eval-episodes", "4", "--checkpoint-every", "2"),
        *(
            "--ppo",
            "gamma=0.99",
            "--ppo",
            "gae_lambda=0.95",
            "--ppo",
            "entropy_coef=0.01",
            "--ppo",
            "minibatch_size=256",
        ),
        *("--run-dir", str(run_dir), "--ray-address", ray_cluster),
    ]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr

    checkpoint = load_checkpoint(latest_checkpoint(run_dir))
    assert checkpoint.config.env == ENV_ID and checkpoint.config.levels == LEVELS
    assert checkpoint.counters.steps == 4 * BATCH
    snapshot = policy_snapshot(checkpoint)
    assert snapshot.spec.categorical and snapshot.spec.action_dim == 7 and snapshot.spec.obs_dim == 147

    records = metrics(run_dir)
    assert [r["step"] for r in records] == [BATCH * k for k in range(1, 5)]
    # Robust PLR first plays every new level for its score alone: those episodes are counted, not trained on.
    assert sum(r["train/score_only_episodes"] for r in records) > 0
    assert sum(r["train/episodes"] for r in records) == checkpoint.counters.episodes
    evaluated = [r for r in records if "eval/success_rate" in r]
    assert len(evaluated) == 2 and all(0.0 <= r["eval/success_rate"] <= 1.0 for r in evaluated)

    with local_teacher_service(run_dir) as url, TeacherClient(url, curriculum_name(run_dir)) as teacher:
        state = teacher.state(recent=1000)
        info = teacher.info()
    assert info.counters.results_received == checkpoint.counters.episodes - checkpoint.counters.offline_episodes > 0
    assert [p.model_dump(include={"name", "type", "low", "high"}) for p in state.curriculum.config.space] == [
        {"name": "level", "type": "integer", "low": 0, "high": LEVELS - 1}
    ]
    results = state.recent_results
    assert results and all(isinstance(r.params["level"], int) and 0 <= r.params["level"] < LEVELS for r in results)
    assert all(r.score is not None and math.isfinite(r.score) and r.score >= 0 for r in results), "every score sent"
    assert any(r.score > 0 for r in results)
    assert Path(done.stdout.strip().splitlines()[-1].removeprefix("final checkpoint:").strip()) == checkpoint.path
