"""A deterministic stand-in for a student, shared by the teacher tests."""

from __future__ import annotations

import math

from common.client.task_space import Task
from teacher_service.teachers import EpisodeResult, Teacher


def scripted_reward(task: Task, episode: int) -> float:
    """A reward that depends on the task and drifts over episodes, so ALP is not constant."""
    values = list(task.values())
    return math.sin(values[0] * 0.1 + episode * 0.01) * (1.0 + values[-1])


def run_student(teacher: Teacher, episodes: int, batch: int = 1) -> list[Task]:
    """Sample tasks in batches, report a scripted reward for each, return every task handed out."""
    handed_out: list[Task] = []
    while len(handed_out) < episodes:
        for task in teacher.sample(min(batch, episodes - len(handed_out))):
            teacher.learn_and_fit(EpisodeResult(task, scripted_reward(task, len(handed_out))))
            handed_out.append(task)
    return handed_out
