"""The fit runner with real spawned fit processes: fair turns between curricula, a waiting fit
replaced by the next, abandoned fits, processes that keep dying, and delivery in due order. The
last test drives two ALP-GMM curricula through a real service."""

from __future__ import annotations

import asyncio
import functools
import os
import signal
import time
from collections import defaultdict
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import fit_jobs
import httpx

from common.client.task_space import Parameter, TaskSpace
from teacher_service.fits import FitOutcome, FitRunner
from teacher_service.metrics import ServiceMetrics
from teacher_service.process import ServiceProcess
from teacher_service.teachers import EpisodeResult, FitJob, make_teacher
from teacher_service.teachers.alp_gmm import AlpGmmTeacher

SHORT_S = 0.4
"""A short fit's duration. B's fits must land within a few of these (a loaded CI machine adds
hundreds of milliseconds of spawn and scheduling noise), far sooner than A's long fit of 30."""


class Outcomes:
    """Every outcome delivered, per curriculum and overall, with when it arrived."""

    def __init__(self) -> None:
        self.by_curriculum: defaultdict[str, list[FitOutcome]] = defaultdict(list)
        self.arrived_at: dict[tuple[str, int], float] = {}
        self.order: list[tuple[str, int]] = []

    def receiver(self, curriculum: str) -> Callable[[FitOutcome], None]:
        def receive(outcome: FitOutcome) -> None:
            self.by_curriculum[curriculum].append(outcome)
            self.arrived_at[curriculum, outcome.index] = time.monotonic()
            self.order.append((curriculum, outcome.index))

        return receive

    async def wait(self, curriculum: str, count: int, timeout: float = 90.0) -> list[FitOutcome]:
        deadline = time.monotonic() + timeout
        while len(self.by_curriculum[curriculum]) < count:
            assert time.monotonic() < deadline, f"{curriculum}: {len(self.by_curriculum[curriculum])} of {count} fits"
            await asyncio.sleep(0.02)
        return self.by_curriculum[curriculum]


@asynccontextmanager
async def fit_runner(processes: int, timeout_s: float = 30.0) -> AsyncIterator[tuple[FitRunner, ServiceMetrics]]:
    metrics = ServiceMetrics()
    runner = FitRunner(processes, timeout_s, metrics)
    runner.start(asyncio.get_running_loop())
    try:
        yield runner, metrics
    finally:
        runner.close()


def job(index: int, run: Callable[..., Any], *args: Any) -> FitJob:
    return FitJob(index=index, run=functools.partial(run, *args))


def sample(metrics: ServiceMetrics, name: str, **labels: str) -> float | None:
    return metrics.registry.get_sample_value(name, labels)


def test_a_long_fit_of_one_curriculum_does_not_hold_up_another() -> None:
    async def scenario() -> None:
        outcomes = Outcomes()
        async with fit_runner(processes=2) as (runner, _):
            for name in ("a", "b"):  # one fit each starts both processes
                runner.submit(name, job(0, fit_jobs.sleep_then, 0.0, None), outcomes.receiver(name))
            await outcomes.wait("a", 1)
            await outcomes.wait("b", 1)
            runner.submit("a", job(1, fit_jobs.sleep_then, 30 * SHORT_S, None), outcomes.receiver("a"))
            for index in range(1, 4):
                due = time.monotonic()
                runner.submit("b", job(index, fit_jobs.sleep_then, SHORT_S, index), outcomes.receiver("b"))
                (*_, landed) = await outcomes.wait("b", index + 1)
                latency = outcomes.arrived_at["b", index] - due
                assert (landed.index, landed.error) == (index, None)
                assert latency < 5 * SHORT_S, f"b's fit {index} landed {latency:.2f} s after it fell due"
            assert len(outcomes.by_curriculum["a"]) == 1, "a's long fit finished: nothing was overlapped"

    asyncio.run(scenario())


