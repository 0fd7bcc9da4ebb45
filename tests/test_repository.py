"""The repository's own gates (``make check``): the lock files agree with pyproject.toml, no tracked
file is over 5 MB, and the tracked files outside models/ keep within a total. Each runs as ``make``
runs it, on this checkout and on a copy with a planted fault that it must refuse."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LOCK_CHECK = ROOT / ".ci" / "lock.py"
LARGE_FILES = ROOT / ".ci" / "large_files.py"
LOCK_INPUTS = ("pyproject.toml", "constraints.txt", "requirements.txt", "requirements-dev.txt")


def run(script: Path, *arguments: str | Path) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, str(script), *map(str, arguments)]
    return subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)


@pytest.fixture
def lock_copy(tmp_path: Path) -> Path:
    for name in LOCK_INPUTS:
        shutil.copy(ROOT / name, tmp_path / name)
    return tmp_path


def replace_once(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert text.count(old) == 1, f"{old!r} is not in {path.name} exactly once"
    path.write_text(text.replace(old, new))


def test_the_committed_locks_agree_with_pyproject() -> None:
    result = run(LOCK_CHECK, "check")
    assert result.returncode == 0, result.stderr


def test_every_lock_pin_carries_a_hash_and_the_cpu_torch_of_constraints() -> None:
    for name in ("requirements.txt", "requirements-dev.txt"):
        text = (ROOT / name).read_text()
        assert "--hash=sha256:" in text
        assert re.search(r"^torch==2\.13\.0\+cpu \\$", text, re.MULTILINE), f"{name} lost the CPU torch"
    runtime, dev = ((ROOT / name).read_text() for name in ("requirements.txt", "requirements-dev.txt"))
    pin = re.compile(r"^([\w.-]+)==(\S+)", re.MULTILINE)
    dev_pins = dict(pin.findall(dev))
    differing = {
        name: (version, dev_pins[name])
        for name, version in pin.findall(runtime)
        if dev_pins.get(name, version) != version
    }
    assert not differing, f"the Docker image and the dev venv would install different releases: {differing}"


def test_a_dependency_raised_in_pyproject_fails_the_check(lock_copy: Path) -> None:
    replace_once(lock_copy / "pyproject.toml", '    "numpy>=1.24",\n', '    "numpy>=99",\n')
    result = run(LOCK_CHECK, "check", "--root", lock_copy)
    assert result.returncode == 1
    assert "requirements.txt was compiled from another pyproject.toml" in result.stderr
    assert re.search(r"requirements-dev\.txt pins numpy==\S+, outside numpy>=99", result.stderr), result.stderr
    assert "make lock" in result.stderr


def test_a_new_dependency_without_a_pin_fails_the_check(lock_copy: Path) -> None:
    replace_once(lock_copy / "pyproject.toml", '    "pytest>=8.0",\n', '    "pytest>=8.0",\n    "left-pad>=1",\n')
    result = run(LOCK_CHECK, "check", "--root", lock_copy)
    assert result.returncode == 1
    assert "requirements-dev.txt pins nothing for left-pad>=1" in result.stderr
    assert "requirements.txt pins nothing" not in result.stderr, "the runtime lock does not hold the dev extra"


def test_a_lock_pin_edited_by_hand_fails_the_check(lock_copy: Path) -> None:
    text = (lock_copy / "requirements.txt").read_text()
    [fastapi] = re.findall(r"^fastapi==\S+", text, re.MULTILINE)
    replace_once(lock_copy / "requirements.txt", fastapi, "fastapi==0.100.0")
    result = run(LOCK_CHECK, "check", "--root", lock_copy)
    assert result.returncode == 1
    assert "requirements.txt pins fastapi==0.100.0, outside fastapi>=0.110" in result.stderr


def test_a_pyproject_change_outside_the_dependencies_needs_no_new_lock(lock_copy: Path) -> None:
    replace_once(lock_copy / "pyproject.toml", "line-length = 120", "line-length = 100")
    result = run(LOCK_CHECK, "check", "--root", lock_copy)
    assert result.returncode == 0, result.stderr


def test_stamp_records_the_inputs_so_a_fresh_compile_passes(lock_copy: Path) -> None:
    replace_once(lock_copy / "constraints.txt", "torch==2.13.0", "torch==2.13.0  # moved comment")
    replace_once(lock_copy / "pyproject.toml", '"tqdm>=4.66"', '"tqdm>=4.60"')
    stale = run(LOCK_CHECK, "check", "--root", lock_copy)
    assert stale.returncode == 1 and "requirements.txt was compiled from another" in stale.stderr, stale.stderr
    assert run(LOCK_CHECK, "stamp", "--root", lock_copy).returncode == 0
    result = run(LOCK_CHECK, "check", "--root", lock_copy)
    assert result.returncode == 0, result.stderr


def git(repository: Path, *arguments: str) -> None:
    subprocess.run(["git", "-C", str(repository), *arguments], check=True, capture_output=True)


def test_this_checkout_keeps_within_the_size_limits() -> None:
    result = run(LARGE_FILES)
    assert result.returncode == 0, result.stderr


def test_a_file_over_the_limit_is_refused(tmp_path: Path) -> None:
    git(tmp_path, "init", "--quiet")
    (tmp_path / "small.bin").write_bytes(b"\0" * 4_000_000)
    (tmp_path / "big dir").mkdir()
    (tmp_path / "big dir" / "teacher.sqlite").write_bytes(b"\0" * 5_000_001)
    git(tmp_path, "add", ".")

    refused = run(LARGE_FILES, "--root", tmp_path)
    assert refused.returncode == 1
    assert "big dir/teacher.sqlite (5,000,001 bytes)" in refused.stderr and "small.bin" not in refused.stderr

    git(tmp_path, "rm", "--quiet", "--cached", "big dir/teacher.sqlite")
    assert run(LARGE_FILES, "--root", tmp_path).returncode == 0


def test_the_total_outside_models_is_bounded_and_models_do_not_count(tmp_path: Path) -> None:
    git(tmp_path, "init", "--quiet")
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "policy.pt").write_bytes(b"\0" * 3_000_000)
    (tmp_path / "results.json").write_bytes(b"\0" * 1_000_000)
    git(tmp_path, "add", ".")
    within = run(LARGE_FILES, "--root", tmp_path, "--total-limit", "1500000")
    assert within.returncode == 0 and "1,000,000 bytes outside models/" in within.stdout, within.stderr

    (tmp_path / "curves.png").write_bytes(b"\0" * 600_000)
    git(tmp_path, "add", ".")
    over = run(LARGE_FILES, "--root", tmp_path, "--total-limit", "1500000")
    assert over.returncode == 1
    assert "total 1,600,000 bytes, over 1,500,000" in over.stderr and "results.json (1,000,000 bytes)" in over.stderr


def test_a_large_file_only_in_the_working_tree_is_not_counted(tmp_path: Path) -> None:
    """The index is what a commit would hold: an untracked big file (a run directory) is no concern here."""
    git(tmp_path, "init", "--quiet")
    (tmp_path / "teacher.sqlite").write_bytes(b"\0" * 5_000_001)
    result = run(LARGE_FILES, "--root", tmp_path)
    assert result.returncode == 0, result.stderr
