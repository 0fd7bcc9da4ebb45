"""The bake-off report's run statistics and teacher names, on evaluations made up here (no training)."""

from __future__ import annotations

import json

import imageio.v3 as iio
import pytest

from common.kuka.task_space import KUKA_TASK_SPACE
from common.policy.trajectory import EpisodeStats
from kuka_curriculum import main
from learner.evaluation.checkpoint_evaluation import EvaluationResult
from learner.experiments.bakeoff_report import (
    PERFORMANCE_PROFILE,
    RUN_STATISTICS_JSON,
    RUN_STATISTICS_MARKDOWN,
    recompute_run_statistics,
    results_markdown,
    seed_scores,
    teacher_label,
    write_reports,
)
from learner.experiments.bakeoff_runs import Run
from learner.experiments.bakeoff_statistics import TeacherResult, seed_statistics

SETTINGS = {"total_steps": 1000, "curve_every": 25, "curve_episodes": 20, "teacher_params": {}}
SUCCESSES = {"random": [2, 1, 3], "plr": [9, 8, 10], "learning-progress": [1]}
"""Each teacher's seeds: successes out of 10 final evaluation episodes."""
REPS = 200


def teacher_results(tmp_path, seeds: dict[str, list[int]] = SUCCESSES) -> list[TeacherResult]:
    task = KUKA_TASK_SPACE.hardest()

    def evaluation(successes: int) -> EvaluationResult:
        episodes = tuple(EpisodeStats(task, 1.0, index < successes, 800) for index in range(10))
        return EvaluationResult(task, 0, episodes)

    return [
        TeacherResult(
            teacher,
            tuple(Run(teacher, seed, tmp_path / f"{teacher}-seed{seed}") for seed in range(len(counts))),
            tuple(evaluation(count) for count in counts),
        )
        for teacher, counts in seeds.items()
    ]


def test_a_report_over_the_level_kinds_names_them_from_the_one_registry(tmp_path):
    results = teacher_results(tmp_path)
    statistics = seed_statistics(seed_scores(results), reps=REPS)
    report = results_markdown(results, SETTINGS, episodes=10, seed=0, statistics=statistics)
    assert "| Prioritized level replay (PLR) (`plr`) | 90% [" in report
    assert "| Learning progress (`learning-progress`) | 10% [n/a] |" in report
    assert teacher_label("a-kind-without-a-label") == "a-kind-without-a-label"


@pytest.mark.parametrize(("choice", "policy"), [("final", "final policy"), ("validated", "validated policy (the best")])
def test_the_report_names_the_policy_its_runs_were_scored_by(tmp_path, choice, policy):
    """A bake-off with ``--policy-choice validated`` scores each run's chosen checkpoint, not its last."""
    results = teacher_results(tmp_path)
    statistics = seed_statistics(seed_scores(results), reps=REPS)
    report = results_markdown(results, SETTINGS | {"policy_choice": choice}, episodes=10, seed=0, statistics=statistics)
    assert f"Each run's {policy}" in report and f"the success rate of its {policy}" in report
    other = "validated policy" if choice == "final" else "final policy"
    assert other not in report


