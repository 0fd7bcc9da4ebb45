"""The real stack under a real Docker engine, used the way a person on a workstation uses it.

The image built from this checkout runs under docker-compose.yml alone: the teacher, a Ray head, two Ray
worker containers, the learner and TensorBoard, with named volumes, as ``docker-compose up`` starts them.
A short training run goes through it while the test kills the teacher's process and, in a second run, a
whole worker container. The first run has its token in ``.env``; the second has no ``.env`` at all (its
few settings in the shell's environment, as ``TOTAL_STEPS=... docker compose up`` gives them), so the
stack makes its own token.

The engine, the image and the compose project are the ones every Docker test shares (tests/docker_stack.py):
a run here starts on a stack that another test may have left up, and ``up`` recreates what its settings
change, as it would for a person.
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import httpx
import numpy as np
import pytest

from common.client.schemas import API_PREFIX
from tests.docker_stack import (
    FIGURES,
    PUBLISHED_PORTS,
    ROOT,
    TEACHER_URL,
    TOKEN,
    SharedStack,
    run,
    wait_for,
    wait_for_training,
)

pytestmark = [pytest.mark.docker, pytest.mark.timeout(1500)]

ARTIFACTS = ROOT / "test-artifacts" / "docker-stack"

TRAIN_ARGS = "--max-episode-steps=100 --rollout-length=256 --eval-every=0 --checkpoint-every=2"
"""Short episodes and batches (2 actors x 4 environments x 256 steps): ALP-GMM's first fit, after
250 results, comes within seconds, and the run has many iterations in which to inject a fault."""
TEACHER_RUN_STEPS = 60_000
"""Long enough to still be training when the killed teacher is back (it trains on without it): the kill
comes after ALP-GMM's first fit, near step 25,000, and the teacher is back some 7 s later."""
WORKER_RUN_STEPS = 25_000
"""A dozen iterations, most of them after the worker container is killed (after the first)."""

RUN_TIMEOUT_S = 600.0
TRAINING_RESUMES_S = 60.0


def run_settings(**values: str | int) -> dict[str, str]:
    """A short run's settings, as a person would put them in ``.env`` or the shell's environment."""
    settings = {
        "TEACHER": "alp-gmm",
        "ROLLOUT_WORKERS": 2,
        "ENVS_PER_WORKER": 4,
        "RAY_WORKER_CPUS": 2,
        "TRAIN_ARGS": TRAIN_ARGS,
        **values,
    }
    return {name: str(value) for name, value in settings.items()}


def curriculum(name: str, part: str = "") -> dict[str, Any]:
    response = httpx.get(f"{TEACHER_URL}{API_PREFIX}/curricula/{name}{part}", timeout=5)
    response.raise_for_status()
    data: dict[str, Any] = response.json()
    return data


def results_received(name: str) -> int:
    """The curriculum's result count; 0 until the learner has registered it."""
    try:
        return int(curriculum(name)["counters"]["results_received"])
    except httpx.HTTPError:
        return 0


def teacher_answers() -> bool:
    try:
        return httpx.get(f"{TEACHER_URL}/healthz", timeout=2).status_code == 200
    except httpx.HTTPError:
        return False


def docker(*arguments: str, timeout: float = 120.0) -> str:
    return run(["docker", *arguments], timeout=timeout)


def container(stack: SharedStack, service: str) -> str:
    [one] = stack.containers(service)
    return one


def state(container: str) -> dict[str, Any]:
    state: dict[str, Any] = json.loads(docker("inspect", "--format", "{{json .State}}", container))
    state["RestartCount"] = int(docker("inspect", "--format", "{{.RestartCount}}", container))
    return state


def read_runs_file(stack: SharedStack, path: str) -> str:
    """A file on the ``runs`` volume, through the TensorBoard container that keeps it mounted."""
    return docker("exec", container(stack, "tensorboard"), "cat", f"/runs/{path}")


