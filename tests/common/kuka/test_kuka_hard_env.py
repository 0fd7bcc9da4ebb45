"""``KukaGraspHard-v0``: the book's task as one point of it, far placements, fading shaping, a slower gripper,
fingers that must close square to the block, its task space; ``KukaGraspHard-v1``, the same family with a
tighter hardest alignment margin."""

from __future__ import annotations

import math
from collections.abc import Iterator

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from test_kuka_env import random_actions, rollout

from common.kuka import ENV_ID, HARD_ENV_ID, HARD_V1_ENV_ID
from common.kuka.diagnostics import beyond_clamp
from common.kuka.env import (
    FAR_CENTRE,
    FAR_MIN_DISTANCE,
    FAR_X_RANGE,
    FAR_Y_RANGE,
    SUCCESS_BLOCK_Z,
    KukaGraspEnv,
    KukaGraspHardEnv,
    KukaGraspHardV1Env,
    make_kuka_env,
)
from common.kuka.task_space import (
    ALIGN_MARGIN_ANY,
    ALIGN_MARGIN_HARDEST,
    ALIGN_MARGIN_HARDEST_V1,
    KUKA_HARD_BOOK_HARDEST,
    KUKA_HARD_TASK_SPACE,
    KUKA_HARD_V1_TASK_SPACE,
    KUKA_TASK_SPACE,
    MOVE_SCALE_HARDEST,
    task_space_for,
)

HARDEST = KUKA_HARD_TASK_SPACE.hardest()
EASIEST = KUKA_HARD_TASK_SPACE.easiest()


def block_xy(env: KukaGraspEnv) -> np.ndarray:
    """The block's world x and y (the observation gives it in the gripper's frame only)."""
    return np.array(env._base_pose(env._block)[0][:2])


@pytest.fixture
def env():
    environment = KukaGraspHardEnv()
    yield environment
    environment.close()


def test_registered_with_its_own_task_space_and_the_hardest_task_by_default():
    made = gymnasium.make(HARD_ENV_ID, max_steps=5)
    assert isinstance(made.unwrapped, KukaGraspHardEnv)
    _, info = made.reset(seed=0)
    assert info["task"] == HARDEST
    made.close()
    check_env(gymnasium.make(HARD_ENV_ID).unwrapped)
    assert task_space_for(HARD_ENV_ID) is KUKA_HARD_TASK_SPACE and task_space_for(ENV_ID) is KUKA_TASK_SPACE
    assert type(make_kuka_env(ENV_ID, max_steps=3)) is KukaGraspEnv
    with pytest.raises(ValueError, match="unknown environment 'KukaGrasp-v9'"):
        make_kuka_env("KukaGrasp-v9")
    with pytest.raises(ValueError, match="unknown environment"):
        task_space_for("KukaGrasp-v9")


def test_v1_is_the_same_family_with_only_the_hardest_alignment_margin_tighter():
    made = gymnasium.make(HARD_V1_ENV_ID, max_steps=5)
    assert type(made.unwrapped) is KukaGraspHardV1Env and isinstance(made.unwrapped, KukaGraspHardEnv)
    _, info = made.reset(seed=0)
    assert info["task"] == KUKA_HARD_V1_TASK_SPACE.hardest()
    made.close()
    check_env(gymnasium.make(HARD_V1_ENV_ID).unwrapped)
    assert task_space_for(HARD_V1_ENV_ID) is KUKA_HARD_V1_TASK_SPACE
    assert type(make_kuka_env(HARD_V1_ENV_ID, max_steps=3)) is KukaGraspHardV1Env
    assert KUKA_HARD_V1_TASK_SPACE.parameters[:-1] == KUKA_HARD_TASK_SPACE.parameters[:-1]
    assert KUKA_HARD_V1_TASK_SPACE.easiest() == EASIEST
    assert KUKA_HARD_V1_TASK_SPACE.hardest() == {**HARDEST, "align_margin": ALIGN_MARGIN_HARDEST_V1}
    assert ALIGN_MARGIN_HARDEST_V1 < ALIGN_MARGIN_HARDEST
    margin = KUKA_HARD_V1_TASK_SPACE.parameters[-1]
    assert (margin.name, margin.low, margin.high) == ("align_margin", ALIGN_MARGIN_HARDEST_V1, ALIGN_MARGIN_ANY)


def test_the_space_keeps_the_books_six_parameters_and_adds_four():
    assert KUKA_HARD_TASK_SPACE.parameters[:6] == KUKA_TASK_SPACE.parameters
    assert KUKA_HARD_TASK_SPACE.names[6:] == ("obj_far", "shaping", "move_scale", "align_margin")
    hardest_new = {
        "obj_far": 1.0,
        "shaping": 0.0,
        "move_scale": MOVE_SCALE_HARDEST,
        "align_margin": ALIGN_MARGIN_HARDEST,
    }
    easiest_new = {"obj_far": 0.0, "shaping": 1.0, "move_scale": 1.0, "align_margin": ALIGN_MARGIN_ANY}
    assert {**KUKA_TASK_SPACE.hardest(), **hardest_new} == HARDEST
    assert {**KUKA_TASK_SPACE.easiest(), **easiest_new} == EASIEST
    assert {**KUKA_TASK_SPACE.hardest(), **easiest_new} == KUKA_HARD_BOOK_HARDEST


