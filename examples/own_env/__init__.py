"""Two environments of your own, for ``kuka-curriculum train --env examples.own_env:PointReach-v0``.

Importing this package registers their ids with gymnasium, which is all ``gymnasium.make("module:Id")``
needs: ``PointReach-v0`` (a box of float task parameters) and ``GridLevels-v0`` (integer levels, image
observations). They use numpy and gymnasium only, nothing of kuka-curriculum: each says what its tasks
are in a ``task_space`` attribute and reads its task from ``reset(options={"task": ...})``.
"""

import gymnasium

from examples.own_env.grid_levels import GridLevelsEnv
from examples.own_env.point_reach import PointReachEnv

gymnasium.register(id="PointReach-v0", entry_point=PointReachEnv)
gymnasium.register(id="GridLevels-v0", entry_point=GridLevelsEnv)

__all__ = ["GridLevelsEnv", "PointReachEnv"]
