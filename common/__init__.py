"""What the services share, in rooms by who uses them.

``common.client`` is what any trainer needs to take its tasks from a teacher service (the API schemas
the service shares too), ``common.kuka`` the KUKA grasp environments, ``common.levels`` the MiniGrid level
families (a level is the reset seed), and ``common.policy`` what the rollout workers and the learner exchange.

Importing ``common`` registers the KUKA environments with gymnasium (``KukaGrasp-v0`` and the harder
families), as it did before the rooms, so that scripts written for ``import common`` keep working; it
loads gymnasium alone, not pybullet, which loads when an environment is made.
"""

from common import kuka as kuka
