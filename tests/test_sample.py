"""The bundled demo take is the project's own, reproducible output."""

from __future__ import annotations

from conftest import ROOT
from mocap_autolabel.core.formats.c3d import read_c3d, write_c3d
from mocap_autolabel.core.synth.sample import sample_take
from mocap_autolabel.core.tracklets import find_tracklets


def test_bundled_sample_regenerates_byte_for_byte(tmp_path):
    out = tmp_path / "demo_take.c3d"
    write_c3d(sample_take(), out)
    assert out.read_bytes() == (ROOT / "samples" / "demo_take.c3d").read_bytes()


def test_sample_is_a_raw_fragmented_take():
    take = read_c3d(ROOT / "samples" / "demo_take.c3d")
    assert all(n.startswith("*") for n in take.names)
    tracklets = find_tracklets(take)
    assert len(tracklets) == take.n_points  # one run per slot: a new slot after every gap
    assert take.n_points > 20  # 19 markers + a ghost, fragmented at their gaps
