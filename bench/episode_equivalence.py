"""Do the environments of this working tree play the same episodes as a baseline commit's?

A fixed set of policies plays the same seeded episodes (episode ``i`` is seeded ``seed + i``) on the hardest
task of each family asked for, once with the baseline commit's ``common`` package (exported with ``git
archive`` into a scratch directory and put first on a subprocess's path) and once with the working tree's;
everything else (the policies, the learner's code that loads the checkpoint) is the working tree's. It
prints, per family and policy, both sides' success counts and every episode whose success flag, return or
length differ, and exits 1 if any success flag does.

Policies: ``zero`` (no action), ``random`` (uniform, seeded per episode), ``scripted`` (the hand-made
controller of ``bench/task_hardness.py``) and ``checkpoint`` (the deterministic policy of
``--checkpoint``).

    .venv/bin/python bench/episode_equivalence.py --episodes 1000 --processes 2
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "e0bfb64"
"""The main that issue 45 started from."""
CHECKPOINT = ROOT / "models" / "alp-gmm-3m-seed2.pt"
POLICIES = ("zero", "random", "scripted", "checkpoint")
ENV_IDS = ("KukaGrasp-v0", "KukaGraspHard-v1")
CHUNK = 25
"""Episodes per unit of work handed to a process."""

Episode = tuple[bool, float, int]
"""Success, return, length."""


def play_chunk(env_id: str, policy: str, checkpoint: str, seeds: list[int]) -> list[Episode]:
    """Episodes of one policy on the family's hardest task, with whichever ``common`` this process imports."""
    sys.path.append(str(ROOT))  # last, so that a baseline's ``common`` on PYTHONPATH comes first
    from bench.task_hardness import episode_policy
    from common.kuka.env import make_kuka_env

    env = make_kuka_env(env_id)
    network = None
    if policy == "checkpoint":
        from common.policy.actor_critic import InferencePolicy
        from learner.core.checkpoint import load_checkpoint
        from learner.core.policy import policy_snapshot

        network = InferencePolicy(policy_snapshot(load_checkpoint(Path(checkpoint))))
    episodes = []
    for seed in seeds:
        if network is not None:
            act = lambda observation: np.clip(network.act(observation[None], deterministic=True)[0][0], -1.0, 1.0)  # noqa: E731,B023
        else:
            act = episode_policy(policy, np.random.default_rng(seed))
        observation, _ = env.reset(seed=seed)
        total, length = 0.0, 0
        while True:
            observation, reward, terminated, truncated, info = env.step(act(observation))
            total += float(reward)
            length += 1
            if terminated or truncated:
                episodes.append((bool(info["is_success"]), total, length))
                break
    env.close()
    return episodes


def play(args: argparse.Namespace) -> dict[str, Any]:
    """Every (family, policy) pair's episodes, in this process's ``common``, shared among processes."""
    import common

    seeds = list(range(args.seed, args.seed + args.episodes))
    chunks = [seeds[start : start + CHUNK] for start in range(0, len(seeds), CHUNK)]
    jobs = [(env_id, policy) for env_id in args.envs for policy in args.policies]
    with multiprocessing.get_context("spawn").Pool(args.processes) as pool:
        parts = {
            job: [pool.apply_async(play_chunk, (*job, str(args.checkpoint), chunk)) for chunk in chunks] for job in jobs
        }
        results = {
            f"{env_id}/{policy}": [e for part in parts[(env_id, policy)] for e in part.get()] for env_id, policy in jobs
        }
    return {"common": str(Path(common.__file__).parent), "results": results}


def run_side(args: argparse.Namespace, common_root: Path | None, out: Path) -> dict[str, Any]:
    """This script in ``--play`` mode, importing ``common`` from ``common_root`` (the working tree's if None)."""
    environment = dict(os.environ)
    if common_root is not None:
        environment["PYTHONPATH"] = os.pathsep.join(filter(None, [str(common_root), environment.get("PYTHONPATH")]))
    command = [sys.executable, __file__, "--play", str(out), "--episodes", str(args.episodes), "--seed", str(args.seed),
               "--processes", str(args.processes), "--checkpoint", str(args.checkpoint),
               "--envs", *args.envs, "--policies", *args.policies]  # fmt: skip
    subprocess.run(command, cwd=ROOT, env=environment, check=True)
    side: dict[str, Any] = json.loads(out.read_text())
    return side