def metrics(stack: SharedStack, run_name: str) -> list[dict[str, Any]]:
    try:
        text = read_runs_file(stack, f"{run_name}/metrics.jsonl")
    except AssertionError:  # not written yet
        return []
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def rollout_actors_hosted(container: str, since: float) -> int:
    """Ray worker processes in this container that hosted a rollout actor since the Unix time ``since`` (Ray
    heads each one's log with it; a log last written before is an earlier run's)."""
    logs = f"find /tmp/ray/session_latest/logs -name 'worker-*.out' -newermt @{since:.0f} -exec cat {{}} + || true"
    return docker("exec", container, "sh", "-c", logs).count(":actor_name:RolloutWorker")


def wait_for_exit(container: str) -> dict[str, Any]:
    return wait_for(lambda: (now := state(container))["Status"] == "exited" and now, RUN_TIMEOUT_S, "the learner")


@dataclass
class TeacherKillRun:
    """What the test saw of a run whose teacher was killed mid-run; the tests below check it."""

    stack: SharedStack
    run_name: str
    learner_state: dict[str, Any] = field(default_factory=dict)
    learner_log: str = ""
    actors_per_container: dict[str, int] = field(default_factory=dict)
    before_kill: dict[str, Any] = field(default_factory=dict)
    after_restart: dict[str, Any] = field(default_factory=dict)
    teacher_restarts: int = 0
    """By Docker's restart policy, from the kill until the teacher answered again."""
    steps_at_kill: int = 0
    steps_after_restart: int = 0


@pytest.fixture(scope="module")
def stack(docker_stack: SharedStack) -> Iterator[SharedStack]:
    """The shared stack for this file's runs; its log and the figures are kept when they are done."""
    try:
        yield docker_stack
    finally:
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        with contextlib.suppress(Exception):
            (ARTIFACTS / "compose.log").write_text(docker_stack.compose("logs", "--no-color", "--timestamps"))
        (ARTIFACTS / "figures.json").write_text(json.dumps(FIGURES, indent=2) + "\n")
        print(f"docker stack figures: {FIGURES}")


@pytest.fixture(scope="module")
def teacher_kill_run(stack: SharedStack) -> TeacherKillRun:
    """Training with the teacher's process killed after ALP-GMM's first fit (a crash, not a ``docker stop``)."""
    observed = TeacherKillRun(stack, run_name="alp-gmm-seed0")
    up_at, up_at_unix = time.monotonic(), time.time()
    stack.start_plain_run(run_settings(KC_TEACHER_TOKEN=TOKEN, SEED=0, TOTAL_STEPS=TEACHER_RUN_STEPS))
    learner = container(stack, "learner")
    wait_for_training(
        stack, lambda: results_received(observed.run_name), "the teacher's first episode result", ARTIFACTS
    )
    FIGURES["up_to_first_result_seconds"] = time.monotonic() - up_at
    wait_for_training(stack, lambda: metrics(stack, observed.run_name), "the learner's first iteration", ARTIFACTS)
    workers = stack.containers("ray-worker")
    observed.actors_per_container = {
        **{f"ray-worker {index}": rollout_actors_hosted(worker, up_at_unix) for index, worker in enumerate(workers)},
        "ray-head": rollout_actors_hosted(container(stack, "ray-head"), up_at_unix),
        "learner": rollout_actors_hosted(learner, up_at_unix),
    }

    def fitted() -> bool:
        return bool(curriculum(observed.run_name)["counters"]["fits_completed"] >= 1)

    wait_for(fitted, RUN_TIMEOUT_S, "ALP-GMM's first fit")
    teacher = container(stack, "teacher")
    restarts_before = state(teacher)["RestartCount"]
    observed.before_kill = curriculum(observed.run_name, "/state")
    observed.steps_at_kill = metrics(stack, observed.run_name)[-1]["step"]
    # With `init: true` the init process survives `kill -1` and exits with the killed service, as a crash would.
    killed_at = time.monotonic()
    docker("exec", teacher, "sh", "-c", "kill -KILL -1")
    wait_for(lambda: state(teacher)["RestartCount"] > restarts_before, 60, "Docker to restart the teacher")
    wait_for(teacher_answers, 120, "the restarted teacher to answer")
    FIGURES["teacher_away_seconds"] = time.monotonic() - killed_at
    observed.after_restart = curriculum(observed.run_name, "/state")
    observed.teacher_restarts = state(teacher)["RestartCount"] - restarts_before
    # The outage lasts about as long as one iteration (~2 s), so the learner may not have logged one
    # since the kill when the teacher answers again; it must do so soon after, and not stay stalled.
    deadline = time.monotonic() + TRAINING_RESUMES_S
    while (step := metrics(stack, observed.run_name)[-1]["step"]) <= observed.steps_at_kill:
        if time.monotonic() > deadline:
            break
        time.sleep(1.0)
    observed.steps_after_restart = step
    FIGURES["teacher_killed_at_step"], FIGURES["training_past_it_at_step"] = observed.steps_at_kill, step

    observed.learner_state = wait_for_exit(learner)
    observed.learner_log = docker("logs", learner)
    records = metrics(stack, observed.run_name)
    iteration_steps = np.diff([0, *(record["step"] for record in records)])
    seconds = sum(
        steps / record["perf/steps_per_second"] for steps, record in zip(iteration_steps, records, strict=True)
    )
    FIGURES["training_steps_per_second"] = records[-1]["step"] / seconds
    return observed


