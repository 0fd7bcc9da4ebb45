"""The validated policy: of a run's late checkpoints, the one that does best on validation episodes.

A run's last checkpoint is not always its best: on the hard family a student can lose late what it had, after
its teacher has reached the target (docs/results/student.md, lever 5). Choosing among checkpoints on episodes
that no other evaluation plays is model selection, as Stable-Baselines3's ``EvalCallback`` keeps its best model;
the episodes that then score the chosen policy stay untouched by the choice.

``train --policy-choice validated`` makes the choice when a run finishes and records it in the run's
``validated-policy.json``; ``evaluate`` and ``render`` then play the chosen checkpoint when given the run.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from learner.core.checkpoint import checkpoint_steps, latest_checkpoint, load_checkpoint, run_checkpoints
from learner.core.json_file import write_json

VALIDATION_SEED = 200_000
"""Where the validation episodes' seeds start: above the in-run evaluations' (10,000 to 99,999) and the final
evaluations' (a screen's from 20,000, a bake-off's from 100,000), so no episode that scores a policy chose it."""
VALIDATION_EPISODES = 200
RECORD = "validated-policy.json"
"""The choice, in the run directory: every candidate's validation success and the chosen checkpoint."""


class UnreadableRecord(ValueError):
    """A run's ``RECORD`` that cannot say which checkpoint it chose (edited by hand, or its checkpoint gone)."""


def schedule(total_steps: int) -> tuple[int, int]:
    """The first candidate's step and the steps between candidates for a run's budget: its second half, every
    twelfth of it (3M and 0.5M on the hard family's 6M, where CURROT is still moving the tasks before 3M)."""
    return total_steps // 2, max(1, total_steps // 12)


def run_schedule(run_dir: Path) -> tuple[int, int]:
    """``schedule`` of the budget the run trained to, as its last checkpoint records it."""
    final = latest_checkpoint(run_dir)
    if final is None:
        raise ValueError(f"{run_dir}: no checkpoints")
    return schedule(load_checkpoint(final).config.total_steps)


@dataclass(frozen=True)
class Validated:
    """A candidate checkpoint and its success on the validation episodes."""

    path: Path
    steps: int
    success: float


def candidate_checkpoints(run_dir: Path, first_step: int, every: int) -> list[Path]:
    """For each of ``first_step``, ``first_step + every``, ... below the run's last checkpoint, its first
    checkpoint at or after that step, and its last checkpoint; in step order, each once."""
    if first_step < 0 or every < 1:
        raise ValueError(f"first_step must be at least 0 and every at least 1, got {first_step} and {every}")
    found = [(checkpoint_steps(path), path) for path in run_checkpoints(run_dir)]
    if not found:
        raise ValueError(f"{run_dir}: no checkpoints")
    last_steps, last = found[-1]
    candidates: list[Path] = []
    for mark in range(first_step, last_steps, every):
        first = next(path for steps, path in found if steps >= mark)
        if first not in candidates:
            candidates.append(first)
    if last not in candidates:
        candidates.append(last)
    return candidates


def choose(validated: Sequence[Validated]) -> Validated:
    """The candidate with the highest validation success; of equals, the later one (it trained longer on the
    same tasks, and a run without a better earlier checkpoint keeps its final policy)."""
    if not validated:
        raise ValueError("no candidates to choose from")
    return max(validated, key=lambda candidate: (candidate.success, candidate.steps))


def validate(
    run_dir: Path,
    first_step: int,
    every: int,
    success: Callable[[Path], float],
    on_candidate: Callable[[Validated], None],
) -> list[Validated]:
    """Every candidate checkpoint with its validation success (``success`` plays a checkpoint's file)."""
    validated = []
    for path in candidate_checkpoints(run_dir, first_step, every):
        validated.append(Validated(path, checkpoint_steps(path), success(path)))
        on_candidate(validated[-1])
    return validated


def choose_validated_policy(
    run_dir: Path,
    episodes: int = VALIDATION_EPISODES,
    seed: int = VALIDATION_SEED,
    processes: int | None = None,
    report: Callable[[str], None] = print,
) -> Validated:
    """A finished run's validated policy, chosen by its budget's ``schedule`` and written to its ``RECORD``;
    a record of the run as it stands is read, not made again."""
    from learner.evaluation.checkpoint_evaluation import evaluate_checkpoint  # torch and the environments

    current = recorded_choice(run_dir)
    if current is not None:
        return current
    first_step, every = run_schedule(run_dir)

    def success(path: Path) -> float:
        checkpoint = load_checkpoint(path)
        task = checkpoint.config.evaluation_task()
        result = evaluate_checkpoint(checkpoint, task, episodes, seed, processes, progress=False)
        return result.success_rate.estimate

    def on_candidate(candidate: Validated) -> None:
        report(f"validation: {candidate.path.name} grasps {candidate.success:.1%} of {episodes} episodes")

    validated = validate(run_dir, first_step, every, success, on_candidate)
    chosen = choose(validated)
    write_json(run_dir / RECORD, choice_record(run_dir, validated, chosen, episodes, seed, first_step, every))
    report(f"validated policy: {chosen.path.name} (written to {run_dir / RECORD})")
    return chosen


def choice_record(
    run_dir: Path, validated: Sequence[Validated], chosen: Validated, episodes: int, seed: int, first: int, every: int
) -> dict[str, Any]:
    """What ``RECORD`` holds: the rule, every candidate's validation success and the choice."""
    return {
        "rule": {
            "first_step": first,
            "every": every,
            "validation_episodes": episodes,
            "validation_seed": seed,
            "choice": "the highest validation success; a tie goes to the later checkpoint",
        },
        "candidates": [
            {"checkpoint": str(each.path.relative_to(run_dir)), "steps": each.steps, "validation_success": each.success}
            for each in validated
        ],
        "chosen": str(chosen.path.relative_to(run_dir)),
    }


def recorded_choice(run_dir: Path) -> Validated | None:
    """The run's recorded validated policy while the record is current, its last candidate the run's last
    checkpoint (a run trained on past its record is chosen again); None without one. The record is written
    whole or not at all (``write_json``); one that cannot say what it chose raises ``UnreadableRecord``, since
    playing another checkpoint in its place would score a policy the user did not ask for."""
    record_path = run_dir / RECORD
    if not record_path.is_file():
        return None
    final = latest_checkpoint(run_dir)
    try:
        record = json.loads(record_path.read_text(encoding="utf-8"))
        last_candidate = record["candidates"][-1]["checkpoint"]
        if final is None or last_candidate != str(final.relative_to(run_dir)):
            return None
        chosen = next(each for each in record["candidates"] if each["checkpoint"] == record["chosen"])
        validated = Validated(run_dir / chosen["checkpoint"], int(chosen["steps"]), float(chosen["validation_success"]))
    except (ValueError, KeyError, IndexError, TypeError, StopIteration) as error:
        raise UnreadableRecord(
            f"{record_path} does not say which checkpoint it chose ({error!r}); "
            "delete it and the run's policy is chosen again"
        ) from None
    if not validated.path.is_file():
        raise UnreadableRecord(
            f"{record_path} chose {validated.path.name}, which is not in the run any more; "
            "delete it and the run's policy is chosen again"
        )
    return validated


def run_policy(run_dir: Path) -> Path | None:
    """The checkpoint that is the run's policy: its recorded validated one, else its latest; None without any."""
    validated = recorded_choice(run_dir)
    return latest_checkpoint(run_dir) if validated is None else validated.path
