"""A scripted student whose reach grows with practice, for the teachers that follow a frontier."""

from __future__ import annotations

from common.client.task_space import Parameter, TaskSpace
from teacher_service.teachers import EpisodeResult, Teacher

SQUARE = TaskSpace(
    [
        Parameter("x", 0.0, 1.0, easiest=0.0, hardest=1.0),
        Parameter("y", -2.0, 2.0, easiest=-2.0, hardest=2.0),
    ]
)


class ReachStudent:
    """Succeeds when every parameter of the task lies within ``reach`` (a share of its range from
    the easiest end); each success adds ``growth`` to the reach."""

    def __init__(self, reach: float, growth: float = 0.0) -> None:
        self.reach = reach
        self.growth = growth

    def attempt(self, task: dict[str, float]) -> bool:
        shares = [(task[p.name] - p.low) / (p.high - p.low) for p in SQUARE.parameters]
        success = max(shares) <= self.reach + 1e-12
        if success:
            self.reach = min(self.reach + self.growth, 1.0)
        return success


def practise(teacher: Teacher, student: ReachStudent, episodes: int) -> None:
    for _ in range(episodes):
        task = teacher.sample(1)[0]
        teacher.learn_and_fit(EpisodeResult(task, reward=0.0, success=student.attempt(task)))
