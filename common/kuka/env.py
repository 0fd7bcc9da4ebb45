"""``KukaGrasp-v0``: the KUKA arm descends over a tray and must be above a block when it lands.

The rules are those of pybullet's ``kukaGymEnv`` as used in the book (chapter 14): the agent moves
the gripper in x/y and turns the wrist, the environment lowers it by a fixed amount every step,
and the first touch of the tray triggers a scripted grasp that ends the episode. The curriculum
task (``common.kuka.task_space.KUKA_TASK_SPACE``) sets how random the block's placement is and how low
the arm starts.

Each environment owns a DIRECT-mode physics client, so any number can live in one process. The
scene is loaded once and snapshotted; a reset restores the snapshot in under a millisecond instead
of reloading every model (tens of milliseconds), with the same trajectories.

``KukaGraspHard-v0`` (``KukaGraspHardEnv``) is a harder family around the book's task, for which the
book's hardest task needs no curriculum: four more parameters move the block far from where the
gripper starts, fade out the reward's distance shaping, slow the gripper's x/y moves and count a lift
only when the fingers closed square to the block, so that actions without a purpose no longer grasp
it (``common.kuka.task_space.KUKA_HARD_TASK_SPACE``). ``KukaGraspHard-v1`` (``KukaGraspHardV1Env``) plays
by the same rules over a space whose hardest alignment margin is tighter.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import gymnasium
import numpy as np
import pybullet_data
from gymnasium import spaces

from common.client.task_space import Task, TaskSpace
from common.kuka.arm import DEFAULT_START_POSE, END_EFFECTOR_LINK, GRIPPER_LINK, TARGET_X_RANGE, KukaArm
from common.kuka.bullet import direct_client, gui_client, pybullet
from common.kuka.env_ids import ENV_ID, HARD_ENV_ID, HARD_V1_ENV_ID
from common.kuka.task_space import ALIGN_MARGIN_ANY, KUKA_HARD_TASK_SPACE, KUKA_HARD_V1_TASK_SPACE, KUKA_TASK_SPACE

TIME_STEP = 1.0 / 240.0
SOLVER_ITERATIONS = 150
GRAVITY = -10.0

PLANE_POSITION = (0.0, 0.0, -1.0)
TABLE_POSITION = (0.5, 0.0, -0.82)
TRAY_POSITION = (0.64, 0.075, -0.19)
TRAY_ORIENTATION = (0.0, 0.0, 1.0, 0.0)
BLOCK_Z = -0.15
JP2_JOINT, JP4_JOINT = 1, 3  # the start joints that the task's jp2 and jp4 set

MOVE_PER_ACTION = 0.005
YAW_PER_ACTION = 0.05
DESCENT_PER_STEP = 0.0005
FINGER_OPENING = 0.3

TRAY_CONTACT_DISTANCE = 0.005
GRASP_CLOSE_STEPS = 100
GRASP_CLOSE_RISE = 0.0001
GRASP_LIFT_STEPS = 1000
GRASP_LIFT_RISE = 0.001
LIFT_BLOCK_DONE_Z = 0.23
LIFT_GRIPPER_DONE_Z = 0.5
SUCCESS_BLOCK_Z = 0.2
AABB_SAFETY_MARGIN = 0.05
WORLD_BOUND = 5.0  # metres; well beyond anything in reach of the arm or the table

DISTANCE_PENALTY = 10.0
SUCCESS_BONUS = 10000.0
ROTATION_PENALTY = 10.0
REWARD_SCALE = 1.0 / 1000.0  # the book's scaling: a success is worth about +10

FAR_X_RANGE = (0.45, 0.70)
FAR_Y_RANGE = (-0.12, 0.22)
"""Where the hard family's far blocks may lie: the tray within the gripper's reach. That is its target box,
widened in x by half the block's length, which a grasp may hang over, and cut at y = -0.12: beyond it the
arm nears the tray's wall and a controller that sees the block grasps it half as often
(docs/results/bakeoff-hard.md)."""
FAR_CENTRE = (0.532, 0.0)
"""The gripper's x and y at the book's default start pose."""
FAR_MIN_DISTANCE = 0.16
"""A far block lies at least this far (metres) from ``FAR_CENTRE``; random actions rarely end there."""
BLOCK_XY_IN_GRIPPER = slice(6, 8)
"""Observation entries of the block's x and y (metres) in the gripper's frame."""
GRIPPER_EULER_INDICES = (3, 4, 5)
"""Observation entries of the gripper's roll, pitch and yaw (radians): the frame ``BLOCK_XY_IN_GRIPPER`` is in."""
BLOCK_YAW_INDEX = 8
"""Observation entry of the block's yaw in the gripper's frame: pi/2 (modulo pi) when the fingers,
which close along the gripper's x, are square to the block's length."""
FAR_CANDIDATES = 64
"""Uniform draws per far placement, the first far enough is kept (all 64 fail with probability ~1e-12)."""

