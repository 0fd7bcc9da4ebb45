"""The generic state codecs: a kind that keeps numpy arrays (per level, say) declares each in one
line and gets it back with its dtype and shape, through JSON as a snapshot travels."""

from __future__ import annotations

import json

import numpy as np
import pytest

from teacher_service.teachers.state import ARRAY, FloatArray, StateField, export_fields, import_fields


class Levels:
    """What a level teacher might hold: a score, a flag and a counter per level."""

    state_fields = (
        StateField("scores", ARRAY),
        StateField("solved", ARRAY),
        StateField("visits", ARRAY, "_visits"),
    )

    def __init__(self, levels: int) -> None:
        self.scores = np.zeros(levels)
        self.solved = np.zeros(levels, dtype=bool)
        self._visits = np.zeros(levels, dtype=np.int64)


def test_arrays_of_any_dtype_come_back_as_they_were() -> None:
    taught = Levels(4)
    taught.scores[:] = [0.25, np.pi, -1.5, 1e-300]
    taught.solved[[1, 3]] = True
    taught._visits[:] = [0, 2**40, 7, 1]
    stored = json.loads(json.dumps(export_fields(taught, Levels.state_fields)))

    restored = Levels(4)
    import_fields(restored, Levels.state_fields, stored)
    for name in ("scores", "solved", "_visits"):
        before, after = getattr(taught, name), getattr(restored, name)
        assert after.dtype == before.dtype and np.array_equal(after, before), name


def test_a_snapshot_of_another_number_of_levels_is_refused_naming_the_field() -> None:
    stored = export_fields(Levels(3), Levels.state_fields)
    with pytest.raises(ValueError, match=r"state field 'scores'.*\(4,\).*\(3,\)"):
        import_fields(Levels(4), Levels.state_fields, stored)


def test_float_arrays_keep_what_they_wrote() -> None:
    """``FloatArray`` (the box teachers') still reads rows of any count and names its array."""
    rows = FloatArray("the buffer", rows=True)
    assert rows.load([[1, 2], [3, 4], [5, 6]], np.zeros((0, 2))).shape == (3, 2)
    with pytest.raises(ValueError, match="low must have shape"):
        FloatArray("low").load([1.0], np.zeros(2))