def compare(baseline: dict[str, Any], current: dict[str, Any], seed: int) -> int:
    """Print the comparison; the number of episodes whose success flag differs."""
    flag_mismatches = 0
    for key, before in baseline["results"].items():
        after = current["results"][key]
        flags = [i for i, (b, a) in enumerate(zip(before, after, strict=True)) if b[0] != a[0]]
        returns = [i for i, (b, a) in enumerate(zip(before, after, strict=True)) if b[1] != a[1]]
        lengths = [i for i, (b, a) in enumerate(zip(before, after, strict=True)) if b[2] != a[2]]
        flag_mismatches += len(flags)
        successes = (sum(e[0] for e in before), sum(e[0] for e in after))
        mean_returns = (np.mean([e[1] for e in before]), np.mean([e[1] for e in after]))
        print(f"{key:30s} successes {successes[0]:4d} -> {successes[1]:4d} of {len(before)}; "
              f"mean return {mean_returns[0]:7.3f} -> {mean_returns[1]:7.3f}; differing episodes: "
              f"success {len(flags)}, return {len(returns)}, length {len(lengths)}")  # fmt: skip
        for i in sorted(set(flags) | set(returns) | set(lengths))[:10]:
            print(f"    seed {seed + i}: {tuple(before[i])} -> {tuple(after[i])}")
    return flag_mismatches


def export_commit(commit: str, destination: Path, *paths: str) -> Path:
    """Extract ``paths`` (the whole tree if none) of ``commit`` into ``destination``, created (``git archive``)."""
    destination.mkdir()
    archive = subprocess.run(["git", "archive", commit, *paths], cwd=ROOT, capture_output=True, check=True)
    subprocess.run(["tar", "-x", "-C", str(destination)], input=archive.stdout, check=True)
    return destination


def add_new_modules(exported: Path) -> list[str]:
    """Copy into the exported baseline the working tree's ``common`` modules it lacks (the policies may import
    them); every module the baseline has stays the baseline's. Their names, for the report."""
    added = []
    for source in sorted((ROOT / "common").rglob("*.py")):
        relative = source.relative_to(ROOT)
        if not (exported / relative).exists():
            (exported / relative).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, exported / relative)
            added.append(str(relative))
    return added


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline", default=BASELINE, help=f"commit to compare against (default {BASELINE})")
    parser.add_argument("--episodes", type=int, default=1000, help="episodes per family and policy (default 1000)")
    parser.add_argument("--seed", type=int, default=0, help="episode i is seeded seed + i (default 0)")
    parser.add_argument("--processes", type=int, default=2, help="worker processes per side (default 2)")
    parser.add_argument("--envs", nargs="+", choices=ENV_IDS, default=list(ENV_IDS))
    parser.add_argument("--policies", nargs="+", choices=POLICIES, default=list(POLICIES))
    parser.add_argument("--checkpoint", type=Path, default=CHECKPOINT, help="the checkpoint policy's file")
    parser.add_argument("--json", type=Path, help="also write both sides' episodes here")
    parser.add_argument("--play", type=Path, help=argparse.SUPPRESS)  # one side, written to this file
    args = parser.parse_args()
    if args.episodes < 1 or args.processes < 1:
        parser.error("--episodes and --processes must be at least 1")
    if args.play is not None:
        args.play.write_text(json.dumps(play(args)))
        return

    with tempfile.TemporaryDirectory() as scratch:
        exported = export_commit(args.baseline, Path(scratch) / "baseline", "common")
        added = add_new_modules(exported)
        baseline = run_side(args, exported, Path(scratch) / "baseline.json")
        current = run_side(args, None, Path(scratch) / "current.json")
    print(f"baseline {args.baseline}: common from {baseline['common']}; working tree: {current['common']}")
    print(f"modules the baseline lacks, taken from the working tree: {', '.join(added) or 'none'}")
    print(f"{args.episodes} episodes per family and policy on the hardest task, episode seeds {args.seed} to "
          f"{args.seed + args.episodes - 1}")  # fmt: skip
    mismatches = compare(baseline, current, args.seed)
    if args.json is not None:
        sides = {"before": baseline["results"], "after": current["results"]}
        run = {"baseline": args.baseline, "episodes": args.episodes, "seed": args.seed}
        args.json.write_text(json.dumps({**run, **sides}))
    print(f"success flags that differ: {mismatches}")
    sys.exit(1 if mismatches else 0)


if __name__ == "__main__":
    main()
