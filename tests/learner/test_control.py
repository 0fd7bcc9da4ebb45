"""``kuka-curriculum control`` opens pybullet's window with the arm in it, under a virtual X display."""

from __future__ import annotations

import os
import select
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from kuka_curriculum import main

REPO = Path(__file__).resolve().parents[2]


def _arm_orange_pixels(image: np.ndarray) -> np.ndarray:
    """Where the screenshot shows the orange of the KUKA's joint housings; nothing else in the scene or the
    window's panels has that colour."""
    red, green, blue = (image[..., channel].astype(int) for channel in range(3))
    return (red > 180) & (green > 50) & (green < 150) & (blue < 60)


@pytest.fixture
def display() -> Iterator[str]:
    """A fresh Xvfb server on a display number it picks itself (``-displayfd``), so parallel runs never clash."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("no Xvfb to make a display with (Debian: apt-get install xvfb)")
    read_end, write_end = os.pipe()
    server = subprocess.Popen(
        [xvfb, "-displayfd", str(write_end), "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
        pass_fds=(write_end,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_end)
    try:
        ready, _, _ = select.select([read_end], [], [], 30.0)
        number = os.read(read_end, 16).decode().strip() if ready else ""
        if not number:
            pytest.skip("Xvfb did not start a display")
        yield f":{number}"
    finally:
        os.close(read_end)
        server.terminate()
        server.wait(timeout=30)


def _read_line(stream, deadline: float) -> str:
    ready, _, _ = select.select([stream], [], [], max(deadline - time.monotonic(), 0.0))
    return stream.readline() if ready else ""


def test_control_opens_the_arm_in_pybullets_window_and_grasps(display, tmp_path):
    from PIL import ImageGrab, features

    if not features.check("xcb"):
        pytest.skip("this Pillow cannot read an X display (built without XCB)")
    command = [sys.executable, "-m", "kuka_curriculum", "control", "--task", "easiest", "--steps", "120", "--seed", "0"]
    process = subprocess.Popen(
        command,
        cwd=REPO,
        env={**os.environ, "DISPLAY": display},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120.0
        lines = []
        while not any(line.startswith("episode ") for line in lines):  # the window is up and the arm moving
            line = _read_line(process.stdout, deadline)
            assert line, f"no step reported; output so far: {lines}"
            lines.append(line)
        screenshot = ImageGrab.grab(xdisplay=display)
        screenshot.save(tmp_path / "control.png")
        out, err = process.communicate(timeout=180)
    finally:
        process.kill()
        process.wait()
    out = "".join(lines) + out
    assert process.returncode == 0, err[-2000:]

    orange = _arm_orange_pixels(np.asarray(screenshot.convert("RGB")))
    assert orange.sum() > 200, f"the arm is not in the window (screenshot: {tmp_path / 'control.png'})"
    assert "KukaGrasp-v0, gym mode" in out
    assert "-> grasped (return +" in out, "untouched sliders on the easiest task grasp the block"
    assert "120 steps over 2 episode(s)" in out


def test_control_refuses_a_bad_task_or_a_missing_display(monkeypatch, capsys):
    monkeypatch.setenv("DISPLAY", ":0")
    assert main(["control", "--task", "jp2=9"]) == 2
    assert "--task: task parameter 'jp2'=9.0 is outside its bounds" in capsys.readouterr().err
    if sys.platform.startswith("linux"):
        monkeypatch.delenv("DISPLAY")
        assert main(["control", "--task", "easiest", "jp2=1.0"]) == 2
        assert "needs a display" in capsys.readouterr().err
