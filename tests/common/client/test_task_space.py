import math

import numpy as np
import pytest

from common.client.task_space import Parameter, TaskSpace
from common.kuka.task_space import KUKA_TASK_SPACE


def test_kuka_space_has_the_books_six_parameters_with_their_anchors():
    assert KUKA_TASK_SPACE.names == ("rnd_obj_x", "rnd_obj_y", "rnd_obj_ang", "jp2", "jp4", "bias_obj_y")
    assert KUKA_TASK_SPACE.hardest() == {
        "rnd_obj_x": 1.0,
        "rnd_obj_y": 1.0,
        "rnd_obj_ang": 1.0,
        "jp2": 0.413184,
        "jp4": -1.589317,
        "bias_obj_y": 0.0,
    }
    assert KUKA_TASK_SPACE.easiest() == {
        "rnd_obj_x": 0.0,
        "rnd_obj_y": 0.0,
        "rnd_obj_ang": 0.0,
        "jp2": 1.3,
        "jp4": -1.0,
        "bias_obj_y": 0.04,
    }
    assert all(p.doc for p in KUKA_TASK_SPACE.parameters)


def test_validate_returns_a_clean_float_copy():
    task = dict(KUKA_TASK_SPACE.easiest(), rnd_obj_x=1)
    clean = KUKA_TASK_SPACE.validate(task)
    assert clean == task and clean is not task
    assert isinstance(clean["rnd_obj_x"], float)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"speed": 1.0}, "unknown task parameter.*speed"),
        ({"jp2": 2.0}, "'jp2'=2.0 is outside its bounds"),
        ({"jp4": math.nan}, "'jp4' must be finite"),
        ({"bias_obj_y": math.inf}, "'bias_obj_y' must be finite"),
        ({"rnd_obj_y": "far"}, "'rnd_obj_y' must be a number"),
    ],
)
def test_validate_names_the_bad_parameter(change, message):
    with pytest.raises(ValueError, match=message):
        KUKA_TASK_SPACE.validate(dict(KUKA_TASK_SPACE.hardest(), **change))


def test_validate_reports_missing_parameters():
    task = KUKA_TASK_SPACE.hardest()
    del task["rnd_obj_ang"]
    with pytest.raises(ValueError, match="missing task parameter.*rnd_obj_ang"):
        KUKA_TASK_SPACE.validate(task)


def test_array_round_trip_clips_into_the_box_and_unit_scaling_inverts():
    space = TaskSpace([Parameter("a", 0.0, 2.0), Parameter("b", -1.0, 1.0)])
    assert space.from_array(np.array([3.0, -5.0])) == {"a": 2.0, "b": -1.0}
    points = np.array([[0.0, -1.0], [2.0, 1.0], [1.0, 0.0]])
    np.testing.assert_allclose(space.to_unit(points), [[0, 0], [1, 1], [0.5, 0.5]])
    np.testing.assert_allclose(space.from_unit(space.to_unit(points)), points)


def test_bad_space_definitions_are_rejected():
    with pytest.raises(ValueError, match="duplicate"):
        TaskSpace([Parameter("a", 0, 1), Parameter("a", 0, 1)])
    with pytest.raises(ValueError, match="low <= high"):
        Parameter("a", 1.0, 0.0)
    with pytest.raises(ValueError, match="hardest=2"):
        Parameter("a", 0.0, 1.0, hardest=2.0)
    with pytest.raises(ValueError, match="no easiest value"):
        TaskSpace([Parameter("a", 0.0, 1.0)]).easiest()
