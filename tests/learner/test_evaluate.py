"""``kuka-curriculum evaluate`` on a real checkpoint: figures, intervals, seeds, processes, bad input."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from ctrl_c import ctrl_c_as_the_pool_starts
from tiny_checkpoint import TINY_EPISODE_STEPS, save_untrained_checkpoint

from common.kuka import HARD_ENV_ID, HARD_V1_ENV_ID
from common.kuka.diagnostics import play_episode
from common.kuka.env import KukaGraspEnv, KukaGraspHardEnv, make_kuka_env
from common.kuka.scripted import scripted_action
from common.kuka.task_space import KUKA_HARD_TASK_SPACE, KUKA_HARD_V1_TASK_SPACE, KUKA_TASK_SPACE
from common.policy.actor_critic import InferencePolicy
from kuka_curriculum import main
from learner.commands.checkpoint_arguments import parse_task
from learner.core.checkpoint import load_checkpoint
from learner.core.policy import policy_snapshot
from learner.evaluation.checkpoint_evaluation import (
    EvaluationResult,
    describe_task,
    evaluate_policy,
    scripted_evaluation,
    significant,
)
from learner.evaluation.episode_diagnostics import success_by_band
from learner.evaluation.stats import mean_interval, wilson_interval
from rollout_worker.sampler import run_episodes


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return save_untrained_checkpoint(tmp_path_factory.mktemp("run"))


def test_evaluate_prints_and_writes_intervals_of_the_episodes_it_played(checkpoint, tmp_path, capsys):
    out = tmp_path / "eval" / "result.json"
    code = main(["evaluate", str(checkpoint), "--episodes", "5", "--seed", "7", "--processes", "1", "--json", str(out)])

    assert code == 0
    written = json.loads(out.read_text())
    per_episode = written["per_episode"]
    assert written["checkpoint"] == str(checkpoint) and written["steps"] == 512 and written["episodes"] == 5
    assert written["task"] == KUKA_TASK_SPACE.hardest()
    # The checkpoint's own episode limit applies unless another is given.
    assert all(1 <= length <= TINY_EPISODE_STEPS for length in per_episode["length"])

    returns = mean_interval(per_episode["return"])
    success = wilson_interval(sum(per_episode["success"]), 5)
    assert written["return"] == returns.to_dict() and written["success_rate"] == success.to_dict()
    printed = capsys.readouterr().out
    assert (
        f"hardest task, 5 episodes: return {returns.estimate:.2f} ± {returns.half_width:.2f} (95% CI), "
        f"success {success.estimate:.0%} [{success.low:.0%}, {success.high:.0%}] (Wilson 95%), "
        f"mean length {written['mean_length']:.0f}"
    ) in printed

    # Episode i is the deterministic policy's episode with seed 7 + i.
    env = KukaGraspEnv(max_steps=TINY_EPISODE_STEPS)
    expected = run_episodes(
        env, InferencePolicy(policy_snapshot(load_checkpoint(checkpoint))), KUKA_TASK_SPACE.hardest(), range(7, 12)
    )
    env.close()
    assert per_episode["return"] == [significant(episode.reward) for episode in expected]


def test_results_do_not_depend_on_how_many_processes_share_the_episodes(checkpoint):
    snapshot = policy_snapshot(load_checkpoint(checkpoint))
    task = parse_task("rnd_obj_ang=0.3")
    alone = evaluate_policy(snapshot, task, episodes=4, seed=3, processes=1, max_episode_steps=30, progress=False)
    shared = evaluate_policy(snapshot, task, episodes=4, seed=3, processes=2, max_episode_steps=30, progress=False)
    assert shared.episodes == alone.episodes and shared.diagnostics == alone.diagnostics
    assert len({episode.reward for episode in alone.episodes}) > 1, "different seeds should place the block differently"


def test_a_run_directory_means_its_latest_checkpoint_and_a_task_can_be_chosen(checkpoint, tmp_path, capsys):
    out = tmp_path / "easy.json"
    code = main(
        [
            "evaluate",
            str(checkpoint.parent.parent),
            "--episodes",
            "2",
            "--processes",
            "1",
            "--task",
            "easiest,jp2=1.1",
            "--max-episode-steps",
            "15",
            "--json",
            str(out),
        ]
    )
    assert code == 0
    written = json.loads(out.read_text())
    assert written["checkpoint"] == str(checkpoint)
    assert written["task"] == {**KUKA_TASK_SPACE.easiest(), "jp2": 1.1}
    assert max(written["per_episode"]["length"]) <= 15
    assert "easiest task with jp2=1.1, 2 episodes" in capsys.readouterr().out


def test_a_checkpoint_plays_the_environment_it_was_trained_on(checkpoint, tmp_path, capsys):
    hard = save_untrained_checkpoint(tmp_path / "hard-run", env=HARD_ENV_ID)
    out = tmp_path / "hard.json"
    assert main(["evaluate", str(hard), "--episodes", "3", "--processes", "2", "--json", str(out)]) == 0
    written = json.loads(out.read_text())
    assert written["env"] == HARD_ENV_ID and written["task"] == KUKA_HARD_TASK_SPACE.hardest()
    assert f"{HARD_ENV_ID}, hardest task, 3 episodes" in capsys.readouterr().out
    env = KukaGraspHardEnv(max_steps=TINY_EPISODE_STEPS)
    expected = run_episodes(
        env, InferencePolicy(policy_snapshot(load_checkpoint(hard))), KUKA_HARD_TASK_SPACE.hardest(), range(3)
    )
    env.close()
    assert written["per_episode"]["return"] == [significant(episode.reward) for episode in expected]

    assert main(["evaluate", str(hard), "--episodes", "1", "--task", "easiest,obj_far=0.5", "--json", str(out)]) == 0
    assert json.loads(out.read_text())["task"] == {**KUKA_HARD_TASK_SPACE.easiest(), "obj_far": 0.5}
    assert "easiest task with obj_far=0.5, 1 episodes" in capsys.readouterr().out
    # The book's environment has no such parameter.
    assert main(["evaluate", str(checkpoint), "--task", "obj_far=0.5"]) == 2
    assert "unknown task parameter(s) ['obj_far']" in capsys.readouterr().err


DIAGNOSTICS = ("block_x", "block_y", "block_yaw", "beyond_clamp", "touchdown_offset", "off_square_degrees")


def test_each_episode_records_where_its_block_lay_and_the_scripted_controller_plays_the_same_ones(tmp_path, capsys):
    hard = save_untrained_checkpoint(tmp_path / "v1-run", env=HARD_V1_ENV_ID)
    out = tmp_path / "both.json"
    flags = ["--episodes", "3", "--seed", "100000", "--processes", "1", "--json", str(out)]
    assert main(["evaluate", str(hard), "--scripted", *flags]) == 0
    written = json.loads(out.read_text())
    per_episode, scripted = written["per_episode"], written["scripted"]
    assert all(len(per_episode[name]) == 3 for name in DIAGNOSTICS)
    # Each per-episode column is one line of floats cut to six digits.
    lines = out.read_text().splitlines()
    assert sum(line.strip().startswith('"block_x": [') and line.endswith("],") for line in lines) == 2
    mantissas = [
        repr(value).split("e")[0].replace("-", "").replace(".", "").lstrip("0") for value in per_episode["block_x"]
    ]
    assert all(len(digits) <= 6 for digits in mantissas)
    # The same seeds put the block in the same places for the policy and the scripted controller.
    env = make_kuka_env(HARD_V1_ENV_ID)
    placements = []
    for seed in range(100000, 100003):
        env.reset(seed=seed, options={"task": KUKA_HARD_V1_TASK_SPACE.hardest()})
        placements.append(tuple(significant(value) for value in env.block_pose()))
    assert [tuple(per_episode[name][i] for name in DIAGNOSTICS[:3]) for i in range(3)] == placements
    assert scripted["controller"] == "scripted" and scripted["seed"] == 100000
    assert [scripted["per_episode"][name] for name in DIAGNOSTICS[:4]] == [
        per_episode[name] for name in DIAGNOSTICS[:4]
    ]
    # The bands in the file are those of its own episodes, and the result reads back whole.
    result = EvaluationResult.from_dict(written)
    assert len(result.diagnostics) == 3
    assert written["success_by_placement"] == [band.to_dict() for band in success_by_band(result.diagnosed())]
    assert EvaluationResult.from_dict(result.to_dict()) == result
    printed = capsys.readouterr().out
    assert "by placement: inside the clamp" in printed and "scripted controller, the same episodes:" in printed

    # Alone, on its default family, with that family's own step limit: the episodes play_episode plays.
    alone = tmp_path / "scripted.json"
    assert main(["evaluate", "--scripted", "--episodes", "2", "--seed", "100000", "--json", str(alone)]) == 0
    played = json.loads(alone.read_text())
    expected = [
        play_episode(env, KUKA_HARD_V1_TASK_SPACE.hardest(), scripted_action, seed) for seed in (100000, 100001)
    ]
    env.close()
    assert played["controller"] == "scripted" and played["env"] == HARD_V1_ENV_ID
    assert played["per_episode"]["success"] == [episode.success for episode in expected]
    assert played["per_episode"]["off_square_degrees"] == [
        significant(e.diagnostics.off_square_degrees) for e in expected
    ]
    assert played["per_episode"]["block_x"] == per_episode["block_x"][:2]
    # Played to its touchdowns, the wrist's turns are recorded and read back.
    turns = played["per_episode"]["touchdown_wrist_turn_degrees"]
    assert turns == [significant(e.diagnostics.touchdown_wrist_turn_degrees) for e in expected] and None not in turns
    assert [each.touchdown_wrist_turn_degrees for each in EvaluationResult.from_dict(played).diagnostics] == turns
    assert "scripted controller: KukaGraspHard-v1, hardest task, 2 episodes" in capsys.readouterr().out

    # Without a checkpoint there is nothing to evaluate but the scripted controller; a checkpoint plays its own env.
    assert main(["evaluate"]) == 2
    assert "give a CHECKPOINT, or --scripted" in capsys.readouterr().err
    assert main(["evaluate", str(hard), "--env", HARD_ENV_ID]) == 2
    assert f"the checkpoint was trained on {HARD_V1_ENV_ID}" in capsys.readouterr().err


def test_the_cached_scripted_controller_is_reused_only_for_the_same_episodes(tmp_path):
    cache = tmp_path / "scripted_evaluation.json"
    first = scripted_evaluation(cache, HARD_V1_ENV_ID, episodes=2, seed=7, processes=1, max_episode_steps=40)
    assert first.max_episode_steps == 40 and json.loads(cache.read_text())["controller"] == "scripted"
    written = cache.stat().st_mtime_ns
    assert scripted_evaluation(cache, HARD_V1_ENV_ID, episodes=2, seed=7, processes=1, max_episode_steps=40) == first
    assert cache.stat().st_mtime_ns == written
    # Another step limit plays the episodes again: a cut-short episode is not the one a longer limit plays.
    longer = scripted_evaluation(cache, HARD_V1_ENV_ID, episodes=2, seed=7, processes=1, max_episode_steps=60)
    assert longer.max_episode_steps == 60 and cache.stat().st_mtime_ns != written
    assert [episode.length for episode in first.episodes] == [40, 40]
    assert all(episode.length > 40 for episode in longer.episodes)


def test_task_strings():
    assert parse_task("hardest") == KUKA_TASK_SPACE.hardest()
    assert parse_task("easiest") == KUKA_TASK_SPACE.easiest()
    assert parse_task(" jp2 = 1.0 , rnd_obj_x=0.5") == {**KUKA_TASK_SPACE.hardest(), "jp2": 1.0, "rnd_obj_x": 0.5}
    assert describe_task(parse_task("jp2=1.0")) == "hardest task with jp2=1"
    assert parse_task("shaping=0.5", KUKA_HARD_TASK_SPACE) == {**KUKA_HARD_TASK_SPACE.hardest(), "shaping": 0.5}
    for text, message in [
        ("medium", "unknown task 'medium'"),
        ("jp2", "unknown task 'jp2'"),
        ("jp2=high", "'jp2' must be a number"),
        ("jp2=5", r"'jp2'=5.0 is outside its bounds"),
        ("grip=1", r"unknown task parameter\(s\) \['grip'\]"),
        ("jp2=1,jp2=1.1", "given twice"),
        ("", "empty task"),
    ]:
        with pytest.raises(ValueError, match=message):
            parse_task(text)


def test_bad_input_is_refused_in_one_line(checkpoint, tmp_path, capsys):
    assert main(["evaluate", str(tmp_path / "missing.pt")]) == 2
    assert f"no checkpoint at {tmp_path / 'missing.pt'}" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path)]) == 2
    assert "without checkpoints" in capsys.readouterr().err
    (tmp_path / "notes.pt").write_text("not a checkpoint")
    assert main(["evaluate", str(tmp_path / "notes.pt")]) == 2
    assert "notes.pt is not a checkpoint this version can read" in capsys.readouterr().err
    assert main(["evaluate", str(checkpoint), "--task", "jp2=5"]) == 2
    assert "--task: task parameter 'jp2'=5.0 is outside its bounds" in capsys.readouterr().err


def test_ctrl_c_stops_an_evaluation_at_once_and_cleanly(checkpoint):
    """Ctrl-C reaches the pool's workers too, here while they are still starting: they must leave the
    stopping to the parent instead of dying and breaking the pool, and the queued episodes are dropped."""
    command = [sys.executable, "-m", "kuka_curriculum", "evaluate", str(checkpoint), "--episodes", "400"]
    code, stderr = ctrl_c_as_the_pool_starts([*command, "--processes", "2", "--max-episode-steps", "1000"], workers=2)
    assert code == 130, stderr
    assert "kuka-curriculum evaluate: stopped; nothing was written" in stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr


@pytest.mark.parametrize(
    "model", sorted(Path(__file__).parents[2].joinpath("models").glob("*.pt")), ids=lambda p: p.name
)
def test_the_committed_policies_load_and_play(model, capsys):
    assert main(["evaluate", str(model), "--episodes", "2"]) == 0
    assert "hardest task, 2 episodes: return" in capsys.readouterr().out
