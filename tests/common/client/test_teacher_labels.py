"""Every report names teacher kinds from the client's one registry of labels."""

from __future__ import annotations

from common.client.schemas import TEACHER_LABELS
from teacher_service.teachers import TEACHER_KINDS


def test_every_kind_the_service_ships_has_one_label_in_its_order_and_no_other_kind_does():
    assert list(TEACHER_LABELS) == list(TEACHER_KINDS), "train and bakeoff offer the kinds in this order"
    assert len(set(TEACHER_LABELS.values())) == len(TEACHER_LABELS), "two kinds would read alike in a table"
