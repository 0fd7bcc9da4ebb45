"""A learner killed while it writes a checkpoint: the run resumes from the last whole one."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from learner.core.checkpoint import CHECKPOINT_DIR, latest_checkpoint, load_checkpoint

WRITER = """
import sys
from pathlib import Path
from learner.core.checkpoint import Counters, save_checkpoint
from learner.core.config import PPOConfig, TrainConfig
from common.kuka import ENV_ID
from learner.core.policy import policy_spec_for
from learner.core.ppo import PPOLearner

config = TrainConfig(teacher="fixed", ppo=PPOConfig(hidden_sizes=(1024, 1024)))
learner = PPOLearner(policy_spec_for(ENV_ID, config.ppo), config.ppo, 0)
state = learner.state_dict()
for step in range(1, 10_000):
    save_checkpoint(Path(sys.argv[1]), state, Counters(iteration=step, steps=step * 100), config)
    print(step, flush=True)
"""


def test_a_learner_killed_mid_write_resumes_from_its_last_whole_checkpoint(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    partial_seen = False
    for _ in range(5):
        writer = subprocess.Popen(
            [sys.executable, "-c", WRITER, str(tmp_path)], stdout=subprocess.PIPE, text=True, cwd=Path.cwd()
        )
        assert writer.stdout is not None
        writer.stdout.readline()  # one checkpoint is whole: the kills land among the later writes
        time.sleep(float(rng.uniform(0.0, 0.3)))
        writer.send_signal(signal.SIGKILL)
        writer.wait()
        partial_seen |= any((tmp_path / CHECKPOINT_DIR).glob("*.partial"))
        latest = latest_checkpoint(tmp_path)
        assert latest is not None and latest.suffix == ".pt"
        loaded = load_checkpoint(latest)  # a truncated file would fail to load here
        assert loaded.counters.steps == loaded.counters.iteration * 100
    assert partial_seen, "no kill landed mid-write; the test did not test the case"
