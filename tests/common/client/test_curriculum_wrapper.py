"""The curriculum wrapper against a real teacher service process.

Most tests wrap ``TaskEcho``, a toy environment whose episode is fully set by its task (so the
result the service must receive is known exactly); one wraps ``KukaGrasp-v0``. The module shares
one service that guards writes with a token; tests that kill it start it again.
"""

from __future__ import annotations

import multiprocessing
import subprocess
import sys
import time
from collections.abc import Iterator
from typing import Any

import gymnasium
import httpx
import numpy as np
import pytest

from common.client.curriculum_wrapper import (
    TOKEN_VARIABLE,
    CurriculumError,
    CurriculumRegistration,
    CurriculumWrapper,
    TaskRejected,
)
from common.client.schemas import API_PREFIX
from common.client.task_space import Parameter, Task, TaskSpace
from common.kuka import ENV_ID
from teacher_service.process import ServiceProcess, free_port

TOKEN = "wrapper-test-token"
ECHO_SPACE = TaskSpace(
    [
        Parameter("steps", 1.0, 6.0, hardest=6.0, easiest=1.0),
        Parameter("reward", -1.0, 1.0, hardest=-1.0, easiest=1.0),
    ]
)
RANDOM_ECHO = CurriculumRegistration("random", ECHO_SPACE, seed=3)


class TaskEcho(gymnasium.Env[np.ndarray, int]):
    """Each episode lasts ``round(task["steps"])`` steps that each earn ``task["reward"]``, and
    succeeds when that reward is positive. Takes its task as ``KukaGrasp-v0`` does."""

    observation_space = gymnasium.spaces.Box(-np.inf, np.inf, shape=(1,))
    action_space = gymnasium.spaces.Discrete(2)

    def __init__(self) -> None:
        self.task: Task = ECHO_SPACE.easiest()
        self._left = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        if options and "task" in options:
            self.task = ECHO_SPACE.validate(options["task"])
        self._left = episode_length(self.task)
        return np.zeros(1, dtype=np.float32), {}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        self._left -= 1
        done = self._left == 0
        return np.zeros(1, dtype=np.float32), self.task["reward"], done, False, {"is_success": self.task["reward"] > 0}


def episode_length(task: Task) -> int:
    return round(task["steps"])


def play(env: gymnasium.Env, episodes: int) -> list[tuple[dict, dict]]:
    """Run whole episodes; the reset info and the final step's info of each."""
    played = []
    for _ in range(episodes):
        _, reset_info = env.reset()
        done = False
        while not done:
            _, _, terminated, truncated, final_info = env.step(env.action_space.sample())
            done = terminated or truncated
        played.append((reset_info, final_info))
    return played


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServiceProcess]:
    with ServiceProcess(tmp_path_factory.mktemp("wrapper") / "teacher.db", env={TOKEN_VARIABLE: TOKEN}) as running:
        yield running


def wrap(
    service: ServiceProcess, curriculum: str, env: gymnasium.Env | None = None, **options: Any
) -> CurriculumWrapper:
    options = {"token": TOKEN, "close_timeout": 20.0, **options}
    return CurriculumWrapper(env or TaskEcho(), service.url, curriculum, **options)


def received(service: ServiceProcess, curriculum: str) -> dict[str, dict]:
    """The results the service holds for a curriculum, by task id."""
    state = httpx.get(f"{service.url}{API_PREFIX}/curricula/{curriculum}/state", timeout=10).json()
    return {result["task_id"]: result for result in state["recent_results"]}


def counters(service: ServiceProcess, curriculum: str) -> dict[str, Any]:
    return httpx.get(f"{service.url}{API_PREFIX}/curricula/{curriculum}", timeout=10).json()["counters"]


def test_the_module_imports_without_torch_ray_or_pybullet():
    code = (
        "import sys, common.client.curriculum_wrapper; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('torch', 'ray', 'pybullet', 'pybullet_data')))"
    )
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert loaded.strip() == "[]"


def test_each_episode_runs_a_task_of_the_teacher_and_reports_its_result(service):
    env = wrap(service, "echo", register=RANDOM_ECHO)
    played = play(env, 12)
    env.close()

    results = received(service, "echo")
    assert len(results) == 12, "close() delivered every result"
    tasks = [reset_info["task"] for reset_info, _ in played]
    assert len({tuple(task.values()) for task in tasks}) == 12, "a new task each episode"
    for reset_info, final_info in played:
        assert final_info["task_id"] == reset_info["task_id"] and final_info["task"] == reset_info["task"]
        result = results[reset_info["task_id"]]
        task = result["params"]
        assert task == reset_info["task"]
        assert result["length"] == episode_length(task)
        assert result["reward"] == pytest.approx(episode_length(task) * task["reward"])
        assert result["success"] == (task["reward"] > 0)


def test_a_callable_sets_the_task_on_an_environment_that_takes_no_options(service):
    class Gravity(TaskEcho):
        def reset(self, *, seed=None, options=None):
            assert not options, "the callable, not the options, carries the task"
            return super().reset(seed=seed)

    def set_task(env: gymnasium.Env, task: Task) -> None:
        env.unwrapped.task = task

    env = wrap(service, "echo-callable", Gravity(), register=RANDOM_ECHO, apply_task=set_task)
    play(env, 5)
    env.close()
    results = received(service, "echo-callable").values()
    assert len(results) == 5
    assert all(result["length"] == episode_length(result["params"]) for result in results), "episodes ran the task"


