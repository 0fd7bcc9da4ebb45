"""Where each teacher spent its training budget, and what the student made of it.

Reads finished training runs (a bake-off's ``runs/<teacher>-seed<k>`` directories, or any ``train``
run directory): every episode's task, success and length from the run's own teacher database, and
its environment step from the run's metrics log. The task space is the one stored with the run's
curriculum (the book's six parameters, or ``KukaGraspHard-v0``'s ten), and the runs of one invocation
must share it. Writes plots and a markdown summary:

- hardness: each parameter's distance from its easiest value on the unit scale (0 = easiest,
  1 = hardest), its mean over training per parameter, and a task's difficulty band: the quartile of
  its mean hardness among uniformly drawn tasks of the run's space (so a uniform teacher spends a
  quarter of its episodes in each band); the share of environment steps in each band over training,
  and the success rate in each;
- the budget at the student's frontier: each episode is classed by how its 20 nearest earlier
  tasks (among the last 1,000, unit scale) went: *mastered* (90% or more succeeded), *unsolved so
  far* (10% or less) or *learning*; the share of steps in each class over training;
- what makes a task hard for this student: the success rate in the lower and upper half of each
  parameter's range, over the last third of every run;
- the in-run success on the hardest task, for reading the above against;
- coverage of the test, in the book's space only: the ``rnd_*`` parameters scale the uniforms that
  place the block (x, y, yaw), so a task with ``rnd`` below 1 never puts it in the outer part of its
  range. The share of training steps whose placement could fall in the outer tenth, against the
  hardest task's 10%, and the final evaluation's success by where its block was placed (read from
  each episode's seed: the environment's first draw after a seeded reset places the block). In
  ``KukaGraspHard-v0`` ``obj_far`` moves the block toward a point drawn after those uniforms, so
  they no longer say where it lies, and the section is left out.

    .venv/bin/python bench/curriculum_diagnostics.py runs/bakeoff/runs/* --out benchmarks/diagnostics
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
from gymnasium.utils.seeding import np_random
from matplotlib.figure import Figure

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: the checkout's packages
from common.client.task_space import TaskSpace  # noqa: E402
from common.kuka.task_space import KUKA_TASK_SPACE  # noqa: E402
from learner.core.config import TrainConfig  # noqa: E402
from learner.core.figure_file import save_png  # noqa: E402
from learner.experiments.bakeoff_runs import RUNS_DIR  # noqa: E402
from learner.experiments.run_archive import EVALUATION_FILE, exists, metrics_records, read_json, unpacked  # noqa: E402
from learner.job.teacher_process import DATABASE_FILE  # noqa: E402
from teacher_service.curriculum_spec import stored_spec  # noqa: E402
from teacher_service.store import Store  # noqa: E402

BAND_LABELS = ("easiest quarter", "second", "third", "hardest quarter")
WINDOWS = 10
"""Equal slices of the step budget that shares and rates are reported over."""
PLACEMENT_DRAWS = {"rnd_obj_x": 0, "rnd_obj_y": 1, "rnd_obj_ang": 2}
"""Which of the three placement uniforms (x, y, yaw, drawn in this order) each ``rnd_*`` parameter scales."""
PLACEMENT_SKIPPED = (
    "Coverage of the test: left out, as only the book's six-parameter space places the block by the `rnd_*` "
    "uniforms alone (in KukaGraspHard-v0 `obj_far` moves it toward a point drawn after them)."
)
PLACEMENT_EDGES = (0.5, 0.75, 0.9)
PLACEMENT_LABELS = ("inner half", "0.5 to 0.75", "0.75 to 0.9", "outer tenth")
NEIGHBOURS = 20
RECENT = 1000
MASTERED, UNSOLVED = 0.9, 0.1
CLASSES = ("mastered", "learning", "unsolved so far")


def easiest_unit(space: TaskSpace) -> np.ndarray:
    """The space's easiest task on the unit scale: hardness is the distance from it."""
    return space.to_unit(space.to_array(space.easiest()))