CAMERA_TARGET = (0.4, 0.0, 0.1)
CAMERA_DISTANCE = 1.4
CAMERA_YAW = 55.0
CAMERA_PITCH = -27.0


def off_square(block_yaw: float) -> float:
    """Signed angle (radians, in [-pi/2, pi/2)) by which the fingers are off square to the block, from
    the block's yaw in the gripper's frame (observation entry ``BLOCK_YAW_INDEX``)."""
    return block_yaw % math.pi - math.pi / 2


class KukaGraspEnv(gymnasium.Env[np.ndarray, np.ndarray]):
    """Grasp a block from a tray with a KUKA iiwa arm, at a difficulty set by a curriculum task.

    Observation (9): the gripper's world position and Euler angles, then the block's x, y and yaw
    in the gripper's frame. Action (3, in [-1, 1]): gripper x and y moves and wrist yaw change.
    Pass a task with ``reset(options={"task": {...}})``; it is kept for later resets. Without one
    the environment uses the hardest task, the book's evaluation setting.
    """

    task_space: TaskSpace = KUKA_TASK_SPACE
    """The parameters a task sets; a task outside it is refused."""
    metadata = {"render_modes": ["rgb_array"], "render_fps": 240}  # one step is 1/240 s of physics
    observation_space: spaces.Box
    action_space: spaces.Box
    angle_indices = (3, 4, 5, 8)
    """Observation entries that are angles in [-pi, pi]: the gripper's roll, pitch and yaw, and the
    block's yaw in the gripper's frame. The roll of a gripper pointing down sits at +-pi."""

    def __init__(
        self,
        render_mode: str | None = None,
        max_steps: int = 1000,
        task: Mapping[str, float] | None = None,
        render_width: int = 320,
        render_height: int = 240,
        reload_on_reset: bool = False,
        window: bool = False,
    ) -> None:
        """``reload_on_reset`` rebuilds the scene from the model files at every reset, as the
        original environment did; it is slower and exists to check the snapshot restore.

        ``window`` opens pybullet's window on the scene, which draws every step (it needs a display;
        one per process): to watch or drive the arm by hand (``common.kuka.manual_control``). It is not
        a render mode, so that tools which try every declared mode (gymnasium's checker) open none."""
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            modes = self.metadata["render_modes"]
            raise ValueError(f"render_mode must be one of {modes} or None, got {render_mode!r}")
        if max_steps < 1:
            raise ValueError(f"max_steps must be at least 1, got {max_steps}")
        if render_width < 1 or render_height < 1:
            raise ValueError(f"render size must be positive, got {render_width}x{render_height}")
        self.render_mode = render_mode
        self.max_steps = max_steps
        self.render_width = render_width
        self.render_height = render_height
        self.reload_on_reset = reload_on_reset
        self.window = window
        self._task: Task = self.task_space.validate(task) if task is not None else self.task_space.hardest()

        self.action_space = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        bound = np.array([WORLD_BOUND] * 3 + [math.pi] * 3 + [WORLD_BOUND] * 2 + [math.pi], dtype=np.float32)
        self.observation_space = spaces.Box(-bound, bound, dtype=np.float32)

        self._client = client = gui_client() if window else direct_client()
        # Bound once: BulletClient builds a new partial on every attribute access.
        self._step_simulation = client.stepSimulation
        self._closest_points = client.getClosestPoints
        self._contact_points = client.getContactPoints
        self._overlapping_objects = client.getOverlappingObjects
        self._link_state = client.getLinkState
        self._base_pose = client.getBasePositionAndOrientation
        self._invert_transform = client.invertTransform
        self._multiply_transforms = client.multiplyTransforms
        self._euler = client.getEulerFromQuaternion
        self._data_path = pybullet_data.getDataPath()
        self._load_scene()
        self._steps = 0

    @property
    def task(self) -> Task:
        """The task used by the current episode and, until another is given, by later ones."""
        return dict(self._task)

    def block_pose(self) -> tuple[float, float, float]:
        """The block's world x, y (metres) and yaw (radians) now; right after ``reset``, where the task placed
        it. Read-only: diagnostics ask it where an episode's block lay, which the observation gives only in
        the gripper's frame."""
        (x, y, _), orientation = self._base_pose(self._block)
        return x, y, self._euler(orientation)[2]

    @property
    def wrist_turn(self) -> float:
        """How far (radians) the wrist has been turned since the reset, the yaw actions summed: which way and
        how far a policy turns it, which no observation entry gives apart from the arm's own turn."""
        return self._arm.wrist_yaw

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        options = dict(options or {})
        new_task = options.pop("task", None)
        if options:
            raise ValueError(f"unknown reset option(s) {sorted(options)}; the only option is 'task'")
        if new_task is not None:
            self._task = self.task_space.validate(new_task)
        super().reset(seed=seed)

        if self.reload_on_reset:
            self._load_scene()
        else:
            self._client.restoreState(self._scene_state)
        self._place_block()
        start_pose = list(DEFAULT_START_POSE)
        start_pose[JP2_JOINT] = self._task["jp2"]
        start_pose[JP4_JOINT] = self._task["jp4"]
        self._arm.reset(start_pose)
        self._step_simulation()
        self._steps = 0
        return self._observe()[0], {"task": self.task}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        dx, dy, dyaw = np.clip(action, -1.0, 1.0).tolist()
        dyaw *= YAW_PER_ACTION
        move = self._move_per_action()
        self._arm.apply(dx * move, dy * move, -DESCENT_PER_STEP, dyaw, FINGER_OPENING)
        self._step_simulation()
        self._steps += 1

        terminated = self._touches_tray()
        square = True
        info: dict[str, float] = {}
        if terminated:
            off_square_degrees = self._off_square_degrees()
            square = off_square_degrees <= self._align_margin()
            info["off_square_degrees"] = off_square_degrees
            self._grasp(can_count=square)
        observation, block_z = self._observe()
        success = block_z > SUCCESS_BLOCK_Z and square
        shaping = self._distance_weight()
        distance = self._block_to_end_effector_distance() if shaping else 0.0
        reward = (
            -DISTANCE_PENALTY * shaping * distance + SUCCESS_BONUS * success - ROTATION_PENALTY * abs(dyaw)
        ) * REWARD_SCALE
        truncated = not terminated and self._steps >= self.max_steps
        return observation, reward, terminated, truncated, {"is_success": success, **info}

    def render(self) -> np.ndarray | None:  # type: ignore[override]  # gymnasium types it with an unbound TypeVar
        if self.render_mode != "rgb_array":
            return None
        client = self._client
        view = client.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=CAMERA_TARGET,
            distance=CAMERA_DISTANCE,
            yaw=CAMERA_YAW,
            pitch=CAMERA_PITCH,
            roll=0.0,
            upAxisIndex=2,
        )
        projection = client.computeProjectionMatrixFOV(
            fov=60.0, aspect=self.render_width / self.render_height, nearVal=0.05, farVal=10.0
        )
        _, _, pixels, _, _ = client.getCameraImage(
            self.render_width,
            self.render_height,
            view,
            projection,
            renderer=pybullet.ER_TINY_RENDERER,
            flags=pybullet.ER_NO_SEGMENTATION_MASK,
        )
        return np.asarray(pixels, dtype=np.uint8).reshape(self.render_height, self.render_width, 4)[:, :, :3]

    def close(self) -> None:
        if self._client is not None:
            self._client.disconnect()
            self._client = None

    def _load_scene(self) -> None:
        """Build the scene in the original's load order and snapshot it for fast resets."""
        client = self._client
        client.resetSimulation()
        client.setPhysicsEngineParameter(numSolverIterations=SOLVER_ITERATIONS)
        client.setTimeStep(TIME_STEP)
        path = self._data_path
        client.loadURDF(os.path.join(path, "plane.urdf"), PLANE_POSITION)
        client.loadURDF(os.path.join(path, "table/table.urdf"), TABLE_POSITION)
        self._block = client.loadURDF(os.path.join(path, "block.urdf"), (0.55, 0.0, BLOCK_Z))
        client.setGravity(0.0, 0.0, GRAVITY)
        self._arm = KukaArm(client, path)
        self._tray = client.loadURDF(os.path.join(path, "tray/tray.urdf"), TRAY_POSITION, TRAY_ORIENTATION)
        self._scene_state = client.saveState()
        tray_low, tray_high = client.getAABB(self._tray)
        reach = TRAY_CONTACT_DISTANCE + AABB_SAFETY_MARGIN
        self._tray_zone = (tuple(v - reach for v in tray_low), tuple(v + reach for v in tray_high))

    def _place_block(self) -> None:
        x, y, yaw = self._placement()
        orientation = self._client.getQuaternionFromEuler((0.0, 0.0, yaw))
        self._client.resetBasePositionAndOrientation(self._block, (x, y, BLOCK_Z), orientation)

    def _placement(self) -> tuple[float, float, float]:
        """Book's placement (x, y, yaw): each ``rnd_*`` scales the share of the random range used."""
        task = self._task
        u_x, u_y, u_yaw = self.np_random.random(3)
        x = 0.55 + 0.12 * u_x * task["rnd_obj_x"]
        y = task["bias_obj_y"] + 0.2 * u_y * task["rnd_obj_y"]
        yaw = 0.5 * math.pi + math.pi * u_yaw * task["rnd_obj_ang"]
        return x, y, yaw

    def _distance_weight(self) -> float:
        """Weight of the block-distance penalty in the reward: the book's reward keeps all of it."""
        return 1.0

    def _move_per_action(self) -> float:
        """How far (metres) a full x or y action moves the gripper's target in one step."""
        return MOVE_PER_ACTION

    def _align_margin(self) -> float:
        """Degrees from square within which the fingers must touch down for a lift to count: in the book's
        rule, any angle."""
        return ALIGN_MARGIN_ANY

    def _off_square_degrees(self) -> float:
        """How far (degrees, 0 to 90) the fingers are from square to the block now. The step's ``info``
        reports it at touchdown, so a measurement can ask how many lifts a tighter margin would count."""
        block_yaw = float(self._observe()[0][BLOCK_YAW_INDEX])
        return abs(math.degrees(off_square(block_yaw)))

    def _grasp(self, can_count: bool) -> None:
        """The original's scripted grasp: close the fingers while creeping up, then lift.

        Where the reward ignores the gripper's final pose (no distance shaping) and nobody films or watches it, the
        grasp stops as soon as its outcome is decided: a touchdown off square cannot count, and fingers
        that closed without touching the block lift nothing. The step's success flag and reward are then
        those of the full grasp, up to ~1,100 physics steps sooner; only its final observation differs (the
        gripper has not risen), which PPO never uses: a terminated episode bootstraps from zero.
        """
        decide_early = self.render_mode is None and not self.window and self._distance_weight() == 0.0
        if decide_early and not can_count:
            return
        arm, step_simulation = self._arm, self._step_simulation
        opening = FINGER_OPENING
        for _ in range(GRASP_CLOSE_STEPS):
            arm.apply(0.0, 0.0, GRASP_CLOSE_RISE, 0.0, opening)
            step_simulation()
            opening = max(opening - FINGER_OPENING / GRASP_CLOSE_STEPS, 0.0)
        if decide_early and not self._contact_points(self._block, arm.uid):
            return
        for _ in range(GRASP_LIFT_STEPS):
            arm.apply(0.0, 0.0, GRASP_LIFT_RISE, 0.0, opening)
            step_simulation()
            if self._base_pose(self._block)[0][2] > LIFT_BLOCK_DONE_Z:
                break
            if self._link_state(arm.uid, END_EFFECTOR_LINK)[0][2] > LIFT_GRIPPER_DONE_Z:
                break

    def _touches_tray(self) -> bool:
        """Exact tray-contact test, skipped while no arm link's bounding box is near the tray.

        The broadphase query costs a fraction of ``getClosestPoints``; its boxes may lag a step
        behind, which the safety margin covers many times over at the arm's speed limit.
        """
        arm_uid = self._arm.uid
        near = self._overlapping_objects(*self._tray_zone) or ()
        if not any(uid == arm_uid for uid, _ in near):
            return False
        return bool(self._closest_points(self._tray, arm_uid, TRAY_CONTACT_DISTANCE))

    def _block_to_end_effector_distance(self) -> float:
        points = self._closest_points(self._block, self._arm.uid, 1000.0, -1, END_EFFECTOR_LINK)
        distance: float = min(point[8] for point in points)
        return distance

    def _observe(self) -> tuple[np.ndarray, float]:
        """The observation, and the block's height (for the success test, read here to save a call)."""
        gripper_position, gripper_orientation = self._link_state(self._arm.uid, GRIPPER_LINK)[:2]
        block_position, block_orientation = self._base_pose(self._block)
        inverse_position, inverse_orientation = self._invert_transform(gripper_position, gripper_orientation)
        block_in_gripper, block_orientation_in_gripper = self._multiply_transforms(
            inverse_position, inverse_orientation, block_position, block_orientation
        )
        observation = np.array(
            [
                *gripper_position,
                *self._euler(gripper_orientation),
                block_in_gripper[0],
                block_in_gripper[1],
                self._euler(block_orientation_in_gripper)[2],
            ],
            dtype=np.float32,
        )
        return observation, block_position[2]


