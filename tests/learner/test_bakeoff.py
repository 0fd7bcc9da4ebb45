"""``kuka-curriculum bakeoff`` on a tiny budget: real training children, real Ray, a real teacher service."""

from __future__ import annotations

import contextlib
import json
import lzma
import shutil
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import imageio.v3 as iio
import pytest
import torch
from ctrl_c import ctrl_c_as_the_pool_starts
from tiny_checkpoint import save_untrained_checkpoint

from common.kuka import HARD_ENV_ID, HARD_V1_ENV_ID
from common.kuka.diagnostics import EpisodeDiagnostics
from common.kuka.task_space import KUKA_HARD_TASK_SPACE, KUKA_HARD_V1_TASK_SPACE, KUKA_TASK_SPACE
from common.policy.trajectory import EpisodeStats
from kuka_curriculum import main
from learner.commands.arguments import UsageError
from learner.core.checkpoint import CHECKPOINT_DIR, latest_checkpoint, load_checkpoint
from learner.evaluation.checkpoint_evaluation import EvaluationResult
from learner.evaluation.stats import mean_interval
from learner.experiments.bakeoff_report import BOOK_RETURNS, results_markdown, teacher_record
from learner.experiments.bakeoff_runs import (
    Run,
    archives_runs,
    check_curricula,
    check_settings,
    learning_curve,
    plan_runs,
    teacher_params_by_kind,
    train_command,
)
from learner.experiments.bakeoff_statistics import HALF_SUCCESS, TeacherResult, median_steps, steps_to_success
from learner.experiments.run_archive import (
    RESUME_CHECKPOINT,
    TENSORBOARD_DIR,
    archive_run,
    exists,
    read_json,
    read_text,
    restore_run,
    resume_files,
    write_up_files,
)
from learner.job.teacher_probe import TeacherProbe, teacher_probe

BATCH = 1 * 2 * 128
TINY = [
    "--seeds",
    "1",
    "--workers",
    "1",
    "--envs-per-worker",
    "2",
    "--rollout-length",
    "128",
    "--max-episode-steps",
    "60",
    "--checkpoint-every",
    "1",
    "--curve-every",
    "1",
    "--curve-episodes",
    "2",
    "--eval-episodes",
    "3",
    "--eval-processes",
    "1",
    "--ppo",
    "update_epochs=2",
    "--bootstrap-reps",
    "200",
]
"""A tiny bake-off: one worker, short episodes, two PPO epochs, a few evaluation episodes, and 200 bootstrap
resamples per interval where a report takes 10,000 (seconds of each report)."""

ROOT = Path(__file__).resolve().parents[2]


