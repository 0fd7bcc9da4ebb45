"""``learner/experiments/run_archive.py`` splits a run's metrics when it archives it: for git the fields the
write-ups read, on disk the full log, which ``restore_run`` puts back for a resume. Real files in a run
directory, as ``train`` writes them."""

from __future__ import annotations

import json
import lzma
import shutil
import subprocess
from pathlib import Path

import pytest

from learner.core.checkpoint import checkpoint_path, load_checkpoint
from learner.core.json_file import write_json
from learner.core.metrics import METRICS_FILE
from learner.evaluation.selection import RECORD, Validated, choice_record, run_policy
from learner.experiments.run_archive import (
    RESUME_CHECKPOINT,
    archive_run,
    full_log,
    metrics_records,
    restore_run,
    resume_files,
    thin_metrics,
    write_up_files,
)
from tests.learner.tiny_checkpoint import save_untrained_checkpoint

ROOT = Path(__file__).resolve().parents[3]
FULL_NAME = "metrics.full.jsonl.xz"
THIN_NAME = "metrics.jsonl.xz"

# Two iterations as the trainer logs them (the second with an in-run evaluation), then a line cut short.
RECORDS = [
    {
        "step": 4096,
        "time": 1795514718.4618313,
        "loss/policy_loss": -0.0019190149614587426,
        "loss/entropy": 2.755214214324951,
        "loss/action_std": 0.605288028717041,
        "iteration": 1.0,
        "train/episodes": 0.0,
        "train/offline_episodes": 0.0,
        "train/episode_reward": None,
        "train/success_rate": None,
        "train/episode_length": None,
        "workers/replacements": 0.0,
        "train/policy_lag": 0.0,
        "perf/sample_steps_per_second": 1338.6472640299794,
        "perf/wait_seconds": 3.059805304998008,
        "perf/steps_per_second": 1238.8521532846612,
    },
    {
        "step": 8192,
        "time": 1795514743.005115,
        "loss/policy_loss": -0.0012880282010883093,
        "iteration": 2.0,
        "train/episodes": 5.0,
        "train/episode_reward": -3.631758250315973,
        "train/success_rate": 0.2,
        "train/episode_length": 787.0,
        "perf/steps_per_second": 4660.5935067403025,
        "eval/return": -3.559076552436067,
        "eval/success_rate": 0.25,
        "eval/episode_length": 742.85,
        "perf/eval_seconds": 4.302848419996735,
    },
]
KEPT = [
    {
        "step": 4096,
        "time": 1795514718.4618313,
        "train/episodes": 0.0,
        "train/success_rate": None,
        "perf/steps_per_second": 1238.8521532846612,
    },
    {
        "step": 8192,
        "time": 1795514743.005115,
        "train/episodes": 5.0,
        "train/success_rate": 0.2,
        "perf/steps_per_second": 4660.5935067403025,
        "eval/return": -3.559076552436067,
        "eval/success_rate": 0.25,
        "eval/episode_length": 742.85,
    },
]
RAW = "".join(json.dumps(record) + "\n" for record in RECORDS) + '{"step": 12288, "time": 17955'


def finished_run(directory: Path) -> Path:
    """A run directory with its raw metrics log, as training leaves it."""
    directory.mkdir(parents=True)
    (directory / METRICS_FILE).write_text(RAW, encoding="utf-8")
    return directory


def old_style_archive(directory: Path) -> Path:
    """A run archived before the metrics were split: its one metrics.jsonl.xz is the full log."""
    directory.mkdir(parents=True)
    (directory / THIN_NAME).write_bytes(lzma.compress(RAW.encode(), preset=6))
    return directory


def decompressed(path: Path) -> bytes:
    return lzma.decompress(path.read_bytes())


def snapshot(directory: Path) -> dict[str, tuple[bytes, int]]:
    return {path.name: (path.read_bytes(), path.stat().st_mtime_ns) for path in directory.iterdir()}


def test_archiving_keeps_only_the_read_fields_for_git_and_the_full_log_on_disk(tmp_path: Path) -> None:
    run = finished_run(tmp_path / "run")
    archive_run(run)
    assert sorted(path.name for path in run.iterdir()) == [FULL_NAME, THIN_NAME]
    assert THIN_NAME in write_up_files() and FULL_NAME in resume_files()
    assert full_log(run / METRICS_FILE) == run / FULL_NAME
    assert decompressed(run / FULL_NAME) == RAW.encode(), "the full log, byte for byte, cut line and all"
    thin = [json.loads(line) for line in decompressed(run / THIN_NAME).decode().splitlines()]
    assert thin == KEPT, "every record, the read fields alone, in order, values unchanged"
    assert metrics_records(run) == KEPT
    archived = snapshot(run)
    archive_run(run)
    assert snapshot(run) == archived, "archiving an archived run changes nothing"


def test_a_validated_run_keeps_its_chosen_checkpoint_and_its_record_beside_the_final_one(tmp_path: Path) -> None:
    run = finished_run(tmp_path / "run")
    first = save_untrained_checkpoint(run)
    chosen, final = (Path(shutil.copy(first, checkpoint_path(run, steps))) for steps in (1024, 1536))
    candidates = [Validated(chosen, 1024, 0.9), Validated(final, 1536, 0.8)]
    write_json(run / RECORD, choice_record(run, candidates, candidates[0], 200, 200_000, 1024, 512))
    archive_run(run)
    assert sorted(path.name for path in (run / "checkpoints").iterdir()) == [chosen.name, final.name]
    assert load_checkpoint(chosen).evaluation_only and load_checkpoint(final).evaluation_only
    assert not load_checkpoint(run / RESUME_CHECKPOINT).evaluation_only
    assert RECORD in write_up_files() and (run / RECORD).exists()
    assert run_policy(run) == chosen, "the archived run still reads as the policy it chose"


