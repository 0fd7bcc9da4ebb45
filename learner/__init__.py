"""The PPO learner: the update, the training loop, checkpoints, metrics and the ``train`` command."""
