"""The API's response bodies about a curriculum, built from its live state with the shared schemas."""

from __future__ import annotations

import time

from common.client.schemas import CurriculumCounters, CurriculumInfo, CurriculumState
from teacher_service.curricula import Curriculum


def curriculum_info(curriculum: Curriculum) -> CurriculumInfo:
    """What ``GET /curricula/{name}`` answers: the configuration and the counters."""
    return CurriculumInfo(
        name=curriculum.name,
        config=curriculum.config,
        created_at=curriculum.created_at,
        counters=CurriculumCounters(
            tasks_issued=curriculum.tasks_issued,
            results_received=curriculum.results_received,
            results_per_second=curriculum.results_per_second(time.time()),
            tasks_outstanding=len(curriculum.outstanding),
            tasks_expired=curriculum.tasks_expired,
            fits_completed=curriculum.fits_completed,
            fits_pending=curriculum.fits_pending,
            last_fit_at=curriculum.last_fit_at,
            fits_stopped=curriculum.fits_stopped,
            writes_failing=curriculum.writes_failing,
        ),
    )


def curriculum_state(curriculum: Curriculum, recent: int) -> CurriculumState:
    """What ``GET /curricula/{name}/state`` answers: the info, the teacher's own state, the recent
    fits and the last ``recent`` results."""
    results = list(curriculum.recent_results)[-recent:] if recent else []
    return CurriculumState(
        curriculum=curriculum_info(curriculum),
        teacher=curriculum.teacher.state(),
        fits=list(curriculum.fit_events),
        recent_results=results,
    )