@cache
def band_edges(space: TaskSpace) -> np.ndarray:
    """Difficulty quartiles of uniformly drawn tasks, so a uniform teacher puts a quarter of its tasks in each
    band. Computed per space: the mean hardness of more parameters spreads less around its middle."""
    easiest = easiest_unit(space)
    hardness = np.abs(np.random.default_rng(0).random((200_000, len(space))) - easiest).mean(axis=1)
    edges: np.ndarray = np.quantile(hardness, [0.25, 0.5, 0.75])
    return edges


@dataclass(frozen=True)
class RunData:
    """One run's episodes in the order its teacher learned from them."""

    name: str
    teacher: str
    """The teacher and any parameters that differ from training's defaults for it."""
    space: TaskSpace
    """The task space the run's curriculum was registered with, as stored in its teacher database."""
    unit_tasks: np.ndarray
    """(episodes, parameters): each task on the unit scale of its parameters."""
    success: np.ndarray
    length: np.ndarray
    step: np.ndarray
    """The environment step at which the teacher received the episode's result."""
    total_steps: int
    evaluation_steps: np.ndarray
    evaluation_success: np.ndarray
    final_placements: np.ndarray
    """(episodes, 3): the first three uniforms of each final evaluation episode, which place the block (x, y,
    yaw) in the book's space; empty if none."""
    final_success: np.ndarray

    @property
    def hardness(self) -> np.ndarray:
        """(episodes, parameters): each parameter's distance from its easiest value, 0 to 1."""
        result: np.ndarray = np.abs(self.unit_tasks - easiest_unit(self.space))
        return result

    @property
    def band(self) -> np.ndarray:
        """Difficulty quartile (see ``band_edges``) of the mean hardness over parameters."""
        bands: np.ndarray = np.digitize(self.hardness.mean(axis=1), band_edges(self.space))
        return bands

    @property
    def window(self) -> np.ndarray:
        windows: np.ndarray = np.minimum(self.step * WINDOWS // max(self.total_steps, 1), WINDOWS - 1)
        return windows


def load_run(run_dir: Path) -> RunData:
    """A run's episodes, read in the task space its curriculum was registered with, not an assumed one."""
    with unpacked(run_dir / DATABASE_FILE) as database:
        store = Store(database)
        try:
            [curriculum] = store.curricula()
            results = list(store.results(curriculum.id))
            spec = json.loads(curriculum.spec)
        finally:
            store.close()
    space = stored_spec(curriculum.spec).task_space()
    defaults = TrainConfig(teacher=spec["teacher"]).teacher_params
    changed = [f"{name}={json.dumps(value)}" for name, value in spec["params"].items() if defaults.get(name) != value]
    changed += [f"no {name}" for name in defaults if name not in spec["params"]]
    teacher = " ".join([spec["teacher"], *changed])
    placements, final_success = np.empty((0, 3)), np.empty(0, dtype=bool)
    if exists(run_dir / EVALUATION_FILE):
        evaluation = read_json(run_dir / EVALUATION_FILE)
        final_success = np.array(evaluation["per_episode"]["success"], dtype=bool)
        seeds = range(evaluation["seed"], evaluation["seed"] + len(final_success))
        placements = np.array([np_random(seed)[0].random(3) for seed in seeds])
    records = metrics_records(run_dir)
    times = np.array([record["time"] for record in records])
    steps = np.array([record["step"] for record in records])
    received = np.array([result.received_at for result in results])
    evaluations = [(r["step"], r["eval/success_rate"]) for r in records if r.get("eval/success_rate") is not None]
    bakeoff = run_dir.parent.parent.name if run_dir.parent.name == RUNS_DIR else None
    return RunData(
        name=f"{bakeoff}/{run_dir.name}" if bakeoff else run_dir.name,
        teacher=teacher,
        space=space,
        unit_tasks=space.to_unit(np.array([space.to_array(r.task) for r in results])),
        success=np.array([bool(r.success) for r in results]),
        length=np.array([r.length or 0 for r in results]),
        step=np.interp(received, times, steps).astype(np.int64),
        total_steps=int(steps[-1]),
        evaluation_steps=np.array([step for step, _ in evaluations]),
        evaluation_success=np.array([rate for _, rate in evaluations]),
        final_placements=placements,
        final_success=final_success,
    )


def common_space(runs: Sequence[RunData]) -> TaskSpace:
    """The task space every run used; ``ValueError`` for a mix, whose hardness and bands would not compare."""
    first = runs[0]
    for run in runs[1:]:
        if run.space != first.space:
            raise ValueError(
                f"{first.name} ({len(first.space)} parameters) and {run.name} ({len(run.space)} parameters) used "
                "different task spaces; give each space's runs on their own"
            )
    return first.space


def places_block_as_in_book(space: TaskSpace) -> bool:
    """Whether the three ``rnd_*``-scaled uniforms alone place the block, as the coverage section assumes."""
    return space.names == KUKA_TASK_SPACE.names


def outer_tenth_share(run: RunData) -> dict[str, float]:
    """Per ``rnd_*`` parameter: the share of training steps whose block could land in the outer tenth
    of its placement range, and did with this probability (``1 - 0.9 / rnd``)."""
    shares = {}
    for name in PLACEMENT_DRAWS:
        scale = run.unit_tasks[:, run.space.names.index(name)]
        chance = np.clip(1.0 - PLACEMENT_EDGES[-1] / np.maximum(scale, 1e-12), 0.0, None)
        shares[name] = float(np.average(chance, weights=np.maximum(run.length, 1)))
    return shares


def success_by_placement(runs: Sequence[RunData], name: str) -> list[tuple[float, int]]:
    """The final evaluations' success rate, and episode count, per placement band of one ``rnd_*`` draw."""
    draws = np.concatenate([run.final_placements[:, PLACEMENT_DRAWS[name]] for run in runs])
    success = np.concatenate([run.final_success for run in runs])
    bands = np.digitize(draws, PLACEMENT_EDGES)
    return [
        (float(success[bands == band].mean()) if (bands == band).any() else float("nan"), int((bands == band).sum()))
        for band in range(len(PLACEMENT_LABELS))
    ]


def frontier_classes(run: RunData) -> np.ndarray:
    """0 mastered, 1 learning, 2 unsolved so far, -1 too little history: from the nearest earlier tasks."""
    classes = np.full(len(run.success), -1)
    for index in range(NEIGHBOURS, len(run.success)):
        start = max(0, index - RECENT)
        distances = np.linalg.norm(run.unit_tasks[start:index] - run.unit_tasks[index], axis=1)
        nearest = np.argpartition(distances, NEIGHBOURS - 1)[:NEIGHBOURS]
        rate = run.success[start:index][nearest].mean()
        classes[index] = 0 if rate >= MASTERED else 2 if rate <= UNSOLVED else 1
    return classes


def step_shares(run: RunData, labels: np.ndarray, count: int) -> np.ndarray:
    """(windows, count): the share of each window's environment steps whose episode has each label."""
    shares = np.zeros((WINDOWS, count))
    for window in range(WINDOWS):
        inside = run.window == window
        total = run.length[inside & (labels >= 0)].sum()
        for label in range(count):
            shares[window, label] = run.length[inside & (labels == label)].sum() / total if total else np.nan
    return shares


def band_success(run: RunData) -> np.ndarray:
    """(windows, bands): the success rate of each difficulty band's episodes in each window."""
    rates = np.full((WINDOWS, len(BAND_LABELS)), np.nan)
    for window in range(WINDOWS):
        for band in range(len(BAND_LABELS)):
            chosen = (run.window == window) & (run.band == band)
            if chosen.sum() >= 5:
                rates[window, band] = run.success[chosen].mean()
    return rates


def plot_runs(runs: Sequence[RunData], out: Path) -> Path:
    """One row per run: steps per band, success per band, frontier classes, hardest-task success."""
    figure = Figure(figsize=(22, 3.2 * len(runs)), layout="constrained")
    axes = figure.subplots(len(runs), 5, squeeze=False)
    centres = (np.arange(WINDOWS) + 0.5) / WINDOWS
    for row, run in zip(axes, runs, strict=True):
        steps = centres * run.total_steps
        hardness = run.hardness
        for index, name in enumerate(run.space.names):
            means = [hardness[run.window == window, index].mean() for window in range(WINDOWS)]
            row[0].plot(steps, means, label=name)
        row[0].set_ylabel(f"{run.name}\nhardness (0 easiest, 1 hardest)")
        budget = step_shares(run, run.band, len(BAND_LABELS))
        row[1].stackplot(steps, budget.T, labels=BAND_LABELS, alpha=0.8)
        row[1].axhline(0.5, color="black", linewidth=0.5)
        row[1].set_ylabel("share of steps")
        success = band_success(run)
        for band, label in enumerate(BAND_LABELS):
            row[2].plot(steps, success[:, band], marker="o", label=label)
        row[2].set_ylabel("success rate")
        classes = step_shares(run, frontier_classes(run), len(CLASSES))
        row[3].stackplot(steps, classes.T, labels=CLASSES, colors=("tab:green", "tab:orange", "tab:red"))
        row[3].set_ylabel("share of steps")
        row[4].plot(run.evaluation_steps, run.evaluation_success, color="black")
        row[4].set_ylabel("hardest-task success")
        for axes_ in row:
            axes_.set_ylim(0, 1.02)
            axes_.grid(alpha=0.3)
    titles = (
        "mean hardness per parameter",
        "steps per difficulty band (uniform: 25% each)",
        "success per difficulty band",
        "steps at the student's frontier",
        "in-run evaluation",
    )
    for axes_, title in zip(axes[0], titles, strict=True):
        axes_.set_title(title)
    axes[0][0].legend(loc="upper left", fontsize="small", ncols=-(-len(runs[0].space) // 6))
    for column, place in ((1, "lower left"), (2, "lower right"), (3, "lower left")):
        axes[0][column].legend(loc=place, fontsize="small")
    for axes_ in axes[-1]:
        axes_.set_xlabel("environment steps")
    path = out / "curriculum_by_run.png"
    save_png(figure, path, dpi=90)
    return path


def plot_placement(runs: Sequence[RunData], out: Path) -> Path:
    """Final-evaluation success by where the block was placed, one line per teacher, one panel per draw."""
    figure = Figure(figsize=(15, 4), layout="constrained")
    panels = figure.subplots(1, len(PLACEMENT_DRAWS), sharey=True)
    teachers = dict.fromkeys(run.teacher for run in runs if len(run.final_success))
    for axes, name in zip(panels, PLACEMENT_DRAWS, strict=True):
        for teacher in teachers:
            members = [run for run in runs if run.teacher == teacher and len(run.final_success)]
            rates = [rate for rate, _ in success_by_placement(members, name)]
            axes.plot(PLACEMENT_LABELS, rates, marker="o", label=f"{teacher} ({len(members)} runs)")
        axes.set_title(f"block placement drawn for {name}")
        axes.set_ylim(0, 1.02)
        axes.grid(alpha=0.3)
    panels[0].set_ylabel("final hardest-task success")
    panels[0].legend(loc="lower left", fontsize="small")
    path = out / "success_by_placement.png"
    save_png(figure, path, dpi=90)
    return path


def parameter_effects(runs: Sequence[RunData]) -> dict[str, tuple[float, float, int]]:
    """Per parameter: success in the lower and upper half of its unit range, last third of every run."""
    late = [
        (run.unit_tasks[run.step >= 2 * run.total_steps // 3], run.success[run.step >= 2 * run.total_steps // 3])
        for run in runs
    ]
    tasks = np.concatenate([tasks for tasks, _ in late])
    success = np.concatenate([success for _, success in late])

    def rate(chosen: np.ndarray) -> float:
        """NaN for a half the teacher never drew from (CURROT's particles end in one corner)."""
        return float(success[chosen].mean()) if chosen.any() else float("nan")

    effects = {}
    for index, name in enumerate(common_space(runs).names):
        upper = tasks[:, index] >= 0.5
        effects[name] = (rate(~upper), rate(upper), len(success))
    return effects


def placement_markdown(runs: Sequence[RunData]) -> list[str]:
    """The coverage-of-the-test section, or one line saying why it is left out for these runs' space."""
    if not places_block_as_in_book(common_space(runs)):
        return [PLACEMENT_SKIPPED]
    lines = [
        "Coverage of the test: the share of training steps whose block could land in the outer tenth of its "
        "placement range (the hardest task: 10%), and the final evaluation's success by where the block was "
        "placed, pooled over the runs of a teacher (episodes in brackets):",
        "",
        "| run | outer tenth of x / y / yaw, training steps |",
        "|---|---|",
    ]
    for run in runs:
        shares = outer_tenth_share(run)
        lines.append(f"| {run.name} | {' / '.join(f'{shares[name]:.1%}' for name in PLACEMENT_DRAWS)} |")
    groups = {run.teacher: [r for r in runs if r.teacher == run.teacher and len(r.final_success)] for run in runs}
    lines += ["", f"| teacher | placement draw | {' | '.join(PLACEMENT_LABELS)} |", "|---|---|" + "---|" * 4]
    for teacher, members in groups.items():
        for name in PLACEMENT_DRAWS if members else ():
            cells = [f"{rate:.0%} ({count})" for rate, count in success_by_placement(members, name)]
            lines.append(f"| {teacher} ({len(members)} runs) | {name} | {' | '.join(cells)} |")
    return lines


def spoken(names: Sequence[str]) -> str:
    """Names as a sentence lists them: "a, b and c"."""
    return " and ".join([", ".join(names[:-1]), names[-1]]) if len(names) > 1 else "".join(names)


def summary_markdown(runs: Sequence[RunData]) -> str:
    lines = [
        "| run | steps per band (easiest → hardest quarter) | success per band, last third | mastered / learning / "
        "unsolved so far (share of steps after the first 10%) | final in-run hardest-task success |",
        "|---|---|---|---|---|",
    ]
    for run in runs:
        per_band = [run.length[run.band == band].sum() / run.length.sum() for band in range(len(BAND_LABELS))]
        late = run.step >= 2 * run.total_steps // 3
        late_success = [
            f"{run.success[late & (run.band == band)].mean():.0%}" if (late & (run.band == band)).sum() >= 5 else "—"
            for band in range(len(BAND_LABELS))
        ]
        classes = frontier_classes(run)
        counted = (classes >= 0) & (run.step >= run.total_steps // 10)
        class_shares = [
            run.length[counted & (classes == label)].sum() / run.length[counted].sum() for label in range(3)
        ]
        final = run.evaluation_success[-3:].mean() if len(run.evaluation_success) else float("nan")
        lines.append(
            f"| {run.name} | {' / '.join(f'{share:.0%}' for share in per_band)} | {' / '.join(late_success)} "
            f"| {' / '.join(f'{share:.0%}' for share in class_shares)} | {final:.0%} (last 3 evaluations) |"
        )
    space = common_space(runs)
    easier_upper = [name for name, easiest in zip(space.names, easiest_unit(space), strict=True) if easiest > 0.5]
    effects = parameter_effects(runs)
    episodes = next(iter(effects.values()))[2]
    lines += [
        "",
        f"Success in the lower and upper half of each parameter's range, last third of every run ({episodes:_} "
        f"episodes; for {spoken(easier_upper) or 'no parameter'} the upper half is the easier one):",
        "",
        "| parameter | lower half | upper half |",
        "|---|---|---|",
    ]
    lines += [
        f"| {name} | {' | '.join('—' if np.isnan(rate) else f'{rate:.0%}' for rate in (low, high))} |"
        for name, (low, high, _) in effects.items()
    ]
    lines += ["", *placement_markdown(runs)]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run directories (each with teacher.sqlite[.xz])")
    parser.add_argument("--out", type=Path, required=True, help="directory for the plots and summary.md")
    args = parser.parse_args()
    runs = [load_run(path) for path in args.runs if exists(path / DATABASE_FILE)]
    if not runs:
        raise SystemExit("no run directory with a teacher database among the arguments")
    try:
        space = common_space(runs)
    except ValueError as error:
        raise SystemExit(str(error)) from None
    args.out.mkdir(parents=True, exist_ok=True)
    plot_runs(runs, args.out)
    if places_block_as_in_book(space):
        plot_placement(runs, args.out)
    (args.out / "summary.md").write_text(summary_markdown(runs), encoding="utf-8")
    print((args.out / "summary.md").read_text())


if __name__ == "__main__":
    main()