@pytest.mark.parametrize(
    ("book_task", "hard_task", "steps"),
    [(KUKA_TASK_SPACE.hardest(), KUKA_HARD_BOOK_HARDEST, 200), (KUKA_TASK_SPACE.easiest(), EASIEST, 1000)],
    ids=["hardest", "easiest"],
)
def test_the_books_tasks_play_exactly_as_in_the_books_environment(book_task, hard_task, steps):
    book, hard = KukaGraspEnv(task=book_task), KukaGraspHardEnv(task=hard_task)
    actions = random_actions(5, steps)
    for seed in (0, 1):
        book_start, _ = book.reset(seed=seed)
        hard_start, _ = hard.reset(seed=seed)
        assert np.array_equal(book_start, hard_start)
        book_trajectory, hard_trajectory = rollout(book, actions), rollout(hard, actions)
        assert book_trajectory == hard_trajectory
    assert len(book_trajectory) == steps or book_trajectory[-1][2], "the easiest episode should end in a grasp"
    book.close()
    hard.close()


def test_far_blocks_lie_far_from_the_gripper_and_within_reach(env):
    placements = []
    for seed in range(40):
        env.reset(seed=seed, options={"task": HARDEST})
        placements.append(block_xy(env))
    placements_array = np.array(placements)
    distances = np.hypot(placements_array[:, 0] - FAR_CENTRE[0], placements_array[:, 1] - FAR_CENTRE[1])
    assert distances.min() >= FAR_MIN_DISTANCE - 1e-6
    assert FAR_X_RANGE[0] <= placements_array[:, 0].min() and placements_array[:, 0].max() <= FAR_X_RANGE[1]
    assert FAR_Y_RANGE[0] <= placements_array[:, 1].min() and placements_array[:, 1].max() <= FAR_Y_RANGE[1]
    assert placements_array[:, 0].max() > 0.66 and placements_array[:, 1].max() > 0.18, "all over the far region"


def test_an_edge_placement_share_draws_that_share_of_far_points_beyond_the_clamp(env):
    def hardest_placements(environment: KukaGraspEnv, seeds: range) -> Iterator[np.ndarray]:
        for seed in seeds:
            environment.reset(seed=seed, options={"task": HARDEST})
            yield block_xy(environment)

    seeds = range(60)
    task_draw = list(hardest_placements(env, seeds))
    inside = [xy for xy in task_draw if beyond_clamp(xy[0]) <= 0]
    assert len(inside) >= 10, "the task's own draw puts many far blocks inside the clamp"
    at_zero, always, half = (KukaGraspHardV1Env(edge_placement_share=share) for share in (0.0, 1.0, 0.5))
    try:
        assert np.array_equal(np.array(list(hardest_placements(at_zero, seeds))), np.array(task_draw)), (
            "a share of 0 draws nothing more: each seed places the block as before"
        )
        edge_only = np.array(list(hardest_placements(always, seeds)))
        assert all(beyond_clamp(x) > 0 for x in edge_only[:, 0])
        distances = np.hypot(edge_only[:, 0] - FAR_CENTRE[0], edge_only[:, 1] - FAR_CENTRE[1])
        assert distances.min() >= FAR_MIN_DISTANCE - 1e-6, "still far from the gripper"
        half_inside = sum(beyond_clamp(xy[0]) <= 0 for xy in hardest_placements(half, seeds))
        assert 0 < half_inside < len(inside), "half the far points as the task says, so fewer inside"
    finally:
        for environment in (at_zero, always, half):
            environment.close()


@pytest.mark.parametrize("share", [-0.1, 1.5])
def test_an_edge_placement_share_outside_0_to_1_is_refused(share):
    with pytest.raises(ValueError, match="edge_placement_share must be between 0 and 1"):
        KukaGraspHardEnv(edge_placement_share=share)


def test_obj_far_moves_the_block_continuously_from_the_books_placement(env):
    for seed in range(5):
        at = {}
        for share in (0.0, 0.5, 1.0):
            env.reset(seed=seed, options={"task": {**KUKA_HARD_BOOK_HARDEST, "obj_far": share}})
            at[share] = block_xy(env)
        book = KukaGraspEnv()
        book.reset(seed=seed)
        assert np.allclose(at[0.0], block_xy(book), atol=1e-9), "obj_far 0 is the book's placement"
        book.close()
        assert np.allclose(at[0.5], (at[0.0] + at[1.0]) / 2, atol=1e-9), "halfway on the same draws"