def test_bakeoff_trains_resumes_skips_finished_runs_and_reports(tmp_path, ray_cluster, capsys):
    out = tmp_path / "bakeoff"

    def bakeoff(*flags: str) -> int:
        return main(["bakeoff", "--out", str(out), "--ray-address", ray_cluster, *TINY, *flags])

    # A shorter first session leaves `fixed` with a checkpoint below the final budget, as an interruption would.
    assert bakeoff("--teachers", "fixed", "--total-steps", str(BATCH)) == 0
    fixed, random = plan_runs(out, ["fixed", "random"], seeds=1)
    assert load_checkpoint(latest_checkpoint(fixed.directory)).counters.steps == BATCH
    # Finished and evaluated, the run is archived: raw files compressed, and resuming undoes that below.
    assert sorted(path.name for path in fixed.directory.iterdir()) == [
        "checkpoints",
        "evaluation.json.xz",
        "metrics.full.jsonl.xz",
        "metrics.jsonl.xz",
        "resume.pt",
        "teacher.log.xz",
        "teacher.sqlite.xz",
        "tensorboard",
        "train.log.xz",
    ]
    # For git what the report reads; the rest only on disk, for resuming.
    assert sorted(write_up_files()) == [
        "checkpoints",
        "evaluation.json.xz",
        "metrics.jsonl.xz",
        "validated-policy.json",
    ]
    assert sorted(resume_files()) == [
        "metrics.full.jsonl.xz",
        "resume.pt",
        "teacher.log.xz",
        "teacher.sqlite.xz",
        "tensorboard",
        "train.log.xz",
    ]
    capsys.readouterr()

    assert bakeoff("--teachers", "fixed", "random", "--total-steps", str(2 * BATCH)) == 0
    printed = capsys.readouterr().out
    assert f"fixed-seed0: resuming at {BATCH:_}" in printed and "random-seed0: training" in printed
    # Each run is evaluated as soon as it is trained, before the next one starts.
    assert printed.index("fixed-seed0: hardest task") < printed.index("random-seed0: training")
    first_random_checkpoint = min(path.stat().st_mtime_ns for path in (random.directory / "checkpoints").iterdir())
    assert (fixed.directory / "evaluation.json.xz").stat().st_mtime_ns < first_random_checkpoint
    assert f"at step {BATCH:_}" in read_text(fixed.directory / "train.log")
    for run in (fixed, random):
        # Only the evaluated checkpoint stays (the resumed `fixed` wrote two), and the curve is read compressed.
        assert [path.name for path in (run.directory / "checkpoints").iterdir()] == [f"step_{2 * BATCH:010d}.pt"]
        assert not (run.directory / "metrics.jsonl").exists() and not (run.directory / "teacher.sqlite").exists()
        unpacked = tmp_path / f"{run.name}.sqlite"
        unpacked.write_bytes(lzma.decompress((run.directory / "teacher.sqlite.xz").read_bytes()))
        with contextlib.closing(sqlite3.connect(unpacked)) as database:
            assert database.execute("PRAGMA integrity_check").fetchone() == ("ok",)
            assert database.execute("SELECT count(*) FROM sqlite_master").fetchone()[0] > 0
        checkpoint = load_checkpoint(latest_checkpoint(run.directory))
        assert checkpoint.counters.steps == 2 * BATCH and checkpoint.config.teacher == run.teacher
        # The kept checkpoint is evaluation-only; the full one, which resumed `fixed`, stays on disk beside it.
        full = load_checkpoint(run.directory / RESUME_CHECKPOINT)
        assert checkpoint.evaluation_only and not full.evaluation_only and full.counters == checkpoint.counters
        assert checkpoint.config.workers == 1 and checkpoint.config.max_episode_steps == 60
        assert checkpoint.config.ppo.update_epochs == 2
        assert sorted(learning_curve(run)) == [BATCH, 2 * BATCH]

    results = json.loads((out / "results.json").read_text())
    assert [entry["teacher"] for entry in results["teachers"]] == ["fixed", "random"]
    table = (out / "results.md").read_text()
    for entry, run in zip(results["teachers"], (fixed, random), strict=True):
        evaluation = json.loads(lzma.decompress((run.directory / "evaluation.json.xz").read_bytes()))
        returns = mean_interval(evaluation["per_episode"]["return"])
        assert evaluation["checkpoint"] == latest_checkpoint(run.directory).name, "the final policy is evaluated"
        assert evaluation["episodes"] == 3 and evaluation["task"] == results["evaluation"]["task"]
        assert entry["seeds"] == 1 and entry["return"] == returns.to_dict()
        success = sum(evaluation["per_episode"]["success"]) / 3
        assert entry["success_rate_over_seeds"] == {"estimate": success, "low": None, "high": None, "samples": 1}
        assert entry["runs"][0]["steps_to_success"] == steps_to_success(run)
        assert entry["runs"][0]["steps_to_half_success"] == steps_to_success(run, HALF_SUCCESS)
        assert f"(`{run.teacher}`) | {success:.0%} [n/a] | {success:.0%} |" in table
        assert entry["book_return"] == BOOK_RETURNS.get(run.teacher)
        assert f"(`{run.teacher}`) | {returns.estimate:.2f} ± {returns.half_width:.2f} |" in table
    assert f"| {BOOK_RETURNS['fixed']:.2f} |" in table
    assert "registered with" not in table, "fixed and random take no KUKA parameters"
    assert iio.imread(out / "learning_curves.png").ndim == 3
    # The scripted controller played the final evaluation's seeds, and each teacher's students sit beside it.
    scripted = json.loads((out / "scripted_evaluation.json").read_text())
    assert (scripted["controller"], scripted["seed"], scripted["episodes"]) == ("scripted", 0, 3)
    placements = read_json(fixed.directory / "evaluation.json")["per_episode"]["block_x"]
    assert scripted["per_episode"]["block_x"] == placements
    assert results["scripted"]["success_rate"] == scripted["success_rate"]
    assert results["scripted"]["success_by_placement"] == scripted["success_by_placement"]
    assert sum(band["episodes"] for band in results["teachers"][0]["success_by_placement"][:4]) == 3
    assert "## Where the students fail: success by block placement" in table
    for row in ("| No curriculum: hardest task only (1 seed) |", "| Uniform random tasks (1 seed) |"):
        assert row in table
    assert "| Scripted controller (no learning) |" in table and "left out" not in table
    assert iio.imread(out / "success_by_placement.png").ndim == 3
    # The run statistics over seeds, against uniform random by default: one seed each, so no bootstrap bounds.
    statistics = results["run_statistics"]
    assert statistics["baseline"] == "random" and list(statistics["arms"]) == ["fixed", "random"]
    assert statistics["reps"] == 200
    fixed_statistics = statistics["arms"]["fixed"]
    assert fixed_statistics["scores"] == [results["teachers"][0]["runs"][0]["success_rate"]]
    assert fixed_statistics["improvement_over_baseline"]["low"] is None
    assert "## Over seeds, robustly" in table and "P(improvement over Uniform random tasks (`random`))" in table
    assert iio.imread(out / "performance_profile.png").ndim == 3

    # Run again: every run is finished and evaluated, so nothing is trained or evaluated anew.
    untouched = {path: path.stat().st_mtime_ns for path in out.glob("runs/*/*") if path.is_file()}
    untouched |= {path: path.stat().st_mtime_ns for path in out.glob("runs/*/checkpoints/*")}
    untouched[out / "scripted_evaluation.json"] = (out / "scripted_evaluation.json").stat().st_mtime_ns
    assert bakeoff("--teachers", "fixed", "random", "--total-steps", str(2 * BATCH)) == 0
    printed = capsys.readouterr().out
    assert printed.count(f"finished at {2 * BATCH:_} steps, skipped") == 2
    assert {path: path.stat().st_mtime_ns for path in untouched} == untouched

    # One teacher gets more seeds; a later report over every teacher keeps them, and only finished ones.
    assert bakeoff("--teachers", "fixed", "--seeds", "2", "--total-steps", str(2 * BATCH)) == 0
    (out / "runs" / "fixed-seed2").mkdir()  # started, never checkpointed: not in the report
    # Another baseline is a report setting: the same runs, compared with no curriculum instead.
    assert bakeoff("--teachers", "fixed", "random", "--total-steps", str(2 * BATCH), "--baseline", "fixed") == 0
    results = json.loads((out / "results.json").read_text())
    assert results["run_statistics"]["baseline"] == "fixed"
    assert results["run_statistics"]["arms"]["fixed"]["iqm"]["low"] is not None, "two seeds resample"
    teachers = results["teachers"]
    assert {entry["teacher"]: [run["seed"] for run in entry["runs"]] for entry in teachers} == {
        "fixed": [0, 1],
        "random": [0],
    }
    capsys.readouterr()

    # Other hyperparameters in the same directory would make an unfair comparison.
    assert bakeoff("--teachers", "fixed", "--total-steps", str(2 * BATCH), "--rollout-length", "64") == 2
    assert "rollout_length: 128 before, 64 now" in capsys.readouterr().err