# --- what a person sees -----------------------------------------------------------------------------


def test_the_learner_finishes_with_its_final_checkpoint_on_the_runs_volume(teacher_kill_run: TeacherKillRun) -> None:
    learner = teacher_kill_run.learner_state
    assert (learner["ExitCode"], learner["RestartCount"]) == (0, 0), teacher_kill_run.learner_log[-3000:]
    last_line = teacher_kill_run.learner_log.strip().splitlines()[-1]
    assert last_line.startswith("final checkpoint: /runs/alp-gmm-seed0/checkpoints/"), last_line
    checkpoint = last_line.removeprefix("final checkpoint: ")
    docker("exec", container(teacher_kill_run.stack, "tensorboard"), "test", "-s", checkpoint)
    assert metrics(teacher_kill_run.stack, teacher_kill_run.run_name)[-1]["step"] >= TEACHER_RUN_STEPS


def test_rollout_actors_run_on_both_worker_containers_only(teacher_kill_run: TeacherKillRun) -> None:
    placed = teacher_kill_run.actors_per_container
    assert placed["ray-head"] == placed["learner"] == 0, placed
    workers = [count for name, count in placed.items() if name.startswith("ray-worker")]
    assert len(workers) == 2 and all(count >= 1 for count in workers), placed


def test_the_printed_dashboard_opens_on_the_host_with_the_curriculum_and_its_results(
    teacher_kill_run: TeacherKillRun,
) -> None:
    dashboard = f"{TEACHER_URL}/curricula/{teacher_kill_run.run_name}"
    assert f"dashboard:     {dashboard}" in teacher_kill_run.learner_log
    page = httpx.get(dashboard, timeout=10)
    assert page.status_code == 200 and teacher_kill_run.run_name in page.text
    shown = curriculum(teacher_kill_run.run_name, "/state")
    assert shown["curriculum"]["config"]["teacher"] == "alp-gmm"
    assert shown["recent_results"] and shown["curriculum"]["counters"]["fits_completed"] >= 1


def test_tensorboard_and_the_ray_dashboard_answer_on_the_host(teacher_kill_run: TeacherKillRun) -> None:
    runs = httpx.get(f"http://127.0.0.1:{PUBLISHED_PORTS['TensorBoard']}/data/runs", timeout=30)
    assert runs.status_code == 200 and f"{teacher_kill_run.run_name}/tensorboard" in runs.json()
    ray_dashboard = httpx.get(f"http://127.0.0.1:{PUBLISHED_PORTS['Ray dashboard']}/", timeout=30)
    assert ray_dashboard.status_code == 200


def test_a_write_without_the_token_is_refused(teacher_kill_run: TeacherKillRun) -> None:
    tasks = f"{TEACHER_URL}{API_PREFIX}/curricula/{teacher_kill_run.run_name}/tasks"
    assert httpx.post(tasks, json={"count": 1}, timeout=10).status_code == 401
    wrong = httpx.post(tasks, json={"count": 1}, headers={"Authorization": "Bearer wrong"}, timeout=10)
    assert wrong.status_code == 401
    right = httpx.post(tasks, json={"count": 1}, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=10)
    assert right.status_code == 200