def test_a_fit_process_runs_every_native_thread_pool_on_one_thread() -> None:
    """A second BLAS or OpenMP thread in one curriculum's fit takes the core that another's fit or
    the service needs: scikit-learn's OpenMP k-means once slowed a neighbour's fits 2.5 times."""

    async def scenario() -> list[dict[str, Any]]:
        outcomes = Outcomes()
        async with fit_runner(processes=1) as (runner, _):
            runner.submit("a", job(0, fit_jobs.thread_pools), outcomes.receiver("a"))
            (outcome,) = await outcomes.wait("a", 1)
        assert outcome.error is None
        return outcome.output

    pools = asyncio.run(scenario())
    assert {pool["user_api"] for pool in pools} == {"blas", "openmp"}, pools
    assert all(pool["num_threads"] == 1 for pool in pools), pools


def test_a_free_process_goes_to_the_curriculum_that_waited_longest() -> None:
    async def scenario() -> None:
        outcomes = Outcomes()
        async with fit_runner(processes=1) as (runner, _):
            runner.submit("a", job(0, fit_jobs.sleep_then, 0.0, None), outcomes.receiver("a"))
            await outcomes.wait("a", 1)  # the process is up
            runner.submit("a", job(1, fit_jobs.sleep_then, 1.0, None), outcomes.receiver("a"))
            runner.submit("a", job(2, fit_jobs.sleep_then, 0.0, None), outcomes.receiver("a"))
            runner.submit("b", job(0, fit_jobs.sleep_then, 0.0, None), outcomes.receiver("b"))
            runner.submit("c", job(0, fit_jobs.sleep_then, 0.0, None), outcomes.receiver("c"))
            await outcomes.wait("a", 3)
            await outcomes.wait("c", 1)
        assert outcomes.order == [("a", 0), ("a", 1), ("b", 0), ("c", 0), ("a", 2)]

    asyncio.run(scenario())


def test_a_waiting_fit_is_superseded_by_the_next_and_outcomes_arrive_in_due_order() -> None:
    async def scenario() -> None:
        outcomes = Outcomes()
        async with fit_runner(processes=1) as (runner, metrics):
            runner.submit("a", job(0, fit_jobs.sleep_then, 0.0, "fit 0"), outcomes.receiver("a"))
            await outcomes.wait("a", 1)  # the process is up
            runner.submit("a", job(1, fit_jobs.sleep_then, 1.0, "fit 1"), outcomes.receiver("a"))
            for index in range(2, 5):
                runner.submit("a", job(index, fit_jobs.sleep_then, 0.0, f"fit {index}"), outcomes.receiver("a"))
            delivered = await outcomes.wait("a", 5)
            assert sample(metrics, "kc_fits_superseded_total", curriculum="a") == 2
        assert [(o.index, o.output, o.error) for o in delivered] == [
            (0, "fit 0", None),
            (1, "fit 1", None),
            (2, None, "superseded by fit 3"),
            (3, None, "superseded by fit 4"),
            (4, "fit 4", None),
        ]
        running, superseded = delivered[1], delivered[2]
        assert superseded.finished_at < running.finished_at, "fit 2 was superseded while fit 1 ran"

    asyncio.run(scenario())


def _results(teacher: AlpGmmTeacher, count: int) -> list[FitJob]:
    """Feed ``count`` results whose reward rises along x0; return the fits that fell due."""
    jobs = []
    for task in teacher.sample(count):
        fit = teacher.learn(EpisodeResult(task, task["x0"] * teacher.results_seen / 100))
        if fit is not None:
            jobs.append(fit)
    return jobs


