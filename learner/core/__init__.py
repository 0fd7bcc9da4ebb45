"""The training core: PPO's settings, its update, the trainer's loop, checkpoints and metrics.

Readable top to bottom and free of the commands and experiments around it: nothing here imports
another part of ``learner``.
"""
