"""ALP-GMM: bootstrap, refit cadence, model choice by AIC, ALP values and where tasks come from."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from common.client.task_space import Parameter, TaskSpace
from common.kuka.task_space import KUKA_TASK_SPACE
from teacher_service.teachers import EpisodeResult, make_teacher
from teacher_service.teachers.algorithms import learning_progress
from teacher_service.teachers.algorithms.learning_progress import TREE_GROWTH
from teacher_service.teachers.alp_gmm import AlpGmmTeacher
from teacher_service.teachers.mixture import MixtureFit, fit_mixture

SKEWED = TaskSpace(
    [
        Parameter("wide", 0.0, 100.0, hardest=100.0, easiest=0.0),
        Parameter("narrow", -1.0, 0.0, hardest=-1.0, easiest=0.0),
    ]
)
"""Two parameters whose ranges differ 100-fold, like jp2 next to bias_obj_y."""


def alp_gmm(space: TaskSpace = SKEWED, seed: int = 0, **params: Any) -> AlpGmmTeacher:
    teacher = make_teacher("alp-gmm", space, seed, params)
    assert isinstance(teacher, AlpGmmTeacher)
    return teacher


def feed(teacher: AlpGmmTeacher, history: list[tuple[dict[str, float], float]]) -> None:
    for task, reward in history:
        teacher.learn_and_fit(EpisodeResult(task, reward))


def two_component_fit(alps: tuple[float, float], means: list[list[float]], variance: float) -> MixtureFit:
    """A hand-made mixture over (wide, narrow, ALP) in unit task coordinates."""
    return MixtureFit(
        index=0,
        weights=np.array([0.5, 0.5]),
        means=np.array([[*means[0], alps[0]], [*means[1], alps[1]]]),
        covariances=np.array([np.eye(3) * variance] * 2),
    )


def test_first_fit_rate_tasks_are_uniform_and_the_first_fit_comes_due_after_them() -> None:
    teacher = alp_gmm(KUKA_TASK_SPACE, fit_rate=30, max_components=3)
    jobs = []
    for _ in range(30):
        jobs.append(teacher.learn(EpisodeResult(teacher.sample(1)[0], 0.0)))
    assert jobs[:-1] == [None] * 29 and jobs[-1] is not None
    assert teacher.state()["task_origins"] == {"gmm": 0, "uniform": 30}

    teacher.sample(50)
    assert teacher.state()["task_origins"]["gmm"] == 0, "a due fit changes nothing until it is installed"
    assert teacher.state()["bootstrapping"]

    teacher.install(jobs[-1].run())
    teacher.sample(1000)
    origins = teacher.state()["task_origins"]
    assert not teacher.state()["bootstrapping"]
    assert origins["uniform"] - 80 == pytest.approx(0.2 * 1000, abs=40)
    assert teacher.state()["recent_task_origins"].count("gmm") == origins["gmm"]


def test_a_bootstrap_spread_keeps_bootstrap_tasks_near_the_easiest_until_the_first_fit() -> None:
    teacher = alp_gmm(KUKA_TASK_SPACE, fit_rate=30, max_components=3, bootstrap_spread=0.1)
    easiest = KUKA_TASK_SPACE.to_unit(KUKA_TASK_SPACE.to_array(KUKA_TASK_SPACE.easiest()))
    bootstrap = [teacher.sample(1)[0] for _ in range(30)]
    offsets = np.abs(KUKA_TASK_SPACE.to_unit(np.array([KUKA_TASK_SPACE.to_array(t) for t in bootstrap])) - easiest)
    # Half-normal offsets of scale 0.1 (those pushed out of the box are clipped onto its edge).
    assert offsets.mean() == pytest.approx(0.1 * np.sqrt(2 / np.pi) / 2, rel=0.3)
    assert offsets.max() < 0.5 and offsets.std(axis=0).min() > 0
    assert teacher.state()["task_origins"] == {"gmm": 0, "uniform": 0, "near-easiest": 30}

    job = None
    for task in bootstrap:
        job = teacher.learn(EpisodeResult(task, 0.0)) or job
    teacher.install(job.run())
    teacher.sample(1000)
    origins = teacher.state()["task_origins"]
    assert origins["near-easiest"] == 30, "after the first fit, the random share is uniform again"
    assert origins["uniform"] == pytest.approx(0.2 * 1000, abs=40)


def test_a_bootstrap_spread_needs_the_easiest_task() -> None:
    no_anchors = TaskSpace([Parameter("x", 0.0, 1.0)])
    with pytest.raises(ValueError, match="bootstrap_spread needs an easiest value"):
        alp_gmm(no_anchors, bootstrap_spread=0.1)


def test_a_target_task_ratio_sends_that_share_of_tasks_to_the_hardest_task_from_the_first_on() -> None:
    teacher = alp_gmm(KUKA_TASK_SPACE, fit_rate=30, max_components=3, target_task_ratio=0.3)
    hardest = KUKA_TASK_SPACE.hardest()
    bootstrap = teacher.sample(30)
    on_target = sum(task == hardest for task in bootstrap)
    assert 0 < on_target < 30
    assert teacher.state()["task_origins"] == {"gmm": 0, "uniform": 30 - on_target, "target": on_target}

    job = None
    for task in bootstrap:
        job = teacher.learn(EpisodeResult(task, float(task == hardest))) or job
    teacher.install(job.run())
    later = teacher.sample(2000)
    origins = teacher.state()["task_origins"]
    # A GMM draw clipped onto the box's corner can be the hardest task too, so count by origin.
    assert sum(task == hardest for task in later) >= origins["target"] - on_target
    assert origins["target"] - on_target == pytest.approx(0.3 * 2000, abs=70)
    assert origins["uniform"] - (30 - on_target) == pytest.approx(0.2 * 2000, abs=60)
    assert origins["gmm"] == pytest.approx(0.5 * 2000, abs=70)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"target_task_ratio": 0.9}, "cannot add up to more than 1"),
        ({"target_task_ratio": 1.5}, r"target_task_ratio\n  Input should be less than or equal to 1"),
    ],
)
def test_bad_target_shares_are_refused(params: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        alp_gmm(KUKA_TASK_SPACE, **params)


def test_a_target_share_needs_the_hardest_task() -> None:
    space = TaskSpace([Parameter("free", 0.0, 1.0)])
    with pytest.raises(ValueError, match="target_task_ratio needs a hardest value"):
        alp_gmm(space, target_task_ratio=0.2)


def test_refits_fall_due_every_fit_rate_results_and_a_failed_one_is_passed_over() -> None:
    teacher = alp_gmm(fit_rate=20, max_components=3)
    due_at, jobs = [], []
    rng = np.random.default_rng(0)
    for result in range(1, 71):
        job = teacher.learn(EpisodeResult(teacher.sample(1)[0], float(rng.random())))
        if job is not None:
            due_at.append(result)
            jobs.append(job)
    assert due_at == [20, 40, 60]
    assert [job.index for job in jobs] == [0, 1, 2]
    assert teacher.state()["next_fit_at_results"] == 80

    fits = [job.run() for job in jobs]
    teacher.install(fits[1])  # fit 0 failed: its successor still goes in
    with pytest.raises(ValueError, match="fit 0 is stale: fit 1 is installed"):
        teacher.install(fits[0])
    teacher.install(fits[2])
    assert teacher.state()["fits"] == 2 and teacher.state()["last_fit_index"] == 2


def test_each_fit_sees_the_last_fit_rate_points() -> None:
    teacher = alp_gmm(fit_rate=20, max_components=2)
    tasks = [{"wide": float(i), "narrow": -0.5} for i in range(40)]
    jobs = [teacher.learn(EpisodeResult(task, 0.0)) for task in tasks]
    points = jobs[-1].run.args[1]
    assert points.shape == (20, 3)
    assert points[:, 0] == pytest.approx(np.arange(20, 40) / 100)


def test_aic_picks_three_components_for_data_from_three_gaussians() -> None:
    rng = np.random.default_rng(7)
    centres = np.array([[0.15, 0.2, 0.05], [0.5, 0.8, 0.6], [0.85, 0.3, 0.3]])
    points = np.vstack([rng.normal(centre, 0.04, size=(100, 3)) for centre in centres])
    fit = fit_mixture(0, points, range(2, 11), nb_em_init=1, random_state=0)
    assert set(fit.aic_by_components) == set(range(2, 11))
    assert len(fit.weights) == 3 == min(fit.aic_by_components, key=fit.aic_by_components.__getitem__)
    found = fit.means[np.argsort(fit.means[:, 0])]
    assert found == pytest.approx(centres, abs=0.02)


def test_the_same_seed_and_history_give_the_same_fits() -> None:
    def fits(seed: int) -> list[MixtureFit]:
        teacher = alp_gmm(seed=seed, fit_rate=40, max_components=4)
        rng = np.random.default_rng(1)
        jobs = [teacher.learn(EpisodeResult(task, float(rng.random()))) for task in teacher.sample(80)]
        return [job.run() for job in jobs if job is not None]

    for fit, again in zip(fits(3), fits(3), strict=True):
        assert fit.index == again.index
        assert np.array_equal(fit.means, again.means) and np.array_equal(fit.covariances, again.covariances)


def test_alp_is_the_reward_change_from_the_nearest_earlier_task() -> None:
    teacher = alp_gmm(rescale_tasks=False)
    corners = [{"wide": w, "narrow": n} for w in (0.0, 100.0) for n in (-1.0, 0.0)]
    middle = [{"wide": 50.0, "narrow": -0.5}, {"wide": 50.0, "narrow": 0.0}]
    history = [(task, float(i)) for i, task in enumerate(corners + middle)]
    history += [({"wide": 99.0, "narrow": -0.9}, 10.0), ({"wide": 1.0, "narrow": 0.0}, 0.5)]
    feed(teacher, history)
    # Six earlier tasks are needed before ALP is measured; then the nearest corners had 2 and 1.
    assert teacher.recent_alps.tolist() == [0, 0, 0, 0, 0, 0, 8.0, 0.5]


def test_rescaling_makes_a_narrow_parameter_count() -> None:
    history = [({"wide": 0.0, "narrow": -0.5}, 1.0), ({"wide": 30.0, "narrow": 0.0}, 5.0)] * 3
    probe = ({"wide": 10.0, "narrow": 0.0}, 4.0)
    raw, rescaled = alp_gmm(rescale_tasks=False), alp_gmm(rescale_tasks=True)
    feed(raw, [*history, probe])
    feed(rescaled, [*history, probe])
    # Raw units: 10 away from the first task, 20 from the second. Unit box: 0.51 versus 0.2.
    assert raw.recent_alps[-1] == 3.0
    assert rescaled.recent_alps[-1] == 1.0


def test_rewards_are_normalised_by_the_configured_range() -> None:
    history = [({"wide": 0.0, "narrow": -0.5}, 0.0)] * 6
    history += [({"wide": 50.0, "narrow": -0.5}, 2.0), ({"wide": 51.0, "narrow": -0.5}, 40.0)]
    raw, normalised = alp_gmm(), alp_gmm(reward_range=[-10.0, 10.0])
    feed(raw, history)
    feed(normalised, history)
    assert raw.recent_alps[-2:].tolist() == [2.0, 38.0]
    # 0 -> 0.5 and 2 -> 0.6; 40 is clipped to the top of the range, 1.0.
    assert normalised.recent_alps[-2:] == pytest.approx([0.1, 0.4])


def test_the_nearest_neighbour_buffer_changes_speed_not_answers() -> None:
    rng = np.random.default_rng(5)
    history = [({"wide": 100 * a, "narrow": -b}, float(r)) for a, b, r in rng.random((300, 3))]
    small_buffer, large_buffer = alp_gmm(buffer_size=7, fit_rate=1000), alp_gmm(fit_rate=1000)
    feed(small_buffer, history)
    feed(large_buffer, history)
    assert np.array_equal(small_buffer.recent_alps, large_buffer.recent_alps)
    assert small_buffer.recent_alps.max() > 0


def test_tasks_come_from_components_in_proportion_to_their_alp() -> None:
    teacher = alp_gmm(random_task_ratio=0.0)
    teacher.install(two_component_fit(alps=(0.3, 0.1), means=[[0.2, 0.8], [0.7, 0.3]], variance=1e-4))
    tasks = np.array([[t["wide"], t["narrow"]] for t in teacher.sample(4000)])
    near_first = np.linalg.norm(tasks - [20.0, -0.2], axis=1) < 5
    near_second = np.linalg.norm(tasks - [70.0, -0.7], axis=1) < 5
    assert near_first.mean() == pytest.approx(0.75, abs=0.03)
    assert near_second.mean() == pytest.approx(0.25, abs=0.03)
    assert teacher.state()["task_origins"] == {"gmm": 4000, "uniform": 0}


def test_state_reports_components_in_task_units() -> None:
    teacher = alp_gmm()
    teacher.install(two_component_fit(alps=(0.0, 0.0), means=[[0.2, 0.8], [0.7, 0.3]], variance=0.01))
    first, second = teacher.state()["components"]
    assert first["mean"] == pytest.approx({"wide": 20.0, "narrow": -0.2})
    assert np.array(first["covariance"]) == pytest.approx(np.diag([100.0, 0.01]))
    assert first["weight"] == 0.5 and first["mean_alp"] == 0.0
    assert first["sampling_probability"] == second["sampling_probability"] == 0.5, "no progress: pick evenly"


def test_gmm_tasks_go_where_reward_changes() -> None:
    """Reward rises over time only in one corner; after a few fits most GMM tasks go there."""
    teacher = alp_gmm(KUKA_TASK_SPACE, seed=2, fit_rate=100, reward_range=[0.0, 1.0])
    practice = 0
    for _ in range(600):
        task = teacher.sample(1)[0]
        in_corner = task["rnd_obj_x"] < 0.3 and task["jp2"] > 1.0
        practice += in_corner
        teacher.learn_and_fit(EpisodeResult(task, min(practice / 100, 1.0) if in_corner else 0.0))
    teacher.sample(1000)
    components = teacher.state()["components"]
    best = max(components, key=lambda component: component["mean_alp"])
    assert best["mean"]["rnd_obj_x"] < 0.3 and best["mean"]["jp2"] > 1.0
    assert best["sampling_probability"] > 0.5


def test_a_stored_fit_installs_bit_for_bit() -> None:
    teacher = alp_gmm(fit_rate=30, max_components=3)
    rng = np.random.default_rng(2)
    jobs = [teacher.learn(EpisodeResult(teacher.sample(1)[0], float(rng.random()))) for _ in range(30)]
    fitted = jobs[-1].run()
    restored = teacher.import_fit(json.loads(json.dumps(teacher.export_fit(fitted))))
    for name in ("weights", "means", "covariances"):
        assert getattr(restored, name).tobytes() == getattr(fitted, name).tobytes()
    assert (restored.index, restored.aic_by_components) == (fitted.index, fitted.aic_by_components)
    with pytest.raises(ValueError, match="needs means of shape"):
        teacher.import_fit({**teacher.export_fit(fitted), "means": [[0.0, 1.0]]})


def test_a_fit_lost_before_it_was_installed_is_rebuilt_from_the_history() -> None:
    teacher = alp_gmm(fit_rate=25, max_components=3)
    rng = np.random.default_rng(4)
    due = [job for _ in range(60) if (job := teacher.learn(EpisodeResult(teacher.sample(1)[0], float(rng.random()))))]
    assert [job.index for job in due] == [0, 1]
    for job in due:
        again = teacher.refit_job(job.index)
        assert again.run.args[1].tobytes() == job.run.args[1].tobytes()
        assert again.run.args[2:] == job.run.args[2:]
    with pytest.raises(ValueError, match="fit 2 has not fallen due"):
        teacher.refit_job(2)


def repeated_hardest_task_run(teacher: AlpGmmTeacher, results: int, adopt: bool) -> list[float]:
    """Half the tasks are the same hardest task, so nearest-neighbour ties are everywhere. With
    ``adopt`` every tree build is run as soon as it is handed out and given back, as a service does."""
    rewards = np.random.default_rng(8).random(results)
    alps = []
    for reward in rewards:
        teacher.learn_and_fit(EpisodeResult(teacher.sample(1)[0], float(reward)))
        alps.append(float(teacher.recent_alps[-1]))
        if adopt and (job := teacher.build_job()) is not None:
            teacher.adopt_build(job, job.run())
    return alps


def test_tree_switches_happen_at_fixed_counts_whoever_builds_the_tree(monkeypatch: pytest.MonkeyPatch) -> None:
    params = {"fit_rate": 50, "max_components": 3, "buffer_size": 8, "target_task_ratio": 0.5}
    built: list[int] = []

    build = learning_progress.build_tree

    def counting_build(rows: np.ndarray) -> Any:
        built.append(len(rows))
        return build(rows)

    monkeypatch.setattr(learning_progress, "build_tree", counting_build)
    in_background = alp_gmm(KUKA_TASK_SPACE, 5, **params)
    handed_out = repeated_hardest_task_run(in_background, 300, adopt=True)
    background_builds, built[:] = list(built), []
    inline = alp_gmm(KUKA_TASK_SPACE, 5, **params)
    assert repeated_hardest_task_run(inline, 300, adopt=False) == handed_out
    assert built == background_builds[:-1], "without the outputs, the teacher builds each tree itself when due"
    assert background_builds == list(range(8, 300, 8)), "one tree per checkpoint, over every row so far"
    assert in_background.sample(20) == inline.sample(20)

    late = alp_gmm(KUKA_TASK_SPACE, 5, **params)
    repeated_hardest_task_run(late, 20, adopt=False)
    job = late.build_job()
    assert job is not None and job.needed_at == 24 and late.build_job() is None
    repeated_hardest_task_run(late, 10, adopt=False)  # passes 24: built inline, and a new job is pending
    late.adopt_build(job, build(np.zeros((1, len(KUKA_TASK_SPACE) + 3))))  # too late: dropped
    fresh = alp_gmm(KUKA_TASK_SPACE, 5, **params)
    repeated_hardest_task_run(fresh, 20, adopt=False)
    repeated_hardest_task_run(fresh, 10, adopt=False)
    assert late.recent_alps.tolist() == fresh.recent_alps.tolist()
    assert repeated_hardest_task_run(late, 40, adopt=False) == repeated_hardest_task_run(fresh, 40, adopt=False)


def test_the_tree_is_rebuilt_less_often_as_the_history_grows() -> None:
    teacher = alp_gmm(KUKA_TASK_SPACE, 0, fit_rate=2000, buffer_size=100)
    rows = np.random.default_rng(1).random((60_000, len(KUKA_TASK_SPACE) + 3))
    rows[:, -1] = 0.0  # no repeats
    snapshot = teacher.snapshot()
    snapshot["state"]["history_rows"] = snapshot["results_seen"] = len(rows)
    teacher.restore(snapshot, rows)
    job = teacher.build_job()
    assert job is not None
    assert job.needed_at - 60_000 <= max(100, 60_000 // TREE_GROWTH)
    assert job.run().tree.n < 60_000


def test_a_repeated_task_sits_in_the_tree_once_and_is_compared_with_its_first_result() -> None:
    teacher = alp_gmm(fit_rate=1000, buffer_size=8)
    same = {"wide": 50.0, "narrow": -0.5}
    rng = np.random.default_rng(3)
    history = [
        (same if i % 2 else {"wide": 100 * a, "narrow": -b}, float(i)) for i, (a, b) in enumerate(rng.random((80, 2)))
    ]
    feed(teacher, history)
    job = teacher.build_job()
    assert job is not None
    tree = job.run()
    assert tree.tree.n == 41, "40 distinct tasks and the repeated one once"
    assert teacher.history(0)[:, -1].sum() == 39
    teacher.learn_and_fit(EpisodeResult(same, 100.0))
    assert teacher.recent_alps[-1] == 100.0 - 1.0, "the repeated task's first result had reward 1"
