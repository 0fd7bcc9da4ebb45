"""``kuka-curriculum demo`` writes a GIF of the scene."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np

from kuka_curriculum import main


def test_demo_writes_a_gif_into_a_new_folder(tmp_path, capsys):
    out = tmp_path / "runs" / "nested" / "demo.gif"
    assert main(["demo", "--out", str(out), "--steps", "24", "--seed", "3"]) == 0

    assert capsys.readouterr().out.strip().endswith(str(out))
    frames = iio.imread(out, index=None)
    assert frames.shape[0] == 4 and frames.shape[1:3] == (240, 320)
    assert not np.array_equal(frames[0], frames[-1]), "the arm should move between frames"
