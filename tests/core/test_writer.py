"""The C3D writer round-trips through ezc3d, the c3d package and our reader."""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest
from helpers import small_take
from mocap_autolabel.core.formats.c3d import read_c3d, write_c3d
from mocap_autolabel.core.take import Take


@pytest.fixture
def written(tmp_path):
    take = small_take(frames=300, points=8, seed=3)
    take.names = [f"*{i}" for i in range(6)] + ["ThumbTip", "IndexTip"]
    take.first_frame = 10
    path = tmp_path / "labeled.c3d"
    write_c3d(take, path)
    return take, path


def test_roundtrip_our_reader(written):
    take, path = written
    back = read_c3d(path)
    assert back.names == take.names and back.rate == take.rate and back.first_frame == 10
    np.testing.assert_array_equal(np.isnan(back.positions), np.isnan(take.positions))
    assert np.nanmax(np.abs(back.positions - take.positions)) < 1e-5  # 0.01 mm


def test_roundtrip_ezc3d(written):
    ezc3d = pytest.importorskip("ezc3d")
    take, path = written
    c = ezc3d.c3d(str(path))
    pts = c["data"]["points"][:3].transpose(2, 1, 0) / 1000.0
    residual = c["data"]["meta_points"]["residuals"][0].T
    missing = np.isnan(take.positions[..., 0])
    assert (residual[missing] < 0).all() and (residual[~missing] >= 0).all()
    assert np.abs(pts[~missing] - take.positions[~missing]).max() < 1e-5
    assert list(c["parameters"]["POINT"]["LABELS"]["value"]) == take.names


def test_roundtrip_c3d_package(written):
    c3d = pytest.importorskip("c3d")
    take, path = written
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = c3d.Reader(io.BytesIO(path.read_bytes()))
        frames = [points.copy() for _, points, _ in reader.read_frames()]
    data = np.stack(frames)  # (frames, points, 5): x y z residual cameras
    missing = np.isnan(take.positions[..., 0])
    assert (data[..., 3][missing] < 0).all() and (data[..., 3][~missing] >= 0).all()
    assert np.abs(data[..., :3][~missing] / 1000.0 - take.positions[~missing]).max() < 1e-5
    assert [n.strip() for n in reader.point_labels] == take.names


def test_a_take_longer_than_16_bit_counts_keeps_every_frame(tmp_path):
    """65,535 frames is all the header and POINT:FRAMES hold (9 minutes at 120 Hz): a longer take
    states its length in TRIAL:ACTUAL_START/END_FIELD and POINT:LONG_FRAMES, and a file that states
    only the capped count is read to the end of its data (with a warning), not cut at 65,535."""
    import ezc3d

    n = 70_001
    x = np.random.default_rng(3).normal(0, 0.1, (n, 2, 3)).astype(np.float32)
    x[-1, 1] = np.nan
    write_c3d(Take(x, ["a", "b"], 120.0, first_frame=7), tmp_path / "long.c3d")
    back = read_c3d(tmp_path / "long.c3d")
    assert (back.n_frames, back.first_frame, back.warnings) == (n, 7, [])
    np.testing.assert_allclose(back.positions, x, atol=1e-7)
    c = ezc3d.c3d()  # ezc3d alone states 65535 frames for the same data
    c["parameters"]["POINT"]["RATE"]["value"] = [120.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ["a", "b"]
    pts = np.ones((4, 2, n))
    pts[:3] = np.transpose(x * 1000, (2, 1, 0))
    c["data"]["points"] = pts
    c.write(str(tmp_path / "capped.c3d"))
    capped = read_c3d(tmp_path / "capped.c3d")
    assert capped.n_frames == n and "the most its 16-bit counts hold" in " ".join(capped.warnings)
