"""Pure curriculum teachers: no HTTP, no files, no Ray.

``make_teacher(kind, space, seed, params)`` builds one; every kind samples tasks inside the space,
learns from ``EpisodeResult``s and describes itself as JSON-ready data (see ``base.Teacher``).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from common.client.task_space import TaskSpace
from teacher_service.teachers.adr import AdrTeacher
from teacher_service.teachers.alp_gmm import AlpGmmTeacher
from teacher_service.teachers.base import BuildJob, EpisodeResult, FitJob, Teacher
from teacher_service.teachers.covar_gmm import CovarGmmTeacher
from teacher_service.teachers.currot import CurrotTeacher
from teacher_service.teachers.learnability import LearnabilityTeacher
from teacher_service.teachers.levels import LearningProgressTeacher, PlrTeacher
from teacher_service.teachers.manual import ManualTeacher
from teacher_service.teachers.params import TeacherParams
from teacher_service.teachers.riac import RiacTeacher
from teacher_service.teachers.self_paced import SelfPacedTeacher
from teacher_service.teachers.uniform import FixedTeacher, RandomTeacher

TEACHER_KINDS: Mapping[str, type[Teacher]] = MappingProxyType(
    {
        teacher.kind: teacher
        for teacher in (
            AlpGmmTeacher,
            ManualTeacher,
            RandomTeacher,
            FixedTeacher,
            AdrTeacher,
            SelfPacedTeacher,
            CurrotTeacher,
            CovarGmmTeacher,
            RiacTeacher,
            LearnabilityTeacher,
            PlrTeacher,
            LearningProgressTeacher,
        )
    }
)


def make_teacher(
    kind: str, space: TaskSpace, seed: int, params: TeacherParams | Mapping[str, Any] | None = None
) -> Teacher:
    """Build a teacher, or raise ``ValueError`` naming the unknown kind or the bad parameter."""
    factory = TEACHER_KINDS.get(kind)
    if factory is None:
        raise ValueError(f"unknown teacher kind {kind!r}; expected one of {sorted(TEACHER_KINDS)}")
    return factory(space, seed, params)


__all__ = ["TEACHER_KINDS", "BuildJob", "EpisodeResult", "FitJob", "Teacher", "TeacherParams", "make_teacher"]
