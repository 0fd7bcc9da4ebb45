"""The PPO learner: the update, the training loop, checkpoints, metrics, and the commands that train,
evaluate, film and compare policies (``train``, ``evaluate``, ``render``, ``bakeoff``)."""