def test_ctrl_c_during_a_final_evaluation_stops_the_bakeoff_cleanly(tmp_path):
    out = tmp_path / "bakeoff"
    run = plan_runs(out, ["fixed"], seeds=1)[0]
    # Trained to its budget: only the final evaluation is left.
    steps = load_checkpoint(save_untrained_checkpoint(run.directory)).counters.steps
    command = [sys.executable, "-m", "kuka_curriculum", "bakeoff", "--out", str(out), "--teachers", "fixed"]
    command += ["--seeds", "1", "--total-steps", str(steps), "--eval-episodes", "400", "--eval-processes", "2"]
    code, stderr = ctrl_c_as_the_pool_starts(command, workers=2)
    assert code == 130, stderr
    assert "kuka-curriculum bakeoff: stopped; the same command resumes where it stopped" in stderr
    assert "Traceback" not in stderr, stderr
    assert not exists(run.directory / "evaluation.json")


def test_a_bakeoff_on_the_hard_family_trains_and_evaluates_there(tmp_path, ray_cluster, capsys):
    out = tmp_path / "bakeoff-hard"
    flags = ["bakeoff", "--out", str(out), "--ray-address", ray_cluster, *TINY, "--teachers", "fixed"]
    assert main([*flags, "--env", HARD_ENV_ID, "--total-steps", str(BATCH)]) == 0
    (run,) = plan_runs(out, ["fixed"], seeds=1)
    assert load_checkpoint(latest_checkpoint(run.directory)).config.env == HARD_ENV_ID
    hardest = KUKA_HARD_TASK_SPACE.hardest()
    assert read_json(run.directory / "evaluation.json.xz")["task"] == hardest
    results = json.loads((out / "results.json").read_text())
    assert results["evaluation"]["env"] == HARD_ENV_ID and results["evaluation"]["task"] == hardest
    assert results["teachers"][0]["book_return"] is None, "the book measured its own task, not this one"
    table = (out / "results.md").read_text()
    assert f"on the hardest task of {HARD_ENV_ID}" in table and f"| {BOOK_RETURNS['fixed']:.2f} |" not in table
    capsys.readouterr()

    # The runs in one directory share their task family.
    assert main([*flags, "--total-steps", str(2 * BATCH)]) == 2
    assert f"env: '{HARD_ENV_ID}' before, 'KukaGrasp-v0' now" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("flags", "message"), [(["--teachers", "curious"], "invalid choice"), (["--seeds", "0"], "at least 1")]
)
def test_bad_bakeoff_flags_are_refused(tmp_path, capsys, flags, message):
    with pytest.raises(SystemExit) as exit_info:
        main(["bakeoff", "--out", str(tmp_path), *flags])
    assert exit_info.value.code == 2 and message in capsys.readouterr().err


