"""The KUKA environments' task spaces.

``KUKA_TASK_SPACE`` is the book's six-parameter space and ``KUKA_HARD_TASK_SPACE`` the harder family
of ``KukaGraspHard-v0``: the same six plus four more. ``KUKA_HARD_V1_TASK_SPACE`` (``KukaGraspHard-v1``)
is that family with a tighter hardest alignment margin, whose reward PPO without a curriculum did not find
by chance on its screening seeds, as it did v0's (docs/results/bakeoff-hard.md).
"""

from __future__ import annotations

from common.client.task_space import Parameter, Task, TaskSpace
from common.kuka.env_ids import ENV_ID, HARD_ENV_ID, HARD_V1_ENV_ID

DEFAULT_JP2 = 0.413184
DEFAULT_JP4 = -1.589317

KUKA_TASK_SPACE = TaskSpace(
    [
        Parameter(
            "rnd_obj_x",
            0.0,
            1.0,
            hardest=1.0,
            easiest=0.0,
            doc="Share of the block's random x range used: x = 0.55 + 0.12 * U * rnd_obj_x.",
        ),
        Parameter(
            "rnd_obj_y",
            0.0,
            1.0,
            hardest=1.0,
            easiest=0.0,
            doc="Share of the block's random y range used: y = bias_obj_y + 0.2 * U * rnd_obj_y.",
        ),
        Parameter(
            "rnd_obj_ang",
            0.0,
            1.0,
            hardest=1.0,
            easiest=0.0,
            doc="Share of the block's random yaw range used: yaw = pi/2 + pi * U * rnd_obj_ang.",
        ),
        Parameter(
            "jp2",
            DEFAULT_JP2,
            1.3,
            hardest=DEFAULT_JP2,
            easiest=1.3,
            doc="Start position of arm joint 2 (index 1); higher starts the gripper lower.",
        ),
        Parameter(
            "jp4",
            DEFAULT_JP4,
            -1.0,
            hardest=DEFAULT_JP4,
            easiest=-1.0,
            doc="Start position of arm joint 4 (index 3); compensates the reach when jp2 is raised.",
        ),
        Parameter(
            "bias_obj_y",
            0.0,
            0.04,
            hardest=0.0,
            easiest=0.04,
            doc="Offset of the block's y placement, aligning it with the gripper's start.",
        ),
    ]
)

MOVE_SCALE_HARDEST = 0.1
"""The hard family's slowest gripper: 0.5 mm per step at full action, 20 cm in 400 of the ~800 steps
its descent takes from the book's hardest start."""

ALIGN_MARGIN_ANY = 90.0
"""An ``align_margin`` (degrees) that accepts the fingers at any angle to the block: the book's rule."""
ALIGN_MARGIN_HARDEST = 8.0
"""The hard family's tightest ``align_margin`` (degrees): fingers that close within 8 degrees of square
to the block. A controller that turns the wrist to the block always is (docs/results/bakeoff-hard.md); a policy that
leaves the wrist to chance is about one time in eleven."""

ALIGN_MARGIN_HARDEST_V1 = 2.0
"""``KukaGraspHard-v1``'s tightest ``align_margin`` (degrees). The scripted controller still touches down
within 0.1 degree of square, while a third as many chance lifts count as at v0's 8 (docs/results/bakeoff-hard.md)."""


def align_margin_parameter(hardest: float) -> Parameter:
    """The hard families' alignment rule, from the book's any angle (easiest) to ``hardest`` degrees."""
    return Parameter(
        "align_margin",
        hardest,
        ALIGN_MARGIN_ANY,
        hardest=hardest,
        easiest=ALIGN_MARGIN_ANY,
        doc="Degrees from square to the block within which the fingers must be when the gripper touches "
        "the tray for a lift to count; 90 counts every lift, as the book does.",
    )


KUKA_HARD_TASK_SPACE = TaskSpace(
    [
        *KUKA_TASK_SPACE.parameters,
        Parameter(
            "obj_far",
            0.0,
            1.0,
            hardest=1.0,
            easiest=0.0,
            doc="Share of the way from the book's placement to a uniform point of the reachable tray far from "
            "the gripper's start (common.kuka.env.FAR_MIN_DISTANCE or more).",
        ),
        Parameter(
            "shaping",
            0.0,
            1.0,
            hardest=0.0,
            easiest=1.0,
            doc="Weight of the reward's block-distance penalty: 1 is the book's reward, 0 pays the success "
            "bonus alone (less the wrist's rotation cost).",
        ),
        Parameter(
            "move_scale",
            MOVE_SCALE_HARDEST,
            1.0,
            hardest=MOVE_SCALE_HARDEST,
            easiest=1.0,
            doc="Share of the book's 5 mm per step that a full x or y action moves the gripper: at 0.1 a "
            "random walk spreads about 1 cm over an episode, while steady moves still cross the tray.",
        ),
        align_margin_parameter(ALIGN_MARGIN_HARDEST),
    ]
)

KUKA_HARD_BOOK_HARDEST: Task = {
    **KUKA_TASK_SPACE.hardest(),
    "obj_far": 0.0,
    "shaping": 1.0,
    "move_scale": 1.0,
    "align_margin": ALIGN_MARGIN_ANY,
}
"""The book's hardest task (its evaluation setting) as a point of the hard family."""

KUKA_HARD_V1_TASK_SPACE = TaskSpace(
    [*KUKA_HARD_TASK_SPACE.parameters[:-1], align_margin_parameter(ALIGN_MARGIN_HARDEST_V1)]
)
"""``KukaGraspHard-v1``: v0's ten parameters, the alignment margin tightening to 2 degrees instead of 8."""

TASK_SPACES: dict[str, TaskSpace] = {
    ENV_ID: KUKA_TASK_SPACE,
    HARD_ENV_ID: KUKA_HARD_TASK_SPACE,
    HARD_V1_ENV_ID: KUKA_HARD_V1_TASK_SPACE,
}
"""Each registered KUKA environment's task space, by gymnasium id."""


def task_space_for(env_id: str) -> TaskSpace:
    """The task space of a registered KUKA environment; ``ValueError`` names the known ids."""
    try:
        return TASK_SPACES[env_id]
    except KeyError:
        raise ValueError(f"unknown environment {env_id!r}; expected one of {', '.join(TASK_SPACES)}") from None
