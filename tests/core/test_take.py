import numpy as np
import pytest
from helpers import small_take
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.take import Take, mark_missing, unit_scale
from mocap_autolabel.core.tracklets import find_tracklets


def test_mark_missing_recognises_all_three_conventions():
    pos = np.ones((3, 4, 3), dtype=np.float32)
    pos[0, 0] = np.nan                       # NaN
    pos[1, 1] = 0.0                          # exact (0, 0, 0)
    pos[2, 2] = (0.0, 0.0, 1.0)              # a zero coordinate alone is a real position
    residuals = np.zeros((3, 4), dtype=np.float32)
    residuals[2, 3] = -1.0                   # negative residual
    missing = mark_missing(pos, residuals)
    expected = np.zeros((3, 4), bool)
    expected[0, 0] = expected[1, 1] = expected[2, 3] = True
    np.testing.assert_array_equal(missing, expected)
    assert np.isnan(pos[expected]).all() and not np.isnan(pos[~expected]).any()
    assert np.isnan(residuals[expected]).all()


def test_take_validates_shapes_and_rate():
    with pytest.raises(ValueError):
        Take(np.zeros((2, 3, 2), np.float32), ["a", "b", "c"], 100.0)
    with pytest.raises(ValueError):
        Take(np.zeros((2, 3, 3), np.float32), ["a"], 100.0)
    with pytest.raises(ValueError):
        Take(np.zeros((2, 1, 3), np.float32), ["a"], 0.0)


def test_summary_counts_labeled_and_missing():
    take = small_take(frames=50, points=4)
    take.names[2] = "ThumbTip"
    s = take.summary()
    assert (s["labeled_points"], s["unlabeled_points"]) == (1, 3)
    assert s["missing_percent"] == pytest.approx(100 * (4 + 1 + 3) / 200)


def test_unit_scale():
    assert unit_scale("mm") == 1e-3 and unit_scale(" M ") == 1.0 and unit_scale("millimeters") == 1e-3
    with pytest.raises(MocapInputError, match="furlong"):
        unit_scale("furlong", "x.trc")


def test_tracklets_split_at_gaps_with_stable_ids():
    take = small_take(frames=50, points=4)
    tr = find_tracklets(take)
    assert list(zip(tr.slot, tr.start, tr.stop)) == [
        (0, 0, 5), (0, 9, 50), (1, 0, 20), (1, 21, 50), (2, 0, 50), (3, 0, 47)]
    ids = tr.id_map(take.n_frames, take.n_points)
    assert (ids >= 0).sum() == take.valid.sum() == tr.length.sum()
    np.testing.assert_array_equal(ids >= 0, take.valid)
    assert ids[10, 0] == 1 and ids[21, 1] == 3 and ids[46, 3] == 5 and ids[47, 3] == -1
    again = find_tracklets(small_take(frames=50, points=4))
    assert all((a == b).all() for a, b in zip((tr.slot, tr.start, tr.stop), (again.slot, again.start, again.stop)))


def test_tracklets_split_at_impossible_jump():
    take = small_take(frames=30, points=2, gaps=False)
    take.positions[12:, 1] += 0.5   # 0.5 m in one frame at 100 Hz = 50 m/s
    assert len(find_tracklets(take)) == 2
    tr = find_tracklets(take, max_speed=10.0)
    assert list(zip(tr.slot, tr.start, tr.stop)) == [(0, 0, 30), (1, 0, 12), (1, 12, 30)]
    np.testing.assert_array_equal(np.unique(tr.id_map(30, 2)[:, 1]), [1, 2])


def test_mask_runs_finds_every_run_in_column_order():
    from mocap_autolabel.core.tracklets import mask_runs

    mask = np.array([[1, 0], [1, 1], [0, 1], [1, 0]], dtype=bool)
    column, start, stop = mask_runs(mask)
    assert list(zip(column, start, stop)) == [(0, 0, 2), (0, 3, 4), (1, 1, 3)]
    assert all(len(a) == 0 for a in mask_runs(np.zeros((3, 2), dtype=bool)))