def test_shaping_scales_the_distance_penalty_and_zero_leaves_the_success_bonus_alone(env):
    rewards = {}
    for shaping in (1.0, 0.5, 0.0):
        env.reset(seed=3, options={"task": {**HARDEST, "shaping": shaping}})
        rewards[shaping] = [env.step(np.zeros(3, dtype=np.float32))[1] for _ in range(50)]
    assert all(reward < 0.0 for reward in rewards[1.0])
    assert np.allclose(rewards[0.5], np.array(rewards[1.0]) / 2, rtol=1e-9)
    assert rewards[0.0] == [0.0] * 50, "no distance penalty and no wrist turn: nothing to pay"

    env.reset(seed=3, options={"task": {**EASIEST, "shaping": 0.0}})
    while True:
        _, reward, terminated, truncated, info = env.step(np.zeros(3, dtype=np.float32))
        if terminated or truncated:
            break
        assert reward == 0.0
    assert info["is_success"] and 9.0 < reward <= 10.0


def test_move_scale_slows_the_grippers_moves_and_nothing_else(env):
    """The arm's target moves move_scale times as far for the same actions; the wrist turns as fast."""
    moves = {}
    for scale in (1.0, 0.5, MOVE_SCALE_HARDEST):
        env.reset(seed=0, options={"task": {**KUKA_HARD_BOOK_HARDEST, "move_scale": scale}})
        start = np.array(env._arm.target[:2])
        for _ in range(20):
            env.step(np.array([0.5, 1.0, 0.3], dtype=np.float32))
        moves[scale] = (np.array(env._arm.target[:2]) - start, env._arm.wrist_yaw)
    for scale in (0.5, MOVE_SCALE_HARDEST):
        assert np.allclose(moves[scale][0], scale * moves[1.0][0], atol=1e-12)
        assert moves[scale][1] == moves[1.0][1]
    assert np.allclose(moves[1.0][0], [20 * 0.5 * 0.005, 20 * 0.005])


@pytest.mark.parametrize(
    ("env_id", "turn_steps", "margin", "counts"),
    [
        (HARD_ENV_ID, 0, ALIGN_MARGIN_HARDEST, True),
        (HARD_ENV_ID, 2, ALIGN_MARGIN_HARDEST, True),
        (HARD_ENV_ID, 4, ALIGN_MARGIN_HARDEST, False),
        (HARD_ENV_ID, 12, ALIGN_MARGIN_HARDEST, False),
        (HARD_ENV_ID, 4, ALIGN_MARGIN_ANY, True),
        (HARD_ENV_ID, 12, ALIGN_MARGIN_ANY, True),
        (HARD_V1_ENV_ID, 0, ALIGN_MARGIN_HARDEST_V1, True),
        (HARD_V1_ENV_ID, 1, ALIGN_MARGIN_HARDEST_V1, False),
        (HARD_V1_ENV_ID, 1, ALIGN_MARGIN_HARDEST, True),
    ],
)
def test_a_lift_counts_only_when_the_fingers_closed_within_align_margin_of_square(env_id, turn_steps, margin, counts):
    """At the easiest placement the fingers start square to the block; each full wrist action turns them
    0.05 rad (2.9 degrees), which the touchdown's ``info`` reports. The lift happens either way; whether it
    counts depends on the margin."""
    env = make_kuka_env(env_id)
    env.reset(seed=0, options={"task": {**EASIEST, "align_margin": margin}})
    for step in range(1000):
        turn = 1.0 if step < turn_steps else 0.0
        _, reward, terminated, truncated, info = env.step(np.array([0.0, 0.0, turn], dtype=np.float32))
        if terminated or truncated:
            break
    assert terminated and env._base_pose(env._block)[0][2] > SUCCESS_BLOCK_Z, "the block was lifted"
    assert info["is_success"] is counts
    assert (reward > 9.0) is counts, "the success bonus is paid only when the lift counts"
    assert info["off_square_degrees"] == pytest.approx(turn_steps * math.degrees(0.05), abs=0.3)
    env.close()


@pytest.mark.parametrize(
    ("make", "bad_task", "named"),
    [
        (KukaGraspHardEnv, {name: value for name, value in HARDEST.items() if name != "shaping"}, "shaping"),
        (KukaGraspHardEnv, {**HARDEST, "obj_far": 1.5}, "obj_far"),
        (KukaGraspHardEnv, {**HARDEST, "shaping": math.nan}, "shaping"),
        (KukaGraspHardEnv, {**HARDEST, "move_scale": 0.05}, "move_scale"),
        (KukaGraspHardEnv, {**HARDEST, "align_margin": 5.0}, "align_margin"),
        (KukaGraspHardV1Env, {**HARDEST, "align_margin": 1.0}, "align_margin"),
        (KukaGraspEnv, HARDEST, "obj_far"),
    ],
)
def test_a_task_outside_the_environments_space_is_refused(make, bad_task, named):
    environment = make()
    with pytest.raises(ValueError, match=named):
        environment.reset(options={"task": bad_task})
    environment.close()
