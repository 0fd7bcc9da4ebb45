"""The KUKA iiwa arm with its two-finger gripper, driven through inverse kinematics.

Gains, limits and joint layout follow pybullet's ``kuka.py`` so the physics match the book's
environment, including its damped least-squares IK: ``kuka.py`` also lists null-space limits and
rest poses, but its ``useNullSpace = 21`` switch leaves them unused, and with them the arm swings
away from a raised start pose (zero actions on the easiest task then never grasp instead of always).

The one deliberate change: :meth:`KukaArm.reset` starts the IK target at the end effector's actual
pose instead of a fixed point, so a lower start pose stays lower.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

from common.kuka.bullet import BulletClient, pybullet

ARM_JOINTS = 7
END_EFFECTOR_LINK = 6
GRIPPER_LINK = 7
WRIST_JOINT = 7
LEFT_FINGER_JOINT, RIGHT_FINGER_JOINT = 8, 11
FINGER_TIP_JOINTS = (10, 13)

BASE_POSITION = (-0.1, 0.0, 0.07)
DEFAULT_START_POSE: tuple[float, ...] = (
    0.006418,
    0.413184,
    -0.011401,
    -1.589317,
    0.005379,
    1.137684,
    -0.006539,
    0.000048,
    -0.299912,
    0.0,
    -0.000043,
    0.299960,
    0.0,
    -0.000200,
)

TARGET_X_RANGE = (0.50, 0.65)
TARGET_Y_RANGE = (-0.17, 0.22)
GRIPPER_POINTING_DOWN = pybullet.getQuaternionFromEuler((0.0, -math.pi, 0.0))

IK_JOINT_DAMPING = (0.00001,) * 14  # one per joint, fingers included

ARM_FORCE = 200.0
ARM_MAX_VELOCITY = 0.35
ARM_POSITION_GAIN = 0.3
ARM_VELOCITY_GAIN = 1.0
LEFT_FINGER_FORCE = 2.0
RIGHT_FINGER_FORCE = 2.5
FINGER_TIP_FORCE = 2.0
WRIST_POSITION_GAIN = 0.1  # pybullet's default gains, which the original's wrist command used
WRIST_VELOCITY_GAIN = 1.0

ARM_AND_WRIST_JOINTS = (*range(ARM_JOINTS), WRIST_JOINT)
ARM_AND_WRIST_VELOCITIES = (0.0,) * (ARM_JOINTS + 1)
ARM_AND_WRIST_FORCES = (ARM_FORCE,) * (ARM_JOINTS + 1)
ARM_AND_WRIST_POSITION_GAINS = (ARM_POSITION_GAIN,) * ARM_JOINTS + (WRIST_POSITION_GAIN,)
ARM_AND_WRIST_VELOCITY_GAINS = (ARM_VELOCITY_GAIN,) * ARM_JOINTS + (WRIST_VELOCITY_GAIN,)
FINGER_JOINTS = (LEFT_FINGER_JOINT, RIGHT_FINGER_JOINT, *FINGER_TIP_JOINTS)
FINGER_FORCES = (LEFT_FINGER_FORCE, RIGHT_FINGER_FORCE, FINGER_TIP_FORCE, FINGER_TIP_FORCE)


class KukaArm:
    """The arm's body in one physics client, plus the Cartesian target the controller tracks."""

    def __init__(self, client: BulletClient, data_path: str) -> None:
        self._client = client
        self.uid: int = client.loadSDF(os.path.join(data_path, "kuka_iiwa/kuka_with_gripper2.sdf"))[0]
        client.resetBasePositionAndOrientation(self.uid, BASE_POSITION, (0.0, 0.0, 0.0, 1.0))
        self.target = [0.0, 0.0, 0.0]
        self.wrist_yaw = 0.0
        self._finger_opening: float | None = None
        # Bound once: BulletClient builds a new partial on every attribute access.
        self._inverse_kinematics = client.calculateInverseKinematics
        self._set_motors = client.setJointMotorControlArray

    def reset(self, start_pose: Sequence[float]) -> None:
        """Place the joints at ``start_pose`` and aim the controller where the gripper already is."""
        client = self._client
        for joint, position in enumerate(start_pose):
            client.resetJointState(self.uid, joint, position)
            # A motor keeps its velocity limit, so it is set here once: the array call that
            # updates the targets every step cannot set it.
            limit = {"maxVelocity": ARM_MAX_VELOCITY} if joint < ARM_JOINTS else {}
            client.setJointMotorControl2(
                self.uid, joint, pybullet.POSITION_CONTROL, targetPosition=position, force=ARM_FORCE, **limit
            )
        # IK solves for the link frame (state[4]), not the centre of mass (state[0]).
        self.target = list(client.getLinkState(self.uid, END_EFFECTOR_LINK, computeForwardKinematics=1)[4])
        self.wrist_yaw = 0.0
        self._finger_opening = None

    def apply(self, dx: float, dy: float, dz: float, dyaw: float, finger_opening: float) -> None:
        """Move the target by (dx, dy, dz), turn the wrist by ``dyaw`` and set motor commands."""
        target = self.target
        target[0] = min(max(target[0] + dx, TARGET_X_RANGE[0]), TARGET_X_RANGE[1])
        target[1] = min(max(target[1] + dy, TARGET_Y_RANGE[0]), TARGET_Y_RANGE[1])
        target[2] += dz
        self.wrist_yaw += dyaw
        joint_poses = self._inverse_kinematics(
            self.uid, END_EFFECTOR_LINK, target, GRIPPER_POINTING_DOWN, jointDamping=IK_JOINT_DAMPING
        )
        self._set_motors(
            self.uid,
            ARM_AND_WRIST_JOINTS,
            pybullet.POSITION_CONTROL,
            targetPositions=(*joint_poses[:ARM_JOINTS], self.wrist_yaw),
            targetVelocities=ARM_AND_WRIST_VELOCITIES,
            forces=ARM_AND_WRIST_FORCES,
            positionGains=ARM_AND_WRIST_POSITION_GAINS,
            velocityGains=ARM_AND_WRIST_VELOCITY_GAINS,
        )
        if finger_opening != self._finger_opening:  # a motor keeps its command, so resend only changes
            self._finger_opening = finger_opening
            self._set_motors(
                self.uid,
                FINGER_JOINTS,
                pybullet.POSITION_CONTROL,
                targetPositions=(-finger_opening, finger_opening, 0.0, 0.0),
                forces=FINGER_FORCES,
            )
