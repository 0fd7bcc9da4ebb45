"""Success by where the block lay: the table and picture that say where a policy's grasps fail.

The arm's IK target is clamped to x in ``TARGET_X_RANGE``; a block beyond it can only be grasped by hanging
the fingers over its end, which the scripted controller does and a student may not have learnt. Episodes
(``common.kuka.diagnostics``) are put in bands by how far their block lay beyond the clamp, and one more
row picks out the blocks straight ahead at the far edge of the tray, the farthest reach.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.kuka.diagnostics import EpisodeDiagnostics
from learner.core.figure_file import save_png
from learner.evaluation.stats import CONFIDENCE, Interval, wilson_interval

BAND_EDGES = (0.0, 0.02, 0.04)
"""Distances (metres) beyond the clamp that split the bands; the last band is open above."""
BAND_LABELS = ("inside the clamp", "0 to 2 cm out", "2 to 4 cm out", "4 cm or more out")
STRAIGHT_AHEAD_X = 0.69
"""Blocks at this x or beyond: straight ahead at the tray's far edge (``FAR_X_RANGE`` ends at 0.70)."""
STRAIGHT_AHEAD_LABEL = f"straight ahead, x ≥ {STRAIGHT_AHEAD_X:g}"
ALL_LABELS = (*BAND_LABELS, STRAIGHT_AHEAD_LABEL)
"""The table's columns: the bands, which partition the episodes, then the straight-ahead ones, which the
last bands also count."""


def band_of(diagnostics: EpisodeDiagnostics) -> int:
    """The index in ``BAND_LABELS`` of the episode's placement band."""
    beyond = diagnostics.beyond_clamp
    return sum(beyond > edge for edge in BAND_EDGES)


@dataclass(frozen=True)
class BandSuccess:
    """Success among one band's episodes."""

    label: str
    episodes: int
    successes: int

    @property
    def rate(self) -> Interval | None:
        """Wilson interval; None for a band without episodes."""
        return wilson_interval(self.successes, self.episodes) if self.episodes else None

    def to_dict(self) -> dict[str, Any]:
        rate = self.rate
        return {
            "band": self.label,
            "episodes": self.episodes,
            "successes": self.successes,
            "success_rate": None if rate is None else rate.to_dict(),
        }

    def cell(self) -> str:
        """'72% (38)': the rate and the episodes it is over, or a dash for none."""
        return "—" if self.rate is None else f"{self.rate.estimate:.0%} ({self.episodes})"


def success_by_band(episodes: Sequence[tuple[EpisodeDiagnostics, bool]]) -> list[BandSuccess]:
    """Per column of ``ALL_LABELS``: the episodes (diagnostics, success) in it and how many succeeded."""
    members: list[list[bool]] = [[] for _ in ALL_LABELS]
    for diagnostics, success in episodes:
        members[band_of(diagnostics)].append(success)
        if diagnostics.block_x >= STRAIGHT_AHEAD_X:
            members[-1].append(success)
    return [BandSuccess(label, len(each), sum(each)) for label, each in zip(ALL_LABELS, members, strict=True)]


def failures_outside(episodes: Sequence[tuple[EpisodeDiagnostics, bool]]) -> tuple[int, int]:
    """(failures whose block lay beyond the clamp, all failures)."""
    failures = [diagnostics for diagnostics, success in episodes if not success]
    return sum(diagnostics.beyond_clamp > 0 for diagnostics in failures), len(failures)


def band_table(rows: Sequence[tuple[str, Sequence[tuple[EpisodeDiagnostics, bool]]]]) -> list[str]:
    """Markdown lines: one row per named set of episodes, success per placement band (episodes in brackets),
    then how many of its failures lay beyond the clamp."""
    lines = [
        f"| | all | {' | '.join(ALL_LABELS)} | failures beyond the clamp |",
        "|---|---|" + "---|" * len(ALL_LABELS) + "---|",
    ]
    for name, episodes in rows:
        outside, failures = failures_outside(episodes)
        overall = BandSuccess("all", len(episodes), sum(success for _, success in episodes))
        cells = [band.cell() for band in success_by_band(episodes)]
        share = f"{outside} of {failures}" + (f" ({outside / failures:.0%})" if failures else "")
        lines.append(f"| {name} | {overall.cell()} | {' | '.join(cells)} | {share} |")
    return lines


def plot_bands(path: Path, rows: Sequence[tuple[str, Sequence[tuple[EpisodeDiagnostics, bool]]]]) -> None:
    """Grouped bars: success per placement band, one bar per named set of episodes, its Wilson interval as
    an error bar and its episode count above it."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(2.2 * len(ALL_LABELS) + 3.5, 4.5), layout="constrained")
    axes = figure.subplots()
    width = 0.8 / max(len(rows), 1)
    for index, (name, episodes) in enumerate(rows):
        bands = success_by_band(episodes)
        centres = [column + (index - (len(rows) - 1) / 2) * width for column in range(len(bands))]
        rates = [band.rate for band in bands]
        heights = [math.nan if rate is None else rate.estimate for rate in rates]
        errors = [
            [0.0 if rate is None else rate.estimate - rate.low for rate in rates],
            [0.0 if rate is None else rate.high - rate.estimate for rate in rates],
        ]
        bars = axes.bar(centres, heights, width, yerr=errors, capsize=2, label=name)
        axes.bar_label(bars, labels=[str(band.episodes) for band in bands], fontsize="x-small", padding=2)
    axes.set_xticks(range(len(ALL_LABELS)), ALL_LABELS)
    axes.set_ylim(0, 1.1)
    axes.set_ylabel(f"success (Wilson {CONFIDENCE:.0%} interval; episodes above)")
    axes.set_title("Final evaluation: success by how far the block lay beyond the arm's x reach")
    axes.grid(axis="y", alpha=0.3)
    axes.legend(loc="center left", bbox_to_anchor=(1.01, 0.5))
    save_png(figure, path, dpi=110)