def test_the_report_writes_the_run_statistics_beside_every_earlier_figure(tmp_path):
    results = teacher_results(tmp_path)
    write_reports(tmp_path, results, SETTINGS, episodes=10, seed=0, reps=REPS)
    record = json.loads((tmp_path / "results.json").read_text())
    # The earlier format is all there, per seed included; the run statistics come under their own key.
    assert [entry["teacher"] for entry in record["teachers"]] == ["random", "plr", "learning-progress"]
    assert [run["success_rate"] for run in record["teachers"][1]["runs"]] == [0.9, 0.8, 1.0]
    assert {"settings", "evaluation", "teachers", "scripted"} < set(record)
    statistics = record["run_statistics"]
    assert statistics["baseline"] == "random" and statistics["threshold"] == 0.8
    plr = statistics["arms"]["plr"]
    assert plr["scores"] == [0.9, 0.8, 1.0] and plr["iqm"]["estimate"] == pytest.approx(0.9)
    assert plr["share_at_or_above_threshold"]["estimate"] == 1.0
    assert plr["improvement_over_baseline"]["estimate"] == 1.0
    assert statistics["arms"]["learning-progress"]["improvement_over_baseline"]["estimate"] == pytest.approx(1 / 6)
    assert statistics["arms"]["random"]["improvement_over_baseline"] is None
    report = (tmp_path / "results.md").read_text()
    section = report[report.index("## Over seeds, robustly") : report.index("## Pooled episodes")]
    assert "| P(improvement over Uniform random tasks (`random`)) [CI] |" in section
    assert "| Prioritized level replay (PLR) (`plr`) | 3 | 90% [" in section and "| 1.00 [1.00, 1.00] |" in section
    assert (
        "| Learning progress (`learning-progress`) | 1 | 10% [n/a] | 10% [n/a] | 0% [0%, 79%] | 0.17 [n/a] |" in section
    )
    assert (
        f"![Performance profiles: the share of each teacher's seeds above each success rate]({PERFORMANCE_PROFILE})"
        in section
    )
    assert iio.imread(tmp_path / PERFORMANCE_PROFILE).ndim == 3


def test_without_the_baseline_among_the_teachers_the_report_says_so(tmp_path):
    results = teacher_results(tmp_path, {"plr": [9, 8, 10], "fixed": [0, 0]})
    statistics = seed_statistics(seed_scores(results), "random", reps=REPS)
    report = results_markdown(results, SETTINGS, episodes=10, seed=0, statistics=statistics, baseline="random")
    assert "needs the baseline, Uniform random tasks (`random`), among the teachers" in report
    assert "P(improvement over no baseline)" in report
    statistics = seed_statistics(seed_scores(results), "fixed", reps=REPS)
    against_fixed = results_markdown(results, SETTINGS, episodes=10, seed=0, statistics=statistics, baseline="fixed")
    assert "P(improvement over No curriculum: hardest task only (`fixed`)) [CI]" in against_fixed
    assert "| No curriculum: hardest task only (`fixed`) | 2 | 0% [0%, 0%] | 0% [0%, 0%] | 0% [0%, 66%] | — |" in (
        against_fixed
    )


def test_the_run_statistics_are_recomputed_from_a_results_file_alone(tmp_path):
    # A results.json from before the run statistics: the per-seed success rates are all they need.
    scores = {"random": [0.224, 0.218, 0.27], "currot": [0.718, 0.23, 0.89]}
    old = {
        "teachers": [
            {"teacher": kind, "runs": [{"success_rate": rate} for rate in rates]} for kind, rates in scores.items()
        ]
    }
    results_json = tmp_path / "bakeoff-v1" / "results.json"
    results_json.parent.mkdir()
    results_json.write_text(json.dumps(old))
    statistics = recompute_run_statistics(results_json, reps=REPS)
    assert statistics == seed_statistics(scores, "random", reps=REPS)
    assert json.loads(results_json.read_text()) == old, "the results file stays as it was"
    written = json.loads((results_json.parent / RUN_STATISTICS_JSON).read_text())
    assert written == json.loads(json.dumps(statistics.to_dict()))
    report = (results_json.parent / RUN_STATISTICS_MARKDOWN).read_text()
    assert report.startswith("# Run statistics of the bake-off in bakeoff-v1\n\nRecomputed from its `results.json`.")
    assert "| CURROT (`currot`) | 3 |" in report and "| 0.89 [" in report
    assert iio.imread(results_json.parent / PERFORMANCE_PROFILE).ndim == 3
    # Elsewhere, against another baseline.
    against = recompute_run_statistics(results_json, tmp_path / "against-currot", baseline="currot", reps=REPS)
    assert against.baseline == "currot" and against.arms["random"].improvement.estimate == pytest.approx(1 / 9)
    assert (tmp_path / "against-currot" / RUN_STATISTICS_MARKDOWN).exists()


def test_an_unknown_baseline_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["bakeoff", "--out", str(tmp_path), "--baseline", "curious"])
    assert exit_info.value.code == 2 and "invalid choice" in capsys.readouterr().err