def test_steps_to_success_pools_consecutive_evaluations_and_the_median_counts_a_seed_that_never_got_there(tmp_path):
    run = Run("alp-gmm", 0, tmp_path)
    rates = [0.1, 0.9, 0.5, 0.9, 0.8, 0.85, 0.7]
    lines = [json.dumps({"step": 100 * (index + 1), "eval/success_rate": rate}) for index, rate in enumerate(rates)]
    lines.insert(2, json.dumps({"step": 250, "train/episodes": 3.0}))  # an iteration without an evaluation
    (tmp_path / "metrics.jsonl").write_text("\n".join(lines) + "\n")
    # One lucky 0.9 is not enough: the first window of three at 80% or more ends at step 600.
    assert steps_to_success(run) == 600
    assert steps_to_success(run, target=0.9) is None
    assert median_steps([600, None, 300]) == 600
    assert median_steps([600, None, None]) is None
    assert median_steps([400, 200, None, 100]) == 300


def test_steps_to_success_takes_a_moving_mean_so_a_lone_evaluation_at_the_target_is_not_enough(tmp_path):
    run = Run("currot", 0, tmp_path)

    def curve(rates: list[float]) -> None:
        records = [{"step": 1000 * (index + 1), "eval/success_rate": rate} for index, rate in enumerate(rates)]
        (tmp_path / "metrics.jsonl").write_text("".join(json.dumps(record) + "\n" for record in records))

    curve([0.0, 0.85, 0.6, 0.85, 0.6, 0.95, 0.55])  # at 80% every other time, a mean of about 0.7: never there
    assert steps_to_success(run) is None
    assert steps_to_success(run, window=1) == 2000, "one evaluation alone would have read it at the first spike"
    curve([0.0, 0.5, 0.75, 0.8, 0.85, 0.8, 0.7, 0.9])  # the first three at a mean of 80% end at 6,000 steps
    assert steps_to_success(run) == 6000
    curve([])  # a run without in-run evaluations never gets there
    assert steps_to_success(run) is None
    # The median over seeds: not reached when the middle seed never got there, with an even count as well.
    assert median_steps([None, None, None]) is None
    assert median_steps([3000, None]) is None
    assert median_steps([3000, 1000, None, None, 2000]) == 3000