def test_registration_is_idempotent_and_a_different_configuration_is_refused(service):
    first = wrap(service, "echo-twice", register=RANDOM_ECHO)
    second = wrap(service, "echo-twice", register=RANDOM_ECHO)
    joined = wrap(service, "echo-twice")
    for env in (first, second, joined):
        env.close()
    with pytest.raises(CurriculumError, match="different configuration"):
        wrap(service, "echo-twice", register=CurriculumRegistration("random", ECHO_SPACE, seed=4))


def test_the_environments_of_a_process_share_one_client(service):
    envs = [wrap(service, "echo-shared", register=RANDOM_ECHO, prefetch=4) for _ in range(2)]
    for env in envs:
        env.reset()
    assert counters(service, "echo-shared")["tasks_issued"] == 4, "one batch of tasks served both"
    for env in envs:
        env.close()


def test_an_unknown_curriculum_fails_at_construction(service):
    started = time.monotonic()
    with pytest.raises(CurriculumError, match="no curriculum 'no-such-curriculum'.*register="):
        wrap(service, "no-such-curriculum")
    assert time.monotonic() - started < 5


def test_a_wrong_or_missing_token_fails_at_construction(service, monkeypatch):
    wrap(service, "echo-token", register=RANDOM_ECHO).close()
    with pytest.raises(CurriculumError, match=f"refused.*{TOKEN_VARIABLE}"):
        wrap(service, "echo-token", token="not-the-token")
    monkeypatch.delenv(TOKEN_VARIABLE, raising=False)
    with pytest.raises(CurriculumError, match="got no token"):
        wrap(service, "echo-token", token=None)
    monkeypatch.setenv(TOKEN_VARIABLE, TOKEN)
    wrap(service, "echo-token", token=None).close()


def test_an_unreachable_teacher_fails_at_construction_within_the_timeout():
    started = time.monotonic()
    with pytest.raises(CurriculumError, match="cannot reach the teacher service"):
        CurriculumWrapper(TaskEcho(), f"http://127.0.0.1:{free_port()}", "echo", startup_timeout=1.0)
    assert time.monotonic() - started < 3


def test_a_task_space_the_environment_rejects_fails_at_reset(service):
    env = wrap(service, "echo-on-kuka", gymnasium.make(ENV_ID), register=RANDOM_ECHO)
    with pytest.raises(TaskRejected, match="refused task .*'steps'.*unknown task parameter"):
        env.reset()
    env.close()


def test_a_teacher_outage_neither_stalls_training_nor_loses_a_result(service):
    env = wrap(service, "echo-outage", register=RANDOM_ECHO, prefetch=2, task_timeout=0.5)
    before = play(env, 3)
    service.kill()
    try:
        started = time.monotonic()
        during = play(env, 8)
        assert time.monotonic() - started < 5, "one task_timeout for the whole outage, not one per episode"
        offline = [reset_info for reset_info, _ in during if reset_info["task_id"] is None]
        assert offline, "once the prefetched tasks ran out, episodes went on with recent tasks"
        issued = [reset_info["task"] for reset_info, _ in before + during if reset_info["task_id"] is not None]
        assert all(info["task"] in issued for info in offline)
    finally:
        service.start()
    after = play(env, 3)
    assert all(reset_info["task_id"] is not None for reset_info, _ in after), "back online"
    env.close()

    reported = {info["task_id"] for info, _ in before + during + after if info["task_id"] is not None}
    assert set(received(service, "echo-outage")) == reported


def _play_in_child(env: CurriculumWrapper, episodes: int) -> None:
    play(env, episodes)
    env.close()


def test_a_forked_child_reports_through_a_client_of_its_own(service):
    env = wrap(service, "echo-fork", register=RANDOM_ECHO)
    play(env, 2)
    child = multiprocessing.get_context("fork").Process(target=_play_in_child, args=(env, 3))
    child.start()
    child.join(60)
    assert child.exitcode == 0
    play(env, 2)
    env.close()
    assert len(received(service, "echo-fork")) == 7


def test_the_token_shows_in_no_repr(service, monkeypatch):
    monkeypatch.setenv(TOKEN_VARIABLE, TOKEN)
    for env in (wrap(service, "echo-repr", register=RANDOM_ECHO), wrap(service, "echo-repr", token=None)):
        env.reset()
        shown = [repr(env), str(env), repr(env._client_key), repr(vars(env)), repr(env._client)]
        assert not [text for text in shown if TOKEN in text]
        env.close()


def test_with_scores_from_the_learner_an_episode_waits_for_its_score(service):
    env = wrap(service, "echo-scored", register=RANDOM_ECHO, scores_from_learner=True, report_interval=0.05)
    played = play(env, 5)
    assert all(final_info["score_only"] is False for _, final_info in played)
    time.sleep(0.5)
    assert counters(service, "echo-scored")["results_received"] == 0, "nothing is sent before its score"
    assert env.report_scores([0.5, 0.25, 0.125]) == 2, "two ended episodes still wait"
    with pytest.raises(ValueError, match="3 scores for 2 ended episodes"):
        env.report_scores([1.0, 1.0, 1.0])
    env.close()  # the last two go without a score

    results = received(service, "echo-scored")
    scores = [results[reset_info["task_id"]]["score"] for reset_info, _ in played]
    assert scores == [0.5, 0.25, 0.125, None, None], "each score goes to its episode, in the order they ended"