def test_restoring_puts_the_full_log_back_raw_for_the_resumed_run_to_append_to(tmp_path: Path) -> None:
    run = finished_run(tmp_path / "run")
    archive_run(run)
    restore_run(run)
    assert sorted(path.name for path in run.iterdir()) == [METRICS_FILE]
    assert (run / METRICS_FILE).read_bytes() == RAW.encode()
    assert metrics_records(run) == RECORDS
    # Resumed, the run appends to its full log; archived again, both copies hold the new record.
    more = {"step": 12288, "time": 1795514800.0, "loss/entropy": 2.7, "eval/success_rate": 0.5}
    with (run / METRICS_FILE).open("a", encoding="utf-8") as log:
        log.write("\n" + json.dumps(more) + "\n")
    archive_run(run)
    assert decompressed(run / FULL_NAME) == (RAW + "\n" + json.dumps(more) + "\n").encode()
    assert metrics_records(run) == [*KEPT, {"step": 12288, "time": 1795514800.0, "eval/success_rate": 0.5}]


def test_a_run_archived_before_the_split_reads_archives_and_restores_as_before(tmp_path: Path) -> None:
    run = old_style_archive(tmp_path / "run")
    assert metrics_records(run) == RECORDS, "its one compressed log is the full one"
    archived = snapshot(run)
    archive_run(run)
    assert snapshot(run) == archived, "an archived run is left as it is"
    restore_run(run)
    assert sorted(path.name for path in run.iterdir()) == [METRICS_FILE]
    assert (run / METRICS_FILE).read_bytes() == RAW.encode()


def test_thin_metrics_splits_a_run_archived_before_the_split_once(tmp_path: Path) -> None:
    run = old_style_archive(tmp_path / "run")
    before = (run / THIN_NAME).read_bytes()
    thin_metrics(run / METRICS_FILE)
    assert (run / FULL_NAME).read_bytes() == before, "the full log kept as it was"
    assert metrics_records(run) == KEPT
    split = snapshot(run)
    thin_metrics(run / METRICS_FILE)
    assert snapshot(run) == split, "splitting twice changes nothing"
    restore_run(run)
    assert (run / METRICS_FILE).read_bytes() == RAW.encode()


def test_thin_metrics_leaves_a_thin_copy_without_its_full_log_alone(tmp_path: Path) -> None:
    """In a clone the full log is not there (git-ignored): the thin copy must not pass for it."""
    run = finished_run(tmp_path / "run")
    archive_run(run)
    (run / FULL_NAME).unlink()
    clone = snapshot(run)
    thin_metrics(run / METRICS_FILE)
    assert snapshot(run) == clone


def test_a_split_interrupted_before_the_thin_copy_is_written_finishes_when_called_again(tmp_path: Path) -> None:
    # Interrupted after the full log was copied: the git copy still holds the full log.
    run = old_style_archive(tmp_path / "old")
    (run / FULL_NAME).write_bytes((run / THIN_NAME).read_bytes())
    thin_metrics(run / METRICS_FILE)
    assert metrics_records(run) == KEPT and decompressed(run / FULL_NAME) == RAW.encode()
    # Interrupted with the raw log still there, beside a stale full log: the raw one is authoritative.
    run = finished_run(tmp_path / "raw")
    (run / FULL_NAME).write_bytes(lzma.compress(b"stale\n"))
    archive_run(run)
    assert decompressed(run / FULL_NAME) == RAW.encode() and metrics_records(run) == KEPT


def test_a_named_metrics_log_beside_others_splits_the_same_way(tmp_path: Path) -> None:
    """A tune's kept copies are named per trial (benchmarks/tune-*/metrics-TRIAL.jsonl.xz)."""
    (tmp_path / "metrics-a.jsonl.xz").write_bytes(lzma.compress(RAW.encode()))
    thin_metrics(tmp_path / "metrics-a.jsonl")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["metrics-a.full.jsonl.xz", "metrics-a.jsonl.xz"]
    thin = [json.loads(line) for line in decompressed(tmp_path / "metrics-a.jsonl.xz").decode().splitlines()]
    assert thin == KEPT and decompressed(tmp_path / "metrics-a.full.jsonl.xz") == RAW.encode()


@pytest.mark.skipif(not (ROOT / ".git").exists(), reason="needs a git checkout")
def test_git_ignores_the_full_logs_and_tracks_the_thin_ones() -> None:
    def ignored(path: str) -> bool:
        return subprocess.run(["git", "check-ignore", "-q", "--no-index", path], cwd=ROOT).returncode == 0

    assert ignored(f"benchmarks/b/runs/fixed-seed0/{FULL_NAME}") and ignored("benchmarks/t/metrics-a.full.jsonl.xz")
    assert not ignored(f"benchmarks/b/runs/fixed-seed0/{THIN_NAME}") and not ignored("benchmarks/t/metrics-a.jsonl.xz")