def test_the_report_says_which_runs_curves_played_the_older_easier_seeds(tmp_path):
    task = KUKA_HARD_V1_TASK_SPACE.hardest()
    evaluation = EvaluationResult(task, 100000, (EpisodeStats(task, 1.0, True, 800),), HARD_V1_ENV_ID)
    runs = tuple(Run("currot", seed, tmp_path / f"currot-seed{seed}") for seed in range(3))
    save_untrained_checkpoint(runs[0].directory, env=HARD_V1_ENV_ID)
    older = save_untrained_checkpoint(runs[1].directory, env=HARD_V1_ENV_ID)
    saved = torch.load(older, weights_only=True)
    del saved["config"]["eval_seeds"]  # written before issue 59
    torch.save(saved, older)
    result = TeacherResult("currot", runs, (evaluation,) * 3, HARD_V1_ENV_ID)  # seed 2: no checkpoint yet
    assert result.seed_curve_seeds == ["stratified", "consecutive", None]
    assert [entry["curve_seeds"] for entry in teacher_record(result)["runs"]] == ["stratified", "consecutive", None]
    settings = {"total_steps": 1000, "curve_every": 25, "curve_episodes": 20, "teacher_params": {}}
    report = results_markdown([result], settings, episodes=1, seed=100000)
    assert "a fixed stratified set of the hardest task's" in report
    assert "Except for currot seed 1: trained before issue 59" in report and "seed 0:" not in report
    fresh = TeacherResult("currot", runs[:1], (evaluation,), HARD_V1_ENV_ID)
    assert "Except for" not in results_markdown([fresh], settings, episodes=1, seed=100000)


def test_the_success_interval_over_seeds_stays_within_zero_and_one(tmp_path):
    task = KUKA_TASK_SPACE.hardest()

    def evaluation(successes: list[bool]) -> EvaluationResult:
        return EvaluationResult(task, 0, tuple(EpisodeStats(task, 1.0, success, 800) for success in successes))

    runs = (Run("alp-gmm", 0, tmp_path / "a"), Run("alp-gmm", 1, tmp_path / "b"))
    result = TeacherResult("alp-gmm", runs, (evaluation([True] * 9 + [False]), evaluation([True] * 10)))
    interval = result.success_over_seeds
    assert interval.estimate == pytest.approx(0.95) and interval.high == 1.0 and 0.0 < interval.low < 0.95
    assert result.seed_success_rates == [0.9, 1.0]


def test_the_placement_table_holds_each_diagnosed_teacher_and_the_scripted_controller(tmp_path):
    task = KUKA_HARD_V1_TASK_SPACE.hardest()

    def evaluation(placed: list[tuple[float, bool]], diagnosed: bool = True) -> EvaluationResult:
        episodes = tuple(EpisodeStats(task, 1.0, success, 800) for _, success in placed)
        diagnostics = tuple(EpisodeDiagnostics(x, 0.0, 0.0, 0.0, 0.0, 1.0) for x, _ in placed) if diagnosed else ()
        return EvaluationResult(task, 100000, episodes, HARD_V1_ENV_ID, diagnostics)

    def result(teacher: str, *evaluations: EvaluationResult) -> TeacherResult:
        runs = tuple(Run(teacher, seed, tmp_path / f"{teacher}-{seed}") for seed in range(len(evaluations)))
        return TeacherResult(teacher, runs, evaluations, HARD_V1_ENV_ID)

    currot = result("currot", evaluation([(0.58, True), (0.68, False)]), evaluation([(0.66, True), (0.695, False)]))
    # One seed evaluated before episodes recorded their placement: a table of the other seed alone would mislead.
    alp_gmm = result("alp-gmm", evaluation([(0.58, True)]), evaluation([(0.58, True)], diagnosed=False))
    scripted = evaluation([(0.58, True), (0.68, True), (0.66, True), (0.695, True)])
    settings = {"total_steps": 1000, "curve_every": 25, "curve_episodes": 20, "teacher_params": {}}
    report = results_markdown([currot, alp_gmm], settings, episodes=2, seed=100000, scripted=scripted)
    section = report[report.index("## Where the students fail") :]
    assert "| CURROT (2 seeds) | 50% (4) | 100% (1) | 100% (1) | 0% (1) | 0% (1) | 0% (1) | 2 of 2 (100%) |" in section
    assert "| Scripted controller (no learning) | 100% (4) |" in section and "ALP-GMM (" not in section
    assert "so left out: ALP-GMM." in section
    assert teacher_record(alp_gmm)["success_by_placement"] is None
    record = teacher_record(currot)
    assert record["failures_beyond_clamp"] == {"beyond": 2, "failures": 2}
    assert [band["episodes"] for band in record["success_by_placement"]] == [1, 1, 1, 1, 1]
    # Without any diagnosed episodes the section is left out whole.
    assert "Where the students fail" not in results_markdown([alp_gmm], settings, episodes=2, seed=100000)