def test_a_killed_teacher_comes_back_by_itself_with_its_counters_and_fits(teacher_kill_run: TeacherKillRun) -> None:
    assert teacher_kill_run.teacher_restarts >= 1
    before, after = teacher_kill_run.before_kill, teacher_kill_run.after_restart
    for counter in ("tasks_issued", "results_received", "fits_completed"):
        assert after["curriculum"]["counters"][counter] >= before["curriculum"]["counters"][counter], counter
    fits_after = {fit["index"]: fit for fit in after["fits"]}
    for fit in before["fits"]:
        assert fits_after[fit["index"]]["started_at"] == fit["started_at"], "a fit was lost or rewritten"
    assert any(fit["replayed"] for fit in after["fits"]), "the restarted teacher did not rebuild its fits"


def test_the_learner_carries_on_and_no_episode_result_is_lost(teacher_kill_run: TeacherKillRun) -> None:
    assert teacher_kill_run.steps_after_restart > teacher_kill_run.steps_at_kill, "training stalled"
    records = metrics(teacher_kill_run.stack, teacher_kill_run.run_name)
    reported = sum(r["train/episodes"] - r["train/offline_episodes"] for r in records)
    received = curriculum(teacher_kill_run.run_name)["counters"]["results_received"]
    assert received == reported > 0


@dataclass
class NoEnvRun:
    """The second run: no ``.env``, so the stack's own token; one of the two worker containers killed."""

    stack: SharedStack
    victim: str
    learner_state: dict[str, Any]
    learner_log: str
    token: str


@pytest.fixture(scope="module")
def no_env_run(teacher_kill_run: TeacherKillRun) -> NoEnvRun:
    """The same stack brought up again with no ``.env`` and another seed: the teacher (whose token
    changes) and the learner are recreated; the teacher's database and the runs stay on their volumes."""
    stack = teacher_kill_run.stack
    stack.start_plain_run({}, shell=run_settings(SEED=1, TOTAL_STEPS=WORKER_RUN_STEPS))
    learner = container(stack, "learner")
    wait_for_training(stack, lambda: metrics(stack, "alp-gmm-seed1"), "the second run's first iteration", ARTIFACTS)
    victim = stack.containers("ray-worker")[0]
    docker("kill", victim)

    learner_state = wait_for_exit(learner)
    token = docker("exec", container(stack, "teacher"), "cat", "/secrets/teacher-token").strip()
    return NoEnvRun(stack, victim, learner_state, docker("logs", learner), token)


def test_training_completes_when_a_worker_container_is_killed(no_env_run: NoEnvRun) -> None:
    learner = no_env_run.learner_state
    assert (learner["ExitCode"], learner["RestartCount"]) == (0, 0), no_env_run.learner_log[-3000:]
    assert state(no_env_run.victim)["Status"] == "exited", "the killed worker container came back"
    records = metrics(no_env_run.stack, "alp-gmm-seed1")
    assert records[-1]["step"] >= WORKER_RUN_STEPS
    assert records[-1]["workers/replacements"] >= 1, "no rollout actor was replaced after its container died"
    last_line = no_env_run.learner_log.strip().splitlines()[-1]
    assert last_line.startswith("final checkpoint: /runs/alp-gmm-seed1/checkpoints/"), last_line


def test_with_no_env_the_stack_makes_a_token_and_the_learner_says_how_to_read_it(no_env_run: NoEnvRun) -> None:
    log = no_env_run.learner_log
    hint = "teacher token: made on the stack's first start; read it with: docker compose exec teacher cat "
    assert f"{hint}/secrets/teacher-token" in log, log[:3000]
    assert f"dashboard:     {TEACHER_URL}/curricula/alp-gmm-seed1" in log
    assert len(no_env_run.token) >= 40 and no_env_run.token != TOKEN

    tasks = f"{TEACHER_URL}{API_PREFIX}/curricula/alp-gmm-seed1/tasks"
    assert httpx.post(tasks, json={"count": 1}, timeout=10).status_code == 401
    old = httpx.post(tasks, json={"count": 1}, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=10)
    assert old.status_code == 401, "the .env token of the first run should no longer be accepted"
    made = httpx.post(tasks, json={"count": 1}, headers={"Authorization": f"Bearer {no_env_run.token}"}, timeout=10)
    assert made.status_code == 200
