"""Figures as small PNG files: the results pages commit every plot, and the tree has a size limit.

A plot has few colours, so a 256-colour palette draws it the same as matplotlib's full-colour output, in about
a third of the bytes for a dense plot."""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import TYPE_CHECKING

from PIL import Image

if TYPE_CHECKING:
    from matplotlib.figure import Figure

PALETTE_COLOURS = 256


def save_png(figure: Figure, path: Path, dpi: int) -> None:
    """Render ``figure`` at ``dpi`` and write it as a palette PNG, through a temporary file so that an
    interrupted write never leaves half an image."""
    rendered = io.BytesIO()
    figure.savefig(rendered, format="png", dpi=dpi)
    rendered.seek(0)
    path = Path(path)
    partial = path.with_name(path.name + ".partial")
    with Image.open(rendered) as image:
        image.convert("RGB").quantize(colors=PALETTE_COLOURS).save(partial, format="PNG", optimize=True)
    os.replace(partial, path)
