"""Integer parameters beside float ones: levels (Discrete) and layouts (MultiDiscrete) in one task space."""

import numpy as np
import pytest

from common.client.schemas import ParameterSpec
from common.client.task_space import Parameter, TaskSpace

LEVELS = TaskSpace([Parameter("level", 0, 199, type="integer")])
LAYOUT = TaskSpace([Parameter("rooms", 2, 4, type="integer"), Parameter("size", 5, 6, type="integer")])
MIXED = TaskSpace([Parameter("level", 0, 9, type="integer"), Parameter("friction", 0.5, 1.5)])


def test_a_float_parameter_stays_the_default_and_keeps_its_floats():
    assert Parameter("x", 0, 1).type == "float"
    assert TaskSpace([Parameter("x", 0, 1)]).validate({"x": 1}) == {"x": 1.0}
    assert isinstance(TaskSpace([Parameter("x", 0, 1)]).validate({"x": 1})["x"], float)


def test_integer_bounds_and_anchors_are_kept_as_ints():
    parameter = Parameter("level", 0.0, 199.0, hardest=199.0, type="integer")
    assert (parameter.low, parameter.high, parameter.hardest) == (0, 199, 199)
    assert all(isinstance(value, int) for value in (parameter.low, parameter.high, parameter.hardest))
    assert parameter.levels == 200


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"low": 0.5, "high": 3, "type": "integer"}, "'level' is an integer parameter: low=0.5 is not whole"),
        ({"low": 0, "high": 3, "hardest": 1.5, "type": "integer"}, "hardest=1.5 is not whole"),
        ({"low": 0, "high": 3, "type": "integr"}, "'level': type must be one of"),
    ],
)
def test_a_bad_integer_parameter_is_refused_with_its_name(arguments, message):
    with pytest.raises(ValueError, match=message):
        Parameter("level", **arguments)


def test_validate_takes_ints_and_refuses_floats_bools_and_out_of_bounds():
    assert LEVELS.validate({"level": 7}) == {"level": 7}
    assert isinstance(LEVELS.validate({"level": np.int64(7)})["level"], int)
    for value in (7.0, 7.5, True, "7"):
        with pytest.raises(ValueError, match="'level' is an integer parameter"):
            LEVELS.validate({"level": value})
    with pytest.raises(ValueError, match=r"'level'=200 is outside its bounds \[0, 199\]"):
        LEVELS.validate({"level": 200})


def test_a_mixed_space_validates_each_parameter_by_its_type():
    assert MIXED.validate({"level": 3, "friction": 1}) == {"level": 3, "friction": 1.0}
    assert MIXED.types == {"integer", "float"}
    assert LEVELS.types == {"integer"}


def test_from_array_rounds_integer_parameters_and_clips_both_kinds():
    task = MIXED.from_array(np.array([3.6, 2.0]))
    assert task == {"level": 4, "friction": 1.5}
    assert isinstance(task["level"], int) and isinstance(task["friction"], float)
    assert MIXED.from_array(np.array([-4.0, 0.7]))["level"] == 0


def test_levels_number_every_task_of_a_multidiscrete_space_once():
    assert LAYOUT.level_count() == 6
    tasks = [LAYOUT.level_task(level) for level in range(LAYOUT.level_count())]
    assert tasks[0] == {"rooms": 2, "size": 5} and tasks[1] == {"rooms": 2, "size": 6}
    assert tasks[-1] == {"rooms": 4, "size": 6}
    assert len({tuple(task.values()) for task in tasks}) == 6
    assert [LAYOUT.task_level(task) for task in tasks] == list(range(6))
    with pytest.raises(ValueError, match="level 6 is outside"):
        LAYOUT.level_task(6)


def test_a_float_parameter_has_no_level_count():
    with pytest.raises(ValueError, match="'friction' is a float parameter"):
        MIXED.level_count()


def test_a_registration_echoes_an_integer_parameters_bounds_as_the_ints_it_was_sent():
    level = ParameterSpec(name="level", low=0, high=199, hardest=7, type="integer").model_dump(mode="json")
    assert (level["low"], level["high"], level["hardest"]) == (0, 199, 7)
    assert all(type(level[key]) is int for key in ("low", "high", "hardest"))
    share = ParameterSpec(name="share", low=0, high=1).model_dump(mode="json")
    assert (share["low"], share["high"]) == (0.0, 1.0) and type(share["high"]) is float
