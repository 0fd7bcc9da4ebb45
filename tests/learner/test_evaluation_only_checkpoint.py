"""An evaluation-only checkpoint (what an archived run keeps for git): its policy acts exactly as the full
checkpoint's, ``evaluate`` and ``render`` read it, and training refuses to resume from it, saying why."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from tiny_checkpoint import save_untrained_checkpoint

from common.policy.actor_critic import InferencePolicy
from kuka_curriculum import main
from learner.core.checkpoint import (
    RESUME_ONLY_STATE,
    EvaluationOnlyCheckpointError,
    latest_checkpoint,
    load_checkpoint,
    save_evaluation_only,
)
from learner.core.policy import policy_snapshot, policy_spec_for
from learner.core.ppo import PPOLearner
from teacher_service.process import free_port


@pytest.fixture
def full(tmp_path):
    return save_untrained_checkpoint(tmp_path / "run")


def test_an_evaluation_only_checkpoint_keeps_the_policy_and_leaves_out_what_only_resuming_reads(full, tmp_path):
    slim = save_evaluation_only(full, tmp_path / "slim.pt")
    whole, kept = load_checkpoint(full), load_checkpoint(slim)

    assert not whole.evaluation_only and kept.evaluation_only
    assert set(kept.learner) == set(whole.learner) - set(RESUME_ONLY_STATE) == {"network", "normalizer", "version"}
    assert kept.counters == whole.counters and kept.config == whole.config
    assert torch.load(full, weights_only=True)["learner"]["optimizer"], "the source is left as it was"
    ours, theirs = policy_snapshot(kept), policy_snapshot(whole)
    observations = np.random.default_rng(0).normal(size=(8, ours.spec.obs_dim)).astype(np.float32)
    acted = InferencePolicy(ours, seed=2).act(observations)
    for mine, original in zip(acted, InferencePolicy(theirs, seed=2).act(observations), strict=True):
        assert np.array_equal(mine, original)

    # In place (as the archive slims a run's final checkpoint), under the same name.
    assert save_evaluation_only(full, full) == full and load_checkpoint(full).evaluation_only


def test_evaluate_and_render_read_an_evaluation_only_checkpoint_as_the_full_one(full, tmp_path, capsys):
    slim = save_evaluation_only(full, tmp_path / "slim.pt")
    flags = ["--episodes", "2", "--seed", "3", "--processes", "1", "--max-episode-steps", "15"]
    for name, path in (("full", full), ("slim", slim)):
        assert main(["evaluate", str(path), *flags, "--json", str(tmp_path / f"{name}.json")]) == 0
    played = [json.loads((tmp_path / f"{name}.json").read_text())["per_episode"] for name in ("full", "slim")]
    assert played[0] == played[1]

    gif = tmp_path / "slim.gif"
    assert main(["render", str(slim), "--out", str(gif), "--episodes", "1", "--max-episode-steps", "8"]) == 0
    assert gif.stat().st_size > 0
    capsys.readouterr()


def test_training_refuses_to_resume_from_an_evaluation_only_checkpoint(full, capsys):
    save_evaluation_only(full, full)
    run_dir = full.parent.parent

    unreachable_ray = ["--ray-address", f"127.0.0.1:{free_port()}"]  # were the checkpoint let through, it stops there
    for flag in ("--resume", "--resume-if-exists"):
        assert main(["train", flag, "--run-dir", str(run_dir), *unreachable_ray]) == 2
        error = capsys.readouterr().err
        assert f"{full} is an evaluation-only checkpoint" in error and "cannot resume" in error

    # Below the command too (a tune's trial resumes through the trainer): the learner refuses the state.
    checkpoint = load_checkpoint(latest_checkpoint(run_dir))
    learner = PPOLearner(policy_spec_for(checkpoint.config.env, checkpoint.config.ppo), checkpoint.config.ppo, 0)
    with pytest.raises(EvaluationOnlyCheckpointError, match="evaluation-only checkpoint"):
        learner.load_state_dict(checkpoint.learner)
