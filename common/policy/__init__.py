"""What the rollout workers and the learner exchange: the actor-critic policy and its snapshot, the
observation normaliser and the trajectories the workers collect."""
