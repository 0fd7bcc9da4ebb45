"""Rollout workers: Ray actors that play KUKA episodes on the teacher's tasks and return fixed-size batches."""
