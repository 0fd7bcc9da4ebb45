"""The teacher probe asks a real, throwaway teacher service what it takes, and leaves nothing behind."""

from __future__ import annotations

import tempfile
from collections.abc import Iterator

import httpx
import pytest

from common.client.schemas import TEACHER_LABELS
from common.client.write_token import TOKEN_VARIABLE
from common.kuka.task_space import KUKA_TASK_SPACE
from learner.core.config import TrainConfig
from learner.experiments.bakeoff_runs import kinds_for_family
from learner.job.teacher_probe import Reason, TeacherProbe, UnknownTeacherKind, teacher_probe


@pytest.fixture(scope="module")
def probe() -> Iterator[TeacherProbe]:
    with teacher_probe() as probe:
        yield probe


def test_the_kinds_and_their_parameters_are_the_services(probe):
    assert sorted(probe.kinds) == sorted(TEACHER_LABELS)
    names = [parameter.name for parameter in probe.kind("alp-gmm").parameters]
    assert {"fit_rate", "random_task_ratio", "reward_range"} <= set(names)
    assert probe.parameters("alp-gmm", KUKA_TASK_SPACE).names == tuple(names)
    with pytest.raises(UnknownTeacherKind, match="no teacher kind 'curot'; known: .*currot"):
        probe.kind("curot")


def test_a_refusal_names_the_parameter_in_the_services_words(probe):
    assert probe.refusal("currot", KUKA_TASK_SPACE, {"start": "easiest"}) is None
    refusal = probe.refusal("currot", KUKA_TASK_SPACE, {"start": "middle"})
    assert refusal is not None and refusal.about_parameters
    assert refusal.reasons == (Reason("start", "Input should be 'uniform' or 'easiest'"),)
    assert (
        refusal.line("currot", "KukaGrasp-v0")
        == "--teacher-param for currot: start: Input should be 'uniform' or 'easiest'"
    )
    assert str(probe.refusal("riac", KUKA_TASK_SPACE, {"fit_rate": 100})) == "fit_rate: Extra inputs are not permitted"


def test_the_services_validators_decide_what_a_schema_cannot(probe):
    """[10, 0] is two numbers within bounds, as a JSON schema sees it; only the model's validator refuses it."""
    refusal = probe.refusal("adr", KUKA_TASK_SPACE, {"reward_range": [10, 0]})
    assert refusal is not None and refusal.about_parameters
    assert "reward_range must have low < high" in refusal.messages
    assert probe.refusal("adr", KUKA_TASK_SPACE, {"reward_range": [0, 10]}) is None
    # Each value on its own: 0.9 fits beside ALP-GMM's own target_task_ratio, not beside 0.2.
    parameters = probe.parameters("alp-gmm", KUKA_TASK_SPACE)
    assert parameters.problem("random_task_ratio", 0.9) is None
    assert "cannot add up to more than 1" in str(
        probe.refusal("alp-gmm", KUKA_TASK_SPACE, {"random_task_ratio": 0.9, "target_task_ratio": 0.2})
    )
    assert parameters.problem("fit_rate", 1) == "Input should be greater than or equal to 2"


def test_a_kind_that_does_not_take_the_space_is_refused_for_the_space(probe):
    refusal = probe.refusal("plr", KUKA_TASK_SPACE, {})
    assert refusal is not None and not refusal.about_parameters
    assert "the plr teacher takes integer parameters only" in str(refusal)
    assert refusal.line("plr", "KukaGrasp-v0").startswith("plr on KukaGrasp-v0: Value error, parameter 'rnd_obj_x'")
    unknown = probe.refusal("curot", KUKA_TASK_SPACE, {})
    assert unknown is not None and "'curot'" in str(unknown) and "'currot'" in str(unknown)


def test_the_probe_service_is_private_and_gone_after_the_block(monkeypatch, tmp_path):
    """A deployment's token and host list are the real service's: the probe's own service takes neither, so
    the probe registers without the token; the service and its database go with the block."""
    monkeypatch.setenv(TOKEN_VARIABLE, "a-token-the-probe-never-sends")
    monkeypatch.setenv("KC_ALLOWED_HOSTS", "teacher")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    with teacher_probe() as probe:
        assert probe.refusal("random", KUKA_TASK_SPACE, {}) is None
        assert httpx.get(f"{probe.url}/healthz").json()["curricula"] == 1
        [directory] = tmp_path.iterdir()
        assert (directory / "probe.sqlite").exists()
    with pytest.raises(httpx.TransportError):
        httpx.get(f"{probe.url}/healthz", timeout=1.0)
    assert not list(tmp_path.iterdir())


def test_a_bakeoffs_default_teachers_are_the_kinds_the_service_takes_for_the_family(probe):
    """Over KUKA's float box, every kind but the two that take levels only; over levels, the level kinds and random, not
    the kinds that need a hardest or easiest point a level space does not define."""
    kuka = kinds_for_family(probe, "KukaGrasp-v0", TrainConfig().levels)
    assert {"alp-gmm", "currot", "fixed", "manual", "random"} <= set(kuka)
    assert not {"plr", "learning-progress"} & set(kuka)
    levels = kinds_for_family(probe, "MiniGrid-DoorKey-8x8-v0", 50)
    assert set(levels) == {"random", "plr", "learning-progress", "learnability"}