class KukaGraspHardEnv(KukaGraspEnv):
    """The grasp at the difficulty of ``KUKA_HARD_TASK_SPACE``: the book's six parameters, then how far
    the block lies from the gripper's start (``obj_far``), how much of the distance shaping the reward
    keeps (``shaping``), how far an action moves the gripper (``move_scale``) and how square to the
    block the fingers must close for a lift to count (``align_margin``). At ``obj_far`` 0, ``shaping``
    and ``move_scale`` 1 and ``align_margin`` 90 a task plays exactly as in ``KukaGraspEnv``; the
    default task is the family's hardest.
    """

    task_space = KUKA_HARD_TASK_SPACE

    def __init__(self, *, edge_placement_share: float = 0.0, **kwargs: Any) -> None:
        """``edge_placement_share``: the share of far points drawn beyond the arm's x clamp only, a
        training-time emphasis on the placements students miss most (0: every far point as the task
        says, the evaluations' draw). The other arguments are ``KukaGraspEnv``'s."""
        if not 0.0 <= edge_placement_share <= 1.0:
            raise ValueError(f"edge_placement_share must be between 0 and 1, got {edge_placement_share}")
        self._edge_placement_share = edge_placement_share
        super().__init__(**kwargs)

    def _placement(self) -> tuple[float, float, float]:
        """The book's placement moved a share ``obj_far`` of the way to a uniform far point; the far
        point is drawn after the book's draws, so ``obj_far`` 0 places the block as the book does. With
        an ``edge_placement_share`` the draws then decide whether this far point must lie beyond the
        clamp; at 0 nothing more is drawn, so placements stay those of a given seed."""
        x, y, yaw = super()._placement()
        low = np.array([FAR_X_RANGE[0], FAR_Y_RANGE[0]])
        high = np.array([FAR_X_RANGE[1], FAR_Y_RANGE[1]])
        candidates = low + (high - low) * self.np_random.random((FAR_CANDIDATES, 2))
        distances = np.hypot(candidates[:, 0] - FAR_CENTRE[0], candidates[:, 1] - FAR_CENTRE[1])
        eligible = distances >= FAR_MIN_DISTANCE
        if self._edge_placement_share > 0.0 and self.np_random.random() < self._edge_placement_share:
            eligible &= (candidates[:, 0] < TARGET_X_RANGE[0]) | (candidates[:, 0] > TARGET_X_RANGE[1])
        far_enough = np.flatnonzero(eligible)
        far_x, far_y = candidates[far_enough[0] if far_enough.size else int(np.argmax(distances))]
        share = self._task["obj_far"]
        return x + share * (float(far_x) - x), y + share * (float(far_y) - y), yaw

    def _distance_weight(self) -> float:
        return self._task["shaping"]

    def _move_per_action(self) -> float:
        return MOVE_PER_ACTION * self._task["move_scale"]

    def _align_margin(self) -> float:
        """The task's ``align_margin``: the scripted grasp closes the fingers where they are, and a wide
        enough gap rotates the block into them, so without this rule a wrist left to chance grasps as
        well as one turned on purpose."""
        return self._task["align_margin"]


class KukaGraspHardV1Env(KukaGraspHardEnv):
    """``KukaGraspHard-v1``: the same rules as ``KukaGraspHardEnv``, over ``KUKA_HARD_V1_TASK_SPACE``, whose
    hardest point closes the fingers within 2 degrees of square instead of 8."""

    task_space = KUKA_HARD_V1_TASK_SPACE


KUKA_ENVS: dict[str, type[KukaGraspEnv]] = {
    ENV_ID: KukaGraspEnv,
    HARD_ENV_ID: KukaGraspHardEnv,
    HARD_V1_ENV_ID: KukaGraspHardV1Env,
}
"""The environment class of each registered id."""


def make_kuka_env(env_id: str, **kwargs: Any) -> KukaGraspEnv:
    """A bare environment of a registered id (no gymnasium wrappers): what workers and evaluations step."""
    try:
        env_class = KUKA_ENVS[env_id]
    except KeyError:
        raise ValueError(f"unknown environment {env_id!r}; expected one of {', '.join(KUKA_ENVS)}") from None
    return env_class(**kwargs)