def test_a_fit_past_the_time_limit_is_abandoned_and_the_teacher_keeps_its_model(tmp_path: Path) -> None:
    space = TaskSpace([Parameter("x0", 0.0, 1.0), Parameter("x1", 0.0, 1.0)])
    teacher = make_teacher("alp-gmm", space, 5, {"fit_rate": 20, "min_components": 1, "max_components": 2})
    assert isinstance(teacher, AlpGmmTeacher)
    pid_file = tmp_path / "hung.pid"

    def install(outcome: FitOutcome) -> None:
        if outcome.error is None:
            teacher.install(outcome.output)

    async def scenario() -> None:
        outcomes = Outcomes()
        record = outcomes.receiver("a")

        def install_and_record(outcome: FitOutcome) -> None:
            install(outcome)
            record(outcome)

        async with fit_runner(processes=1, timeout_s=1.0) as (runner, metrics):
            (first,) = _results(teacher, 20)
            runner.submit("a", first, install_and_record)
            await outcomes.wait("a", 1)
            assert teacher.state()["last_fit_index"] == 0
            (hanging,) = _results(teacher, 20)
            hang = job(hanging.index, fit_jobs.note_pid_then_sleep, str(pid_file), 60.0)
            runner.submit("a", hang, install_and_record)
            (*_, abandoned) = await outcomes.wait("a", 2)
            assert abandoned.error == "abandoned after 1 s"
            assert 1.0 <= abandoned.finished_at - abandoned.started_at < 5.0
            assert sample(metrics, "kc_fit_timeouts_total", curriculum="a") == 1
            assert teacher.state()["last_fit_index"] == 0, "the teacher must keep its model"
            assert len(teacher.sample(5)) == 5
            hung = int(pid_file.read_text())
            deadline = time.monotonic() + 10
            while Path(f"/proc/{hung}").exists():
                assert time.monotonic() < deadline, "the hung fit's process was not killed"
                await asyncio.sleep(0.05)
            (after,) = _results(teacher, 20)
            runner.submit("a", after, install_and_record)
            runner.submit("b", job(0, fit_jobs.own_pid), outcomes.receiver("b"))
            await outcomes.wait("a", 3)
            (fresh,) = await outcomes.wait("b", 1)
            assert fresh.error is None and fresh.output != hung
            assert teacher.state()["last_fit_index"] == after.index == 2

    asyncio.run(scenario())


def test_a_process_that_dies_once_is_replaced_and_its_fit_runs_again(tmp_path: Path) -> None:
    async def scenario() -> None:
        outcomes = Outcomes()
        async with fit_runner(processes=1) as (runner, metrics):
            runner.submit("a", job(0, fit_jobs.exit_once, str(tmp_path / "exited"), "model"), outcomes.receiver("a"))
            (outcome,) = await outcomes.wait("a", 1)
            assert (outcome.output, outcome.error) == ("model", None)
            assert sample(metrics, "kc_fit_process_deaths_total") == 1
            assert runner.stopped is None

    asyncio.run(scenario())


def test_processes_that_keep_dying_stop_the_fits_and_say_why() -> None:
    async def scenario() -> None:
        outcomes = Outcomes()
        async with fit_runner(processes=1) as (runner, metrics):
            runner.submit("a", job(0, fit_jobs.kill_own_process), outcomes.receiver("a"))
            (outcome,) = await outcomes.wait("a", 1, timeout=60.0)
            assert runner.stopped is not None
            assert "died 3 times in a row" in runner.stopped and "SIGKILL" in runner.stopped
            assert outcome.error == f"fits stopped: {runner.stopped}"
            assert sample(metrics, "kc_fit_process_deaths_total") == 3
            assert sample(metrics, "kc_fits_stopped") == 1
            runner.submit("b", job(0, fit_jobs.own_pid), outcomes.receiver("b"))
            (refused,) = outcomes.by_curriculum["b"]
            assert refused.error == outcome.error, "a fit after the stop must complete at once, unrun"

    asyncio.run(scenario())


def _feed(http: httpx.Client, name: str, count: int) -> None:
    """Draw ``count`` tasks and report a reward that rises with ``jp2``."""
    while count:
        batch = min(count, 1000)
        tasks = http.post(f"/curricula/{name}/tasks", json={"count": batch}).json()["tasks"]
        results = [{"task_id": t["task_id"], "reward": t["params"]["jp2"]} for t in tasks]
        assert http.post(f"/curricula/{name}/results", json={"results": results}).json()["accepted"] == batch
        count -= batch


