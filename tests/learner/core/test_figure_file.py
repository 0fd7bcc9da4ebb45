import numpy as np
from matplotlib.figure import Figure
from PIL import Image

from learner.core.figure_file import PALETTE_COLOURS, save_png


def dense_plot() -> Figure:
    """Many anti-aliased curves in many colours: a plot as the reports draw them, at its worst for a palette."""
    figure = Figure(figsize=(6, 4))
    axes = figure.subplots()
    steps = np.linspace(0, 1, 400)
    for curve in range(30):
        axes.plot(steps, np.sin(steps * (curve + 1) * 3) + curve * 0.1, alpha=0.7)
    return figure


def test_a_figure_is_written_as_a_palette_png_of_its_size_smaller_than_matplotlibs_own(tmp_path):
    figure = dense_plot()
    save_png(figure, tmp_path / "small.png", dpi=100)
    figure.savefig(tmp_path / "full.png", dpi=100)
    with Image.open(tmp_path / "small.png") as small, Image.open(tmp_path / "full.png") as full:
        assert small.mode == "P"
        assert small.size == full.size == (600, 400)
        assert len(small.getcolors(PALETTE_COLOURS) or []) <= PALETTE_COLOURS
        drawn = np.asarray(small.convert("RGB"), dtype=float)
        reference = np.asarray(full.convert("RGB"), dtype=float)
    assert np.abs(drawn - reference).mean() < 2.0  # of 255: the same picture to the eye
    assert (tmp_path / "small.png").stat().st_size < (tmp_path / "full.png").stat().st_size
    assert sorted(path.name for path in tmp_path.iterdir()) == ["full.png", "small.png"]  # no partial file left
