"""Success by placement band: which band an episode falls in, the counts per band, the table and picture."""

from __future__ import annotations

import imageio.v3 as iio
import pytest

from common.kuka.arm import TARGET_X_RANGE
from common.kuka.diagnostics import EpisodeDiagnostics
from learner.evaluation.episode_diagnostics import (
    ALL_LABELS,
    BAND_LABELS,
    STRAIGHT_AHEAD_LABEL,
    band_of,
    band_table,
    failures_outside,
    plot_bands,
    success_by_band,
)
from learner.evaluation.stats import wilson_interval

LOW, HIGH = TARGET_X_RANGE


def at(x: float) -> EpisodeDiagnostics:
    return EpisodeDiagnostics(x, 0.1, 0.0, 0.0, 0.0, 0.5)


@pytest.mark.parametrize(
    ("x", "band"),
    [
        (0.575, 0),
        (HIGH, 0),  # on the edge is within reach
        (LOW, 0),
        (HIGH + 0.005, 1),
        (LOW - 0.019, 1),  # the near side counts by its distance too
        (HIGH + 0.03, 2),
        (LOW - 0.03, 2),
        (HIGH + 0.045, 3),
        (HIGH + 0.2, 3),  # the last band is open above
    ],
)
def test_each_placement_falls_in_the_band_of_its_distance_beyond_the_clamp(x, band):
    assert band_of(at(x)) == band


def test_success_is_counted_per_band_and_straight_ahead_blocks_again():
    episodes = [
        (at(0.58), True),
        (at(0.60), False),
        (at(0.66), True),
        (at(0.68), False),
        (at(0.695), False),
        (at(0.699), True),
        (at(0.455), False),
    ]
    bands = {band.label: band for band in success_by_band(episodes)}
    assert list(bands) == list(ALL_LABELS)
    counts = {label: (band.episodes, band.successes) for label, band in bands.items()}
    assert counts == {
        BAND_LABELS[0]: (2, 1),
        BAND_LABELS[1]: (1, 1),
        BAND_LABELS[2]: (1, 0),
        BAND_LABELS[3]: (3, 1),
        STRAIGHT_AHEAD_LABEL: (2, 1),
    }
    assert sum(bands[label].episodes for label in BAND_LABELS) == len(episodes), "the bands partition the episodes"
    assert bands[BAND_LABELS[3]].rate == wilson_interval(1, 3)
    assert bands[BAND_LABELS[3]].to_dict()["success_rate"] == wilson_interval(1, 3).to_dict()
    assert failures_outside(episodes) == (3, 4)

    empty = success_by_band([(at(0.58), True)])[1]
    assert empty.rate is None and empty.cell() == "—" and empty.to_dict()["success_rate"] is None


def test_the_table_has_a_row_per_set_of_episodes_and_the_picture_is_drawn(tmp_path):
    policy = [(at(0.58), True), (at(0.58), True), (at(0.68), False), (at(0.695), False)]
    scripted = [(at(0.58), True), (at(0.58), True), (at(0.68), True), (at(0.695), True)]
    lines = band_table([("CURROT (2 seeds)", policy), ("Scripted", scripted)])
    assert lines[0].startswith(f"| | all | {BAND_LABELS[0]} |") and lines[0].endswith("| failures beyond the clamp |")
    assert lines[2] == "| CURROT (2 seeds) | 50% (4) | 100% (2) | — | 0% (1) | 0% (1) | 0% (1) | 2 of 2 (100%) |"
    assert lines[3] == "| Scripted | 100% (4) | 100% (2) | — | 100% (1) | 100% (1) | 100% (1) | 0 of 0 |"

    path = tmp_path / "bands.png"
    plot_bands(path, [("CURROT (2 seeds)", policy), ("Scripted", scripted)])
    assert iio.imread(path).ndim == 3
