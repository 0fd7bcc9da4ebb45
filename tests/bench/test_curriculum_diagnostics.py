"""``bench/curriculum_diagnostics.py`` reads each run's task space from its own teacher database: tiny
runs of the book's space and of the hard family's, written the way the service and ``train`` write them."""

from __future__ import annotations

import asyncio
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.curriculum_diagnostics import PLACEMENT_SKIPPED, load_run, main, summary_markdown
from common.client.schemas import ParameterSpec
from common.client.task_space import TaskSpace
from common.kuka.task_space import KUKA_HARD_TASK_SPACE, KUKA_TASK_SPACE
from learner.core.metrics import METRICS_FILE
from learner.experiments.run_archive import EVALUATION_FILE, archive_run
from learner.job.teacher_process import DATABASE_FILE
from teacher_service.curriculum_spec import SPEC_CLASSES
from teacher_service.store import NewResult, NewTask, Store, StoredCurriculum

EPISODES = 1200
"""Uniformly drawn tasks per run: enough for each difficulty band's share to be within a few points of 25%."""
PLACEMENT_TABLE = "| run | outer tenth of x / y / yaw, training steps |"
PLACEMENT_ROW = "| random (1 runs) | rnd_obj_ang |"


def write_run(directory: Path, space: TaskSpace) -> Path:
    """A finished run of a uniform teacher over ``space``: its teacher database, metrics log and final evaluation."""
    rng = np.random.default_rng(0)
    tasks = [space.from_array(space.from_unit(rng.random(len(space)))) for _ in range(EPISODES)]
    spec = SPEC_CLASSES["random"](teacher="random", space=[ParameterSpec.from_parameter(p) for p in space.parameters])
    directory.mkdir(parents=True)
    store = Store(directory / DATABASE_FILE)

    async def write() -> None:
        store.start(asyncio.get_running_loop())
        await store.add_curriculum(StoredCurriculum(1, directory.name, spec.model_dump_json(), 0.0))
        await store.add_tasks(1, [NewTask(index, task, 0, float(index)) for index, task in enumerate(tasks)])
        results = [NewResult(index, 1.0, bool(rng.random() < 0.5), 50, index + 1.0) for index in range(EPISODES)]
        await store.add_results(1, results)

    try:
        asyncio.run(write())
    finally:
        store.close()
    records = [{"step": 5000 * k, "time": 100.0 * k, "eval/success_rate": 0.5} for k in range(EPISODES // 100 + 2)]
    (directory / METRICS_FILE).write_text("".join(json.dumps(record) + "\n" for record in records))
    evaluation = {"seed": 7, "per_episode": {"success": [bool(k % 3) for k in range(30)]}}
    (directory / EVALUATION_FILE).write_text(json.dumps(evaluation))
    return directory


def parameter_rows(markdown: str) -> list[str]:
    """The parameter names of the lower/upper-half table, in its order."""
    table = markdown.split("| parameter | lower half | upper half |\n|---|---|---|\n")[1].split("\n\n")[0]
    return [line.split(" | ")[0].removeprefix("| ") for line in table.splitlines()]


@pytest.fixture(scope="module")
def book_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_run(tmp_path_factory.mktemp("book") / "random-seed1", KUKA_TASK_SPACE)


@pytest.fixture(scope="module")
def hard_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_run(tmp_path_factory.mktemp("hard") / "random-seed1", KUKA_HARD_TASK_SPACE)


@pytest.mark.parametrize(("which", "space"), [("book_run", KUKA_TASK_SPACE), ("hard_run", KUKA_HARD_TASK_SPACE)])
def test_a_run_is_read_in_its_own_space(which: str, space: TaskSpace, request: pytest.FixtureRequest) -> None:
    run = load_run(request.getfixturevalue(which))
    assert run.space.names == space.names
    assert run.unit_tasks.shape == (EPISODES, len(space))
    # A uniform teacher spends a quarter of its episodes in each band only if the bands are this space's:
    # the book's edges would put about 18% of ten-parameter tasks in each outer band.
    assert np.allclose(np.bincount(run.band, minlength=4) / EPISODES, 0.25, atol=0.03)
    assert parameter_rows(summary_markdown([run])) == list(space.names)


def test_placement_is_reported_for_the_book_and_left_out_for_the_hard_family(book_run: Path, hard_run: Path) -> None:
    book = summary_markdown([load_run(book_run)])
    assert PLACEMENT_TABLE in book and PLACEMENT_SKIPPED not in book
    assert PLACEMENT_ROW in book
    hard = summary_markdown([load_run(hard_run)])
    assert PLACEMENT_SKIPPED in hard and PLACEMENT_TABLE not in hard and PLACEMENT_ROW not in hard


def test_the_command_writes_the_placement_plot_only_for_the_book(
    book_run: Path, hard_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for name, run in (("book", book_run), ("hard", hard_run)):
        monkeypatch.setattr(sys, "argv", ["curriculum_diagnostics", str(run), "--out", str(tmp_path / name)])
        main()
    assert sorted(path.name for path in (tmp_path / "book").iterdir()) == [
        "curriculum_by_run.png",
        "success_by_placement.png",
        "summary.md",
    ]
    assert sorted(path.name for path in (tmp_path / "hard").iterdir()) == ["curriculum_by_run.png", "summary.md"]


def test_runs_of_different_spaces_are_refused(
    book_run: Path, hard_run: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys, "argv", ["curriculum_diagnostics", str(book_run), str(hard_run), "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match=r"\(6 parameters\) and .* \(10 parameters\) used different task spaces"):
        main()
    assert not any(tmp_path.iterdir())


def test_an_archived_bakeoff_run_reads_as_its_raw_files_did(tmp_path: Path) -> None:
    run_dir = write_run(tmp_path / "random-seed0", KUKA_TASK_SPACE)
    raw = load_run(run_dir)
    archive_run(run_dir)
    assert not (run_dir / DATABASE_FILE).exists() and (run_dir / f"{DATABASE_FILE}.xz").exists()
    archived = load_run(run_dir)
    assert archived.teacher == raw.teacher and archived.space.names == raw.space.names
    for field in ("unit_tasks", "success", "length", "step", "evaluation_steps", "evaluation_success", "final_success"):
        assert np.array_equal(getattr(archived, field), getattr(raw, field)), field
    assert summary_markdown([archived]) == summary_markdown([raw])
    names = sorted(path.name for path in run_dir.iterdir())
    assert names == ["evaluation.json.xz", "metrics.full.jsonl.xz", "metrics.jsonl.xz", "teacher.sqlite.xz"], (
        "no decompressed copy left behind"
    )
