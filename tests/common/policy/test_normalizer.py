import numpy as np
import pytest

from common.policy.normalizer import RunningNormalizer


def test_statistics_folded_batch_by_batch_equal_those_of_all_the_data():
    rng = np.random.default_rng(0)
    batches = [rng.normal(loc=[5.0, -300.0], scale=[0.1, 40.0], size=(size, 2)) for size in (1, 7, 250, 33)]
    normalizer = RunningNormalizer(2)
    for batch in batches:
        normalizer.update(batch)
    everything = np.concatenate(batches)
    assert normalizer.mean == pytest.approx(everything.mean(axis=0))
    assert normalizer.var == pytest.approx(everything.var(axis=0))
    assert normalizer.count == len(everything)
    scaled = normalizer.normalize(everything)
    assert scaled.dtype == np.float32
    assert scaled.mean(axis=0) == pytest.approx([0.0, 0.0], abs=1e-4)
    assert scaled.std(axis=0) == pytest.approx([1.0, 1.0], abs=1e-3)


def test_outliers_are_clipped_and_state_round_trips():
    normalizer = RunningNormalizer(1, clip=3.0)
    normalizer.update(np.array([[0.0], [2.0]]))
    assert normalizer.normalize(np.array([[1000.0], [-1000.0]])).ravel().tolist() == [3.0, -3.0]
    copy = RunningNormalizer(1, clip=3.0)
    copy.load_state(normalizer.state())
    assert copy.normalize(np.array([[1.5]])) == normalizer.normalize(np.array([[1.5]]))
    with pytest.raises(ValueError, match="size"):
        RunningNormalizer(2).load_state(normalizer.state())
