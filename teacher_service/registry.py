"""A service's curricula: creating and finding them, rebuilding them at start-up (``replay``), and
starting and stopping the background work (group commits, fits, builds) they share.

A database written by another version must not keep the service from starting. A curriculum whose
stored snapshot does not restore into today's teacher is rebuilt from its first stored result,
with a warning (see ``replay``). One that cannot be loaded at all (its teacher kind is gone, its
stored parameters no longer build a teacher, its rows do not replay) is logged as an error and
not served: its name answers 409 with the reason (``CurriculumUnloadable``) and cannot be
registered again, while the other curricula are served as usual. Its rows stay in the database
untouched, for the version that wrote them."""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

from teacher_service.core.config import Settings
from teacher_service.curricula import FIT_HISTORY, Curriculum, CurriculumConflict, UnknownCurriculum
from teacher_service.curriculum_spec import TypedSpec, stored_spec
from teacher_service.fits import FitRunner
from teacher_service.metrics import ServiceMetrics
from teacher_service.replay import Replayed, SnapshotUnusable, replay
from teacher_service.store import Store, StoredCurriculum

log = logging.getLogger(__name__)


class CurriculumUnloadable(Exception):
    """A stored curriculum that this version could not load; the message says why and what to do."""


class CurriculumRegistry:
    """Every curriculum of one service, loaded from and written to one store."""

    def __init__(self, store: Store, metrics: ServiceMetrics, settings: Settings) -> None:
        self._store = store
        self._metrics = metrics
        self._settings = settings
        self._fits = FitRunner(settings.fit_processes, settings.fit_timeout_s, metrics)
        self._builds = ThreadPoolExecutor(max_workers=1, thread_name_prefix="teacher-builds")
        self._curricula: dict[str, Curriculum] = {}
        self._unloadable: dict[str, tuple[int, str]] = {}
        """Stored curricula this version could not load: id and why, by name."""

    def restore(self) -> None:
        """Rebuild every stored curriculum; call before ``start``."""
        for stored in self._store.curricula():
            started = time.perf_counter()
            try:
                curriculum = self._restore(stored)
            except Exception as error:
                reason = (
                    f"curriculum {stored.name!r} is stored but this version cannot load it "
                    f"({type(error).__name__}: {error}); serve its database with the version that wrote it, "
                    "or register the curriculum under another name"
                )
                log.exception("%s", reason)
                self._unloadable[stored.name] = (stored.id, reason)
                continue
            self._curricula[stored.name] = curriculum
            log.info(
                "restored curriculum %r in %.2f s: %d tasks, %d results, %d fits",
                stored.name,
                time.perf_counter() - started,
                curriculum.tasks_issued,
                curriculum.results_received,
                curriculum.fits_completed,
            )

    def _restore(self, stored: StoredCurriculum) -> Curriculum:
        """One stored curriculum, rebuilt from its snapshot, or from its first result when the
        snapshot does not restore into today's teacher."""
        curriculum = self._build(stored)
        try:
            replayed = self._replay(curriculum, from_start=False)
        except SnapshotUnusable as unusable:
            log.warning(
                "curriculum %r: its stored snapshot does not restore into this version's %s teacher (%s); "
                "rebuilding it from its first stored result",
                stored.name,
                curriculum.spec.teacher,
                unusable,
            )
            curriculum = self._build(stored)
            replayed = self._replay(curriculum, from_start=True)
        curriculum.adopt_replay(replayed)
        return curriculum

    def _replay(self, curriculum: Curriculum, *, from_start: bool) -> Replayed:
        return replay(
            self._store,
            curriculum.id,
            curriculum.name,
            curriculum.teacher,
            task_window=self._settings.task_window,
            fit_history=FIT_HISTORY,
            recent_results=self._settings.recent_results,
            from_start=from_start,
        )

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Start writing and fitting on ``loop``, the running loop."""
        self._store.start(loop)
        self._fits.start(loop)
        for curriculum in self._curricula.values():
            curriculum.resume()

    def close(self) -> None:
        self._fits.close()
        self._store.close()
        self._builds.shutdown(wait=False, cancel_futures=True)

    @property
    def fits_stopped(self) -> str | None:
        """Why no fits run any more, if the fit processes kept dying."""
        return self._fits.stopped

    @property
    def writes_failing(self) -> str | None:
        """Why the database refuses writes (a full disk, a read-only file), while it does."""
        return self._store.writes_failing

    def __len__(self) -> int:
        return len(self._curricula)

    def __iter__(self) -> Iterator[Curriculum]:
        return iter(list(self._curricula.values()))

    def get(self, name: str) -> Curriculum:
        """Raises ``UnknownCurriculum``, or ``CurriculumUnloadable`` for one stored but not loaded."""
        try:
            return self._curricula[name]
        except KeyError:
            if name in self._unloadable:
                raise CurriculumUnloadable(self._unloadable[name][1]) from None
            raise UnknownCurriculum(name) from None

    async def create(self, name: str, spec: TypedSpec) -> tuple[Curriculum, bool]:
        """Create a curriculum, or return the identical one that exists (``created`` False).

        Raises ``CurriculumConflict`` when the name holds a different one, ``ValueError`` when the
        teacher rejects its parameters."""
        if name in self._unloadable:
            raise CurriculumConflict(self._unloadable[name][1])
        existing = self._curricula.get(name)
        if existing is not None:
            if existing.spec != spec:
                raise CurriculumConflict(
                    f"curriculum {name!r} already exists with a different configuration "
                    f"(teacher {existing.spec.teacher!r}, seed {existing.spec.seed}); choose another name"
                )
            return existing, False
        taken = [c.id for c in self._curricula.values()] + [id_ for id_, _ in self._unloadable.values()]
        curriculum_id = max(taken, default=0) + 1
        stored = StoredCurriculum(curriculum_id, name, spec.model_dump_json(), time.time())
        curriculum = self._build(stored)
        # Registered before the write so a concurrent PUT sees it; the store's FIFO order puts this
        # row before any task written for it.
        self._curricula[name] = curriculum
        await self._store.add_curriculum(stored, on_abort=lambda: self._curricula.pop(name, None))
        return curriculum, True

    def _build(self, stored: StoredCurriculum) -> Curriculum:
        return Curriculum(
            stored.id,
            stored.name,
            stored_spec(stored.spec),
            stored.created_at,
            self._store,
            self._fits,
            self._builds,
            self._metrics,
            self._settings,
        )
