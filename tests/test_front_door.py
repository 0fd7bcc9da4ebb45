"""What a newcomer meets first: ``kuka-curriculum --version``, ``import common`` registering the KUKA
environments as it did before the rooms, and a local training start without Ray's token warning."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def python(code: str, **environment: str) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter, as a user's script would run it."""
    env = {key: value for key, value in os.environ.items() if key != "RAY_AUTH_MODE"}
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=240, check=False, cwd=ROOT,
        env={**env, **environment},
    )  # fmt: skip


def test_version_prints_the_version_in_pyproject() -> None:
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    result = python("import sys, kuka_curriculum; sys.exit(kuka_curriculum.main(['--version']))")
    assert (result.returncode, result.stdout) == (0, f"kuka-curriculum {version}\n"), result.stderr


def test_import_common_registers_the_kuka_environments_without_loading_pybullet() -> None:
    result = python(
        "import sys, gymnasium, common\n"
        "print(sorted(i for i in gymnasium.registry if i.startswith('Kuka')), 'pybullet' in sys.modules)\n"
        "env = gymnasium.make('KukaGrasp-v0')\n"
        "print(env.reset(seed=0)[0].shape)\n"
    )
    assert result.returncode == 0, result.stderr
    registered, made = result.stdout.splitlines()
    assert registered == "['KukaGrasp-v0', 'KukaGraspHard-v0', 'KukaGraspHard-v1'] False"
    assert made == "(9,)"


def test_a_new_local_ray_cluster_keeps_token_authentication_without_the_warning(tmp_path: Path) -> None:
    """Ray turns tokens on for a new local cluster and warns that it chose so; the learner chooses the same."""
    result = python(
        "import contextlib, os\n"
        "from learner.job.session import connect_ray\n"
        "with contextlib.ExitStack() as stack:\n"
        "    connect_ray(None, 1, stack)\n"
        "    print(os.environ['RAY_AUTH_MODE'])\n",
        HOME=str(tmp_path),  # where Ray keeps the token it makes: ~/.ray/auth_token
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout == "token\n"
    assert (tmp_path / ".ray" / "auth_token").is_file()
    assert "authentication" not in result.stderr.lower(), result.stderr