def test_the_report_names_what_each_teacher_was_registered_with(tmp_path):
    task = KUKA_TASK_SPACE.hardest()
    evaluation = EvaluationResult(task, 0, (EpisodeStats(task, 1.0, True, 800),))
    results = [
        TeacherResult(teacher, (Run(teacher, 0, tmp_path / teacher),), (evaluation,))
        for teacher in ("alp-gmm", "fixed")
    ]
    settings = {"total_steps": 1000, "curve_every": 25, "curve_episodes": 20, "teacher_params": {}}
    report = results_markdown(results, settings, episodes=1, seed=0)
    registered = next(line for line in report.splitlines() if "registered with" in line)
    assert registered.endswith("defaults: ALP-GMM reward_range=[-5.0, 10.0], target_task_ratio=0.2.")
    assert "hardest task only" not in registered and "teacher params" not in report
    assert "Each teacher trained 1 seed for 1_000 environment steps" in report

    # Each teacher is named with its own parameters, and only its own.
    settings["teacher_params"] = {"alp-gmm": {"fit_rate": 100}, "fixed": {}}
    report = results_markdown(results, settings, episodes=1, seed=0)
    registered = next(line for line in report.splitlines() if "registered with" in line)
    assert registered.endswith("ALP-GMM reward_range=[-5.0, 10.0], target_task_ratio=0.2, fit_rate=100.")


def test_the_report_says_how_many_seeds_while_a_round_is_unfinished(tmp_path):
    task = KUKA_TASK_SPACE.hardest()
    evaluation = EvaluationResult(task, 0, (EpisodeStats(task, 1.0, True, 800),))
    seeds = {"fixed": 5, "currot": 1}
    results = [
        TeacherResult(
            teacher,
            tuple(Run(teacher, seed, tmp_path / f"{teacher}-{seed}") for seed in range(count)),
            (evaluation,) * count,
        )
        for teacher, count in seeds.items()
    ]
    settings = {"total_steps": 1000, "curve_every": 25, "curve_episodes": 20, "teacher_params": {}}
    report = results_markdown(results, settings, episodes=1, seed=0)
    assert "Each teacher trained 1 to 5 seeds (the Seeds column says how many) for 1_000" in report


def test_bad_teacher_parameters_stop_the_bakeoff_before_any_run(tmp_path, capsys):
    """Each refusal is the teacher service's, asked before the first run: a kind it does not list, a value its
    model refuses, a kind that does not take the family's task space."""
    for flags, message in [
        (["--teachers", "fixed", "--teacher-param", "curot.start=easiest"], "no teacher kind 'curot'; known: adr,"),
        (
            ["--teachers", "adr", "fixed", "--teacher-param", "adr.step=2"],
            "--teacher-param for adr: step: Input should be less than or equal to 1",
        ),
        (["--teachers", "random", "plr"], "plr on KukaGrasp-v0: Value error, parameter 'rnd_obj_x' is a float"),
    ]:
        # A tiny budget, so that a regression trains for seconds before the test fails, not for hours.
        assert main(["bakeoff", "--out", str(tmp_path), "--seeds", "1", "--total-steps", "1", *flags]) == 2
        error = capsys.readouterr().err
        assert message in error and len(error.strip().splitlines()) == 1, error
    assert not (tmp_path / "runs").exists() and not (tmp_path / "bakeoff.json").exists()


@pytest.fixture(scope="module")
def probe() -> Iterator[TeacherProbe]:
    with teacher_probe() as probe:
        yield probe


