"""``kuka-curriculum render`` writes a labelled video of a real checkpoint's policy."""

from __future__ import annotations

import importlib.util

import imageio.v3 as iio
import numpy as np
import pytest
from tiny_checkpoint import save_untrained_checkpoint

from common.kuka.env import KukaGraspEnv
from kuka_curriculum import main
from learner.commands.render import FAILURE_COLOUR, SUCCESS_COLOUR, label_frame

HAS_FFMPEG = importlib.util.find_spec("imageio_ffmpeg") is not None


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return save_untrained_checkpoint(tmp_path_factory.mktemp("run"))


@pytest.fixture(scope="module")
def scene():
    env = KukaGraspEnv(render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    env.close()
    return frame


def test_render_writes_a_gif_of_the_policy_acting(checkpoint, tmp_path, capsys):
    out = tmp_path / "films" / "policy.gif"
    assert main(["render", str(checkpoint), "--out", str(out), "--episodes", "2", "--max-episode-steps", "24"]) == 0

    assert capsys.readouterr().out.strip() == str(out)
    frames = iio.imread(out, index=None)
    assert frames.ndim == 4 and frames.shape[1:] == (240, 320, 3)
    assert frames.shape[0] >= 4, "at least the start and end of each episode"
    assert not np.array_equal(frames[0], frames[-1]), "the labels and the arm should change"


def colour_pixels(frame: np.ndarray, colour: tuple[int, int, int]) -> int:
    return int((np.abs(frame.astype(int) - colour).sum(axis=-1) < 60).sum())


def test_frames_show_episode_return_and_outcome(scene):
    running = label_frame(scene, episode=1, episodes=3, step=8, episode_return=-0.5, success=None)
    later = label_frame(scene, episode=1, episodes=3, step=8, episode_return=-1.5, success=None)
    succeeded = label_frame(scene, episode=1, episodes=3, step=90, episode_return=9.7, success=True)
    failed = label_frame(scene, episode=1, episodes=3, step=90, episode_return=-2.0, success=False)

    assert running.shape == scene.shape and running.dtype == np.uint8
    assert not np.array_equal(running, later), "the return so far is drawn"
    assert not np.array_equal(running, label_frame(scene, 2, 3, 8, -0.5, None)), "the episode number is drawn"
    assert colour_pixels(succeeded, SUCCESS_COLOUR) > 20 and colour_pixels(succeeded, FAILURE_COLOUR) == 0
    assert colour_pixels(failed, FAILURE_COLOUR) > 20 and colour_pixels(failed, SUCCESS_COLOUR) == 0
    assert colour_pixels(running, SUCCESS_COLOUR) == colour_pixels(running, FAILURE_COLOUR) == 0
    # The scene below the label band is left as rendered.
    assert np.array_equal(running[120:], scene[120:])


@pytest.mark.skipif(HAS_FFMPEG, reason="imageio-ffmpeg is installed")
def test_mp4_without_ffmpeg_is_refused_before_filming(checkpoint, tmp_path, capsys):
    out = tmp_path / "policy.mp4"
    assert main(["render", str(checkpoint), "--out", str(out)]) == 2
    assert "imageio-ffmpeg" in capsys.readouterr().err and not out.exists()


@pytest.mark.skipif(not HAS_FFMPEG, reason="writing .mp4 needs imageio-ffmpeg")
def test_render_writes_an_mp4(checkpoint, tmp_path):
    out = tmp_path / "policy.mp4"
    assert main(["render", str(checkpoint), "--out", str(out), "--episodes", "1", "--max-episode-steps", "24"]) == 0
    frames = iio.imread(out, index=None, plugin="FFMPEG")
    assert frames.shape[0] >= 2 and frames.shape[1:] == (240, 320, 3)


def test_an_unknown_video_format_is_refused(checkpoint, tmp_path, capsys):
    assert main(["render", str(checkpoint), "--out", str(tmp_path / "policy.avi")]) == 2
    assert ".gif or .mp4" in capsys.readouterr().err
