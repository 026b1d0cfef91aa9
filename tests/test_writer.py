"""The C3D writer round-trips through ezc3d, the c3d package and our reader."""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest
from helpers import small_take
from mocap_autolabel.core.formats.c3d import read_c3d, write_c3d


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