def test_each_teacher_trains_with_its_own_parameters_and_plain_names_reach_every_teacher(tmp_path, probe):
    pairs = [("currot.start", "easiest"), ("currot.target", "hardest"), ("seed_note", 1), ("adr.step", 0.2)]
    teachers = ["currot", "adr", "fixed"]
    with pytest.raises(UsageError, match="no teacher kind 'curot'"):
        teacher_params_by_kind([("curot.start", "easiest")], teachers, probe.kinds)
    with_note = teacher_params_by_kind(pairs, teachers, probe.kinds)
    with pytest.raises(UsageError, match="^--teacher-param for currot: seed_note: Extra inputs are not permitted$"):
        check_curricula(probe, with_note, "KukaGraspHard-v0", 1)  # no kind takes a seed_note
    params = teacher_params_by_kind([pair for pair in pairs if pair[0] != "seed_note"], teachers, probe.kinds)
    assert params == {"currot": {"start": "easiest", "target": "hardest"}, "adr": {"step": 0.2}, "fixed": {}}
    check_curricula(probe, params, "KukaGraspHard-v0", 1)
    # A kind that this invocation does not run keeps its parameters to itself.
    assert teacher_params_by_kind(pairs[:2], ["fixed"], probe.kinds) == {"fixed": {}}
    assert teacher_params_by_kind([("reward_range", [0, 1])], ["adr", "self-paced"], probe.kinds) == {
        "adr": {"reward_range": [0, 1]},
        "self-paced": {"reward_range": [0, 1]},
    }
    # The service's validators decide, on top of the family's parameters and over its task space.
    with pytest.raises(UsageError, match="^--teacher-param for adr: Value error, reward_range must have low < high"):
        check_curricula(probe, {"adr": {"reward_range": [1, 0]}}, "KukaGraspHard-v0", 1)
    with pytest.raises(UsageError, match="^alp-gmm on MiniGrid-DoorKey-5x5-v0: .*takes float parameters only$"):
        check_curricula(probe, {"plr": {"robust": True}, "alp-gmm": {}}, "MiniGrid-DoorKey-5x5-v0", 50)

    settings = {"env": "KukaGraspHard-v0", "ppo": {"update_epochs": 2}, "teacher_params": params} | {
        name: 1 for name in ("workers", "envs_per_worker", "rollout_length", "max_episode_steps")
    }
    settings |= {"checkpoint_every": 1, "curve_every": 1, "curve_episodes": 1, "loop": "sync"}
    currot, adr, fixed = (Run(teacher, 0, tmp_path / teacher) for teacher in teachers)
    command = " ".join(train_command(currot, 10, settings, resume=False, ray_address=None))
    assert '--teacher-param start="easiest" --teacher-param target="hardest"' in command
    assert "step=" not in command and "--ppo update_epochs=2" in command
    assert "--teacher-param" not in train_command(fixed, 10, settings, resume=False, ray_address=None)
    # A setting newer than a stored bake-off is handed on as its runs were trained: the final policy.
    assert "--policy-choice final" in command
    validated = train_command(currot, 10, settings | {"policy_choice": "validated"}, resume=False, ray_address=None)
    assert "--policy-choice validated" in " ".join(validated)


def test_a_teacher_may_join_a_bakeoff_with_its_own_parameters_but_not_change_them(tmp_path):
    base = {"env": "KukaGraspHard-v0", "ppo": {}, "total_steps": 100}
    first = check_settings(tmp_path, base | {"teacher_params": {"adr": {"step": 0.2}, "fixed": {}}}, ["adr", "fixed"])
    assert first["teacher_params"] == {"adr": {"step": 0.2}, "fixed": {}}
    # A later invocation adds CURROT with its parameters and reruns ADR with the same ones.
    joined = base | {"teacher_params": {"adr": {"step": 0.2}, "currot": {"start": "easiest"}}}
    reported = check_settings(tmp_path, joined, ["adr", "currot"])
    assert reported["teacher_params"] == {"adr": {"step": 0.2}, "fixed": {}, "currot": {"start": "easiest"}}
    # Runs already trained with the defaults cannot be compared with new ones trained otherwise.
    with pytest.raises(UsageError, match=r"fixed parameters: \{\} before, \{'point': "):
        check_settings(tmp_path, base | {"teacher_params": {"fixed": {"point": {}}}}, ["fixed"])
    with pytest.raises(UsageError, match=r"adr parameters: \{'step': 0.2\} before, \{\} now"):
        check_settings(tmp_path, base | {"teacher_params": {"adr": {}}}, ["adr"])


