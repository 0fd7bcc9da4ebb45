"""The teacher service's live dashboard, for a person watching a training run."""

from teacher_service.dashboard.routes import router

__all__ = ["router"]
