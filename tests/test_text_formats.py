"""TRC (Han et al.) and Qualisys TSV readers on the real hand recordings."""

from __future__ import annotations

import numpy as np
from conftest import data_path
from mocap_autolabel.core.take import read_take

HAN19 = ["ThumbCMC", "ThumbMCP", "ThumbIP", "ThumbTip", "IndexMCP", "IndexPIP", "IndexTip", "MiddleMCP",
         "MiddlePIP", "MiddleTip", "RingMCP", "RingPIP", "RingTip", "PinkyMCP", "PinkyPIP", "PinkyTip",
         "BackHand1", "BackHand2", "BackHand3"]


def test_trc_han2018():
    folder = data_path("hands", "han2018_dense19")
    files = sorted(folder.rglob("*.trc"))
    assert len(files) > 100
    for path in files[:20]:
        take = read_take(path)
        assert take.names == HAN19 and take.rate == 120.0 and take.source_units == "mm"
        assert take.missing_fraction == 0.0
        # Hand markers sit within 30 cm of each other: metres, not millimetres.
        spread = np.nanmax(take.positions, axis=1) - np.nanmin(take.positions, axis=1)
        assert 0.03 < spread.max() < 0.3
    first = files[0].read_text().splitlines()[5].split("\t")
    take = read_take(files[0])
    np.testing.assert_allclose(take.positions[0, 0], np.array(first[2:5], float) / 1000.0, rtol=1e-6)


def test_qualisys_tsv_glove13():
    take = read_take(data_path("hands", "qualisys_glove13", "recording_part1.tsv"))
    assert take.n_frames == 3000 and take.n_points == 21 and take.rate == 100.0
    assert take.names[:3] == ["hand_top", "hand_left", "hand_right"] and "pillow_right" in take.names
    thumb = take.names.index("thumb_tip")
    assert 0.02 < 1 - take.valid[:, thumb].mean() < 0.15  # real occlusions of the thumb tip
    np.testing.assert_allclose(take.positions[0, 0], [0.110406, 0.135075, 0.460584], rtol=1e-6)
