"""Long takes labeled in overlapping windows (core/windows.py): bounds, joining, names, constraints."""

from __future__ import annotations

import numpy as np
import pytest
from mocap_autolabel.core.labeling import EMPTY, NULL, Constraint
from mocap_autolabel.core.pipeline import label_take
from mocap_autolabel.core.settings import Corrections, LabelSettings
from mocap_autolabel.core.synth.generate import synthesize
from mocap_autolabel.core.synth.two_hands import TwoHandConfig, two_hand_take
from mocap_autolabel.core.take import Take
from mocap_autolabel.core.windows import window_bounds


@pytest.fixture(scope="module")
def one_hand(han19):
    return synthesize(han19, 1500, seed=4)


@pytest.mark.parametrize("frames,window,overlap", [(100, 100, 10), (101, 100, 10), (1000, 300, 50),
                                                    (216_000, 30_000, 1_200), (30_001, 30_000, 1_200)])
def test_window_bounds_cover_the_take_with_overlaps(frames, window, overlap):
    bounds = window_bounds(frames, window, overlap)
    assert bounds[0][0] == 0 and bounds[-1][1] == frames
    for (a, b), (c, d) in zip(bounds[:-1], bounds[1:]):
        assert b - c >= min(overlap, window // 4) and c > a and d > b  # each overlaps the next, and moves on
    assert all(b - a <= window for a, b in bounds)
    if frames <= window:
        assert bounds == [(0, frames)]


def _check_segments(lab, take):
    """Segments of a slot never overlap, and every valid sample lies in one."""
    order = np.lexsort((lab.start, lab.slot))
    assert (order == np.arange(len(lab))).all()
    same = lab.slot[1:] == lab.slot[:-1]
    assert (lab.start[1:][same] >= lab.stop[:-1][same]).all()
    per = lab.per_sample()
    assert ((per != EMPTY) == take.valid).all()


def test_windows_label_a_one_hand_take_as_the_whole_does(han19, one_hand):
    whole = label_take(one_hand.take, han19, LabelSettings(window=None))
    windows = label_take(one_hand.take, han19, LabelSettings(window=500))
    assert len(windows.info["windows"]) >= 3
    assert windows.names == whole.names == list(han19.names)
    _check_segments(windows, one_hand.take)
    a, b = whole.per_sample(), windows.per_sample()
    assert (a != b).mean() < 0.002
    # Stage seconds are summed over the windows, and windows report where they were cut.
    assert windows.info["seconds"]["scores"] > 0 and windows.info["frames"] == 1500
    assert all(w["hands"] == 1 for w in windows.info["windows"])


def test_a_constraint_across_a_cut_holds_in_every_window(han19, one_hand):
    take = one_hand.take
    first = label_take(take, han19, LabelSettings(window=500))
    cut = first.info["windows"][1]["cut"]
    # The longest trajectory through the first cut, locked to a label it did not get.
    through = np.flatnonzero((first.start < cut) & (first.stop > cut))
    seg = through[np.argmax(first.stop[through] - first.start[through])]
    wrong = (int(first.label[seg]) + 1) % len(han19) if first.label[seg] >= 0 else 0
    c = Constraint(int(first.slot[seg]), int(first.start[seg]), int(first.stop[seg]), wrong)
    lab = label_take(take, han19, LabelSettings(window=500), corrections=Corrections(constraints=[c]))
    per = lab.per_sample()[c.start:c.stop, c.slot]
    assert (per[per != EMPTY] == wrong).all()
    assert lab.locked[(lab.slot == c.slot) & (lab.start < c.stop) & (lab.stop > c.start)].all()


def test_two_hands_in_windows_are_named_by_side_throughout(han19):
    two = two_hand_take(han19, 1500, seed=3, config=TwoHandConfig(close_share=0.0))
    # The left hand is hidden in the first window: that window holds one hand, the others two.
    positions = two.take.positions.copy()
    left = (two.labels >= 0) & (two.labels < len(han19))
    positions[:600][left[:600]] = np.nan
    take = Take(positions, list(two.take.names), two.take.rate)
    truth = np.where(np.isnan(positions[..., 0]), -2, two.labels)
    lab = label_take(take, han19, LabelSettings(window=600))
    assert [w["hands"] for w in lab.info["windows"]][0] == 1 and lab.info["hands"]["count"] == 2
    assert lab.info["hands"]["sides"] == ["left", "right"] and lab.info["hands"]["naming"]
    assert lab.names[0] == "L_ThumbCMC" and lab.names[len(han19)] == "R_ThumbCMC"
    _check_segments(lab, take)
    per = lab.per_sample()
    real = truth >= 0
    assert (per[real] == truth[real]).mean() > 0.99
    # The right hand of the first window carries its side's labels; no label twice in a frame.
    assert (per[:600][truth[:600] >= len(han19)] >= len(han19)).mean() > 0.99
    f, p = np.nonzero(per >= 0)
    assert len(np.unique(f * 100 + per[f, p])) == len(f)
    assert NULL not in lab.label[lab.label >= 0]


def test_a_two_hand_re_solve_keeps_each_windows_sides(han19):
    """A reviewer's re-solve hands each window its own hands' sides back (relabel_options)."""
    from mocap_autolabel.core.hands import relabel_options

    two = two_hand_take(han19, 1500, seed=5, config=TwoHandConfig(close_share=0.0))
    lab = label_take(two.take, han19, LabelSettings(window=600))
    options = relabel_options(lab.info)
    assert options["hand_count"] == 2 and len(options["sides"]) == len(lab.info["windows"])
    seg = int(np.argmax(lab.length * (lab.label >= 0)))
    c = Constraint(int(lab.slot[seg]), int(lab.start[seg]), int(lab.stop[seg]), int(lab.label[seg]))
    settings = LabelSettings(window=600, hand_count=options["hand_count"], sides=options["sides"],
                             naming=options.get("naming"))
    again = label_take(two.take, han19, settings,
                       corrections=Corrections(constraints=[c], hand_swaps=options["hand_swaps"]))
    assert again.names == lab.names
    a, b = lab.per_sample(), again.per_sample()
    assert (a != b).mean() < 0.002
    assert again.locked[(again.slot == c.slot) & (again.start < c.stop) & (again.stop > c.start)].all()


@pytest.mark.slow
def test_the_label_command_labels_a_long_take_in_windows(han19, tmp_path):
    """A take longer than a window through the label command: one labeled C3D, windows reported."""
    import json

    from mocap_autolabel.cli import main
    from mocap_autolabel.core.formats.c3d import write_c3d
    from mocap_autolabel.core.settings import WINDOW_FRAMES
    from mocap_autolabel.core.take import read_take

    synth = synthesize(han19, WINDOW_FRAMES + 1500, seed=9)
    src, out, report = tmp_path / "long.c3d", tmp_path / "long_labeled.c3d", tmp_path / "report.json"
    write_c3d(synth.take, src)
    assert main(["label", str(src), "--layout", "han19", "-o", str(out), "--report", str(report), "--quiet"]) == 0
    info = json.loads(report.read_text())["info"]
    assert len(info["windows"]) == 2 and info["frames"] == WINDOW_FRAMES + 1500
    labeled = read_take(str(out))
    assert labeled.n_frames == WINDOW_FRAMES + 1500
    named = [n for n in labeled.names if n in han19.names]
    assert len(named) == len(han19)
    # Each marker's samples are the take's own: labeled right in nearly every frame.
    right = total = 0
    for m, name in enumerate(han19.names):
        col = labeled.names.index(name)
        f, p = np.nonzero(synth.labels == m)
        ok = labeled.valid[f, col]
        same = np.isclose(labeled.positions[f[ok], col], synth.take.positions[f[ok], p[ok]], atol=1e-5)
        right += int(same.all(axis=1).sum())
        total += len(f)
    assert right / total > 0.99


@pytest.fixture(scope="module")
def long_one(han19):
    return synthesize(han19, 3000, seed=11)


def _middle_segment(lab, n_frames):
    """A labeled segment of 50-400 frames in the middle third of the take."""
    pick = np.flatnonzero((lab.label >= 0) & (lab.start > n_frames // 3) & (lab.stop < 2 * n_frames // 3)
                          & (lab.length >= 50) & (lab.length <= 400))
    return int(pick[0])


def test_a_re_solve_labels_again_only_around_the_change(han19, long_one):
    take = long_one.take
    lab = label_take(take, han19)
    assert lab.info["locks"] == [] and lab.info["splits"] == []
    seg = _middle_segment(lab, take.n_frames)
    wrong = (int(lab.label[seg]) + 1) % len(han19)
    c = Constraint(int(lab.slot[seg]), int(lab.start[seg]), int(lab.stop[seg]), wrong)
    full = label_take(take, han19, corrections=Corrections(constraints=[c]))
    local = label_take(take, han19, corrections=Corrections(constraints=[c]), previous=lab)
    (a, b), = local.info["relabeled"]
    assert 0 < a < c.start and c.stop < b < take.n_frames  # a stretch around the correction, not the take
    assert local.info["locks"] == [[c.slot, c.start, c.stop, wrong]]
    _check_segments(local, take)
    assert (local.per_sample() == full.per_sample()).mean() > 0.999
    per = local.per_sample()[c.start:c.stop, c.slot]
    assert (per[per != EMPTY] == wrong).all()
    # Outside the stretch the earlier labeling is kept as it was.
    assert (local.per_sample()[:a] == lab.per_sample()[:a]).all()
    # The correction taken back: the stretch is labeled again without it.
    undone = label_take(take, han19, previous=local)
    assert undone.info["relabeled"] and undone.info["locks"] == []
    assert (undone.per_sample() == lab.per_sample()).mean() > 0.999
    # Nothing changed: the take is labeled whole, as before.
    again = label_take(take, han19, previous=lab)
    assert "relabeled" not in again.info and (again.per_sample() == lab.per_sample()).all()


def test_a_two_hand_re_solve_labels_again_around_the_change(han19):
    from mocap_autolabel.core.hands import relabel_options

    two = two_hand_take(han19, 3000, seed=4, config=TwoHandConfig(close_share=0.0))
    lab = label_take(two.take, han19)
    seg = _middle_segment(lab, two.take.n_frames)
    c = Constraint(int(lab.slot[seg]), int(lab.start[seg]), int(lab.stop[seg]), int(lab.label[seg]))
    options = relabel_options(lab.info)
    settings = LabelSettings(hand_count=options["hand_count"], sides=options["sides"], naming=options.get("naming"))
    corrections = Corrections(constraints=[c], hand_swaps=options["hand_swaps"])
    full = label_take(two.take, han19, settings, corrections=corrections)
    local = label_take(two.take, han19, settings, corrections=corrections, previous=lab)
    assert local.info["relabeled"] and local.names == lab.names
    assert (local.per_sample() == full.per_sample()).mean() > 0.999
    f, p = np.nonzero(local.per_sample() >= 0)
    assert len(np.unique(f * 100 + local.per_sample()[f, p])) == len(f)  # no label twice in a frame