def test_archiving_a_run_keeps_what_the_report_reads_and_restoring_it_gives_back_the_raw_files(tmp_path):
    run = Run("fixed", 0, tmp_path / "run")
    final = save_untrained_checkpoint(run.directory)  # at step 512
    shutil.copy(final, final.with_name("step_0000000256.pt"))  # an earlier checkpoint, as training leaves
    records = [{"step": 100, "eval/success_rate": 0.25}, {"step": 200, "eval/success_rate": 0.75}]
    metrics = "".join(json.dumps(record) + "\n" for record in records)
    (run.directory / "metrics.jsonl").write_text(metrics)
    (run.directory / "train.log").write_text("iteration 2 at step 200\n")
    evaluation = {"checkpoint": final.name, "per_episode": {"success": [True, False, True]}}
    (run.directory / "evaluation.json").write_text(json.dumps(evaluation))
    with contextlib.closing(sqlite3.connect(run.directory / "teacher.sqlite")) as database:
        database.execute("PRAGMA journal_mode=WAL")
        database.execute("CREATE TABLE results (step INTEGER)")
        database.executemany("INSERT INTO results VALUES (?)", [(step,) for step in range(500)])
        database.commit()
    # Today's uncompressed layout (the committed v1 runs) reads as it always did.
    raw_curve = learning_curve(run, "eval/success_rate")
    assert raw_curve == {100: 0.25, 200: 0.75}

    archive_run(run.directory)
    names = sorted(path.name for path in run.directory.iterdir())
    assert names == [
        "checkpoints",
        "evaluation.json.xz",
        "metrics.full.jsonl.xz",
        "metrics.jsonl.xz",
        "resume.pt",
        "teacher.sqlite.xz",
        "train.log.xz",
    ]
    # Read by either name: the raw one falls back to the compressed file, as a report reads it.
    assert read_json(run.directory / "evaluation.json") == read_json(run.directory / "evaluation.json.xz") == evaluation
    assert set(names) - set(write_up_files()) <= set(resume_files()), "nothing else stays beside the write-up's"
    assert [path.name for path in (run.directory / "checkpoints").iterdir()] == [final.name]
    assert load_checkpoint(final).evaluation_only, "git keeps the final checkpoint without its optimiser state"
    assert not load_checkpoint(run.directory / RESUME_CHECKPOINT).evaluation_only, "the disk keeps it whole"
    assert run.steps_done() == 512, "the kept checkpoint still marks the run finished"
    assert learning_curve(run, "eval/success_rate") == raw_curve
    assert steps_to_success(run, target=0.5, window=1) == 200
    assert read_text(run.directory / "train.log") == "iteration 2 at step 200\n"
    archived = {path: path.stat().st_mtime_ns for path in run.directory.iterdir() if path.is_file()}
    archive_run(run.directory)
    assert {path: path.stat().st_mtime_ns for path in archived} == archived, "archiving twice changes nothing"

    restore_run(run.directory)
    assert not load_checkpoint(final).evaluation_only and not (run.directory / RESUME_CHECKPOINT).exists()
    assert (run.directory / "metrics.jsonl").read_text() == metrics
    assert json.loads((run.directory / "evaluation.json").read_text()) == evaluation
    assert not list(run.directory.glob("*.xz"))
    with contextlib.closing(sqlite3.connect(run.directory / "teacher.sqlite")) as database:
        assert database.execute("SELECT count(*) FROM results").fetchone() == (500,)


@pytest.mark.skipif(not (ROOT / ".git").exists() or shutil.which("git") is None, reason="needs a git checkout")
def test_git_ignores_what_an_archived_run_keeps_for_resuming_and_tracks_what_the_write_up_reads():
    run = Path("benchmarks/some-bakeoff/runs/fixed-seed0")
    # A directory's patterns match what lies in it: the events file stands for TensorBoard's directory.
    ignored = [f"{name}/events.out" if name == TENSORBOARD_DIR else name for name in resume_files()]
    ignored += ["teacher.sqlite", "metrics.jsonl", "train.log", "teacher.log"]
    kept = [*(name for name in write_up_files() if name != CHECKPOINT_DIR), f"{CHECKPOINT_DIR}/step_0000000512.pt"]

    def is_ignored(name: str) -> bool:
        check = subprocess.run(["git", "check-ignore", "-q", "--no-index", str(run / name)], cwd=ROOT)
        assert check.returncode in (0, 1), f"git check-ignore failed on {name}"
        return check.returncode == 0

    assert [name for name in ignored if not is_ignored(name)] == [], "on disk only, never for git"
    assert [name for name in kept if is_ignored(name)] == [], "what the write-up reads stays in git"


def test_a_bakeoff_directory_from_before_archiving_keeps_its_runs_raw(tmp_path):
    assert archives_runs(tmp_path / "new"), "a new bake-off archives its runs"
    (tmp_path / "new" / "bakeoff.json").write_text("{}")
    assert archives_runs(tmp_path / "new"), "and keeps doing so when resumed"
    (tmp_path / "v1").mkdir()
    (tmp_path / "v1" / "bakeoff.json").write_text("{}")
    assert not archives_runs(tmp_path / "v1")