def _counters(http: httpx.Client, name: str) -> dict[str, Any]:
    counters: dict[str, Any] = http.get(f"/curricula/{name}").json()["counters"]
    return counters


def test_an_ordinary_curriculum_keeps_fitting_beside_one_with_the_most_expensive_fits(
    tmp_path: Path, kuka_space: list[dict[str, Any]]
) -> None:
    expensive = {"fit_rate": 2000, "min_components": 1, "max_components": 16, "nb_em_init": 5}
    ordinary = {"fit_rate": 50, "min_components": 2, "max_components": 4}
    with (
        ServiceProcess(tmp_path / "teacher.db", env={"KC_FIT_PROCESSES": "2"}) as service,
        httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0) as http,
    ):
        for name, params in (("expensive", expensive), ("ordinary", ordinary)):
            body = {"teacher": "alp-gmm", "space": kuka_space, "params": params, "seed": 1}
            assert http.put(f"/curricula/{name}", json=body).status_code == 201
        _feed(http, "expensive", 2000)
        for fits in range(1, 4):
            _feed(http, "ordinary", 50)
            deadline = time.monotonic() + 90
            while _counters(http, "ordinary")["fits_completed"] < fits:
                assert time.monotonic() < deadline, f"the ordinary curriculum's fit {fits - 1} did not land"
                time.sleep(0.05)
        assert _counters(http, "expensive")["fits_pending"] == 1, "the expensive fit ended first: nothing overlapped"
        fits = http.get("/curricula/ordinary/state").json()["fits"]
        assert [(f["index"], f["error"]) for f in fits] == [(0, None), (1, None), (2, None)]
        assert http.get(f"{service.url}/healthz").json()["fits_stopped"] is None


def test_the_service_says_when_its_fit_processes_keep_dying(
    tmp_path: Path, kuka_space: list[dict[str, Any]], fit_processes: Callable[[int], list[int]]
) -> None:
    """Each fit process is killed as soon as it appears, so the fit never finishes."""
    params = {"fit_rate": 2000, "min_components": 1, "max_components": 16, "nb_em_init": 5}
    with (
        ServiceProcess(tmp_path / "teacher.db") as service,
        httpx.Client(base_url=f"{service.url}/api/v1", timeout=30.0) as http,
    ):
        body = {"teacher": "alp-gmm", "space": kuka_space, "params": params, "seed": 1}
        assert http.put("/curricula/doomed", json=body).status_code == 201
        _feed(http, "doomed", 2000)
        killed: set[int] = set()
        deadline = time.monotonic() + 60
        while len(killed) < 3:
            assert time.monotonic() < deadline, f"only {len(killed)} fit processes appeared"
            for pid in set(fit_processes(service.pid)) - killed:
                os.kill(pid, signal.SIGKILL)
                killed.add(pid)
            time.sleep(0.02)
        while (reason := http.get(f"{service.url}/healthz").json()["fits_stopped"]) is None:
            assert time.monotonic() < deadline, "the service did not report that fits stopped"
            time.sleep(0.05)
        assert "died 3 times in a row" in reason and "killed by SIGKILL" in reason
        assert "resume when the service restarts" in reason
        counters = _counters(http, "doomed")
        assert (counters["fits_stopped"], counters["fits_pending"]) == (reason, 0)
        (fit,) = http.get("/curricula/doomed/state").json()["fits"]
        assert (fit["index"], fit["error"]) == (0, f"fits stopped: {reason}")
        metrics = httpx.get(f"{service.url}/metrics").text
        assert "kc_fits_stopped 1.0" in metrics and "kc_fit_process_deaths_total 3.0" in metrics
        _feed(http, "doomed", 10)  # tasks are still served
        assert fit_processes(service.pid) == [], "no fit process may be started after the stop"
