"""pybullet's own C-level output stays out of the terminal; ours gets through."""

import os

import gymnasium

from common.kuka import ENV_ID
from common.kuka.bullet import native_output_silenced


def test_making_an_environment_prints_nothing(capfd) -> None:
    env = gymnasium.make(ENV_ID)
    env.reset(seed=0)
    env.close()
    assert capfd.readouterr() == ("", "")


def test_output_around_a_silenced_block_is_kept(capfd) -> None:
    print("before")
    with native_output_silenced():
        os.write(1, b"native stdout\n")
        os.write(2, b"native stderr\n")
    print("after")
    assert capfd.readouterr() == ("before\nafter\n", "")
