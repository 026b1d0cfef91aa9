"""Gap filling in the core: each method where it must be exact, the ends, open gaps, two hands, C3D."""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.fill import fill_gaps, fill_markers, layout_partners
from mocap_autolabel.core.formats.c3d import read_c3d, write_c3d
from mocap_autolabel.core.hand import HandModel
from mocap_autolabel.core.hand.ik import HandSolver
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.rotations import rotvec_to_matrix
from mocap_autolabel.core.solve import HandSolve
from mocap_autolabel.core.synth.generate import marker_motion
from mocap_autolabel.core.take import Take

HAN19 = load_layout("han19")
RATE = 120.0


def test_spline_reproduces_a_cubic():
    t = np.arange(100) / RATE
    coef = np.random.default_rng(0).normal(size=(4, 3))
    x = (coef[0] + coef[1] * t[:, None] + coef[2] * t[:, None] ** 2 + coef[3] * t[:, None] ** 3)[:, None]
    hidden = x.copy()
    hidden[40:70] = np.nan
    out = fill_markers(hidden, RATE, "spline")
    (gap,) = out.gaps
    assert (gap.start, gap.stop, gap.method) == (40, 70, "spline")
    np.testing.assert_allclose(out.positions, x, atol=1e-9)
    assert out.filled[40:70].all() and out.filled.sum() == 30
    assert np.isfinite(out.error[40:70]).all() and np.isnan(out.error[:40]).all()


def _rigid_cluster(frames: int = 200, seed: int = 1) -> np.ndarray:
    """Five markers of one rigid body turning and moving smoothly: ``(F, 5, 3)`` metres."""
    rng = np.random.default_rng(seed)
    shape = rng.normal(0, 0.04, (5, 3))
    t = np.arange(frames) / RATE
    rot = rotvec_to_matrix(np.stack([np.sin(2 * t), 0.5 * np.cos(3 * t), t], axis=1))
    move = np.stack([0.2 * np.sin(t), 0.1 * t, 0.05 * np.cos(4 * t)], axis=1)
    return np.einsum("fij,mj->fmi", rot, shape) + move[:, None]


#: Each marker of the cluster moves rigidly with the four others.
CLUSTER = [np.delete(np.arange(5), m) for m in range(5)]


def test_rigid_reproduces_a_rigidly_moving_cluster():
    x = _rigid_cluster()
    hidden = x.copy()
    hidden[60:110, 0] = np.nan
    hidden[150:160, 2] = np.nan  # a partner unseen elsewhere: the others still carry the marker
    out = fill_markers(hidden, RATE, "rigid", partners=CLUSTER)
    assert [g.method for g in out.gaps] == ["rigid", "rigid"]
    np.testing.assert_allclose(out.positions, x, atol=1e-9)
    spline = fill_markers(hidden, RATE, "spline").positions
    assert np.abs(spline - x).max() > 1e-4  # the cluster's motion is no cubic: the test can tell


def _articulated(frames: int = 600, seed: int = 2) -> np.ndarray:
    """A rigid base of four markers turning and moving, and three markers that articulate on it
    (their places on the base linear in a 2-D bend): ``(F, 7, 3)`` metres."""
    rng = np.random.default_rng(seed)
    base = _rigid_cluster(frames, seed)[:, :4]
    t = np.arange(frames) / RATE
    bend = np.stack([np.sin(1.3 * t), np.cos(0.7 * t + 1)], axis=1)  # (F, 2)
    rest, along = rng.normal(0, 0.04, (3, 3)), rng.normal(0, 0.02, (3, 3, 2))
    local = rest[None] + np.einsum("mij,fj->fmi", along, bend)  # (F, 3, 3) on the base
    rot = rotvec_to_matrix(np.stack([np.sin(2 * t), 0.5 * np.cos(3 * t), t], axis=1))
    move = np.stack([0.2 * np.sin(t), 0.1 * t, 0.05 * np.cos(4 * t)], axis=1)
    return np.concatenate([base, np.einsum("fij,fmj->fmi", rot, local) + move[:, None]], axis=1)


def test_pose_reproduces_a_rigid_cluster_and_follows_an_articulating_marker():
    from mocap_autolabel.core.fill import PoseFill

    x = _rigid_cluster(600)
    hidden = x.copy()
    hidden[300:400, 0] = np.nan
    model = PoseFill(hidden, RATE)  # the model itself: exact for a rigid body
    np.testing.assert_allclose(model.predict(0, np.arange(290, 410), 300, 400), x[290:410, 0], atol=1e-9)
    out = fill_markers(hidden, RATE, "pose")
    assert [g.method for g in out.gaps] == ["pose"]
    np.testing.assert_allclose(out.positions, x, atol=5e-5)  # its course smoothed: 7 frames, quadratic
    spline = fill_markers(hidden, RATE, "spline").positions
    assert np.abs(spline - x).max() > 1e-3  # the test can tell

    x = _articulated()
    hidden = x.copy()
    hidden[250:370, 6] = np.nan  # one second of an articulating marker
    pose = fill_markers(hidden, RATE, "pose").positions
    spline = fill_markers(hidden, RATE, "spline").positions
    pca = fill_markers(hidden, RATE, "pca").positions
    err = {name: np.abs(f[250:370, 6] - x[250:370, 6]).max() for name, f in
           (("pose", pose), ("spline", spline), ("pca", pca))}
    assert err["pose"] < 2.5e-3 and err["pose"] < err["pca"] / 5 and err["pose"] < err["spline"] / 5, err


def _solved(observed: np.ndarray, hand: HandModel) -> dict:
    """``hand`` and its poses solved from ``observed`` (no smoothing: exact for exact data), as
    :func:`fill_markers` takes them."""
    solver = HandSolver(hand, HAN19.place(hand)[0])
    return {"solver": solver, "poses": solver.solve(observed).poses}


def _synergy_motion(hand: HandModel, frames: int, seed: int) -> np.ndarray:
    """Markers ``(F, 19, 3)`` of ``hand`` moving at random, its joint angles along one synergy (all
    together, as a closing hand, +-1 rad): a hidden fingertip's unseen angle is what the others say."""
    poses, _ = marker_motion(HAN19, hand, frames, seed=seed)
    angles = poses[:, 6:]
    _, _, vt = np.linalg.svd(angles - angles.mean(axis=0), full_matrices=False)
    course = (angles - angles.mean(axis=0)) @ vt[0]
    poses[:, 6:] = angles.mean(axis=0) + (course / np.abs(course).max())[:, None] * vt[0]
    return HandSolver(hand, HAN19.place(hand)[0]).markers(poses)


def test_hand_reproduces_the_hidden_marker_of_a_synthetic_take():
    """With its tip hidden, the thumb's IP angle is what the other angles say, and the prior says so."""
    hand = HandModel(side="right")
    truth = _synergy_motion(hand, 400, seed=1)
    hidden = truth.copy()
    tip, back = HAN19.names.index("ThumbTip"), HAN19.names.index("BackHand2")
    hidden[150:210, tip] = np.nan  # half a second
    hidden[250:280, back] = np.nan
    out = fill_markers(hidden, RATE, "hand", names=HAN19.names, **_solved(hidden, hand))
    assert {(g.name, g.method) for g in out.gaps} == {("ThumbTip", "hand"), ("BackHand2", "hand")}
    # exact but for the prior's floor (PRIOR_FLOOR: every angle may stray a little): < 0.1 mm
    assert np.abs(out.positions - truth).max() < 1e-4
    spline = fill_markers(hidden, RATE, "spline").positions
    assert np.abs(spline[150:210, tip] - truth[150:210, tip]).max() > 1e-3


def test_fills_meet_the_samples_with_no_jump():
    """A hand of the wrong size, off the marker by an offset that changes with the pose, still
    meets it in position and velocity."""
    hand = HandModel(side="left")
    _, truth = marker_motion(HAN19, hand, 300, seed=4)
    hidden = truth.copy()
    hidden[100:160, 3] = np.nan
    wrong = _solved(hidden, HandModel(side="left", length=hand.length * 1.1, breadth=hand.breadth * 0.9))
    model = wrong["solver"].markers(wrong["poses"])[:, 3]
    assert np.abs(model - truth[:, 3]).max() > 0.005  # off by more than 5 mm
    out = fill_markers(hidden, RATE, "hand", **wrong)
    x = out.positions[:, 3]
    for a, b in ((99, 100), (159, 160)):
        own = np.linalg.norm(truth[a + 1, 3] - truth[a, 3])
        assert np.linalg.norm(x[b] - x[a]) < own + 1e-4
    step = np.diff(x, axis=0)
    true_step = np.diff(truth[:, 3], axis=0)
    assert np.abs(step[[98, 99, 100, 158, 159, 160]] - true_step[[98, 99, 100, 158, 159, 160]]).max() < 1e-4
    assert np.abs(x[100:160] - truth[100:160, 3]).max() < 3e-3  # the drift is blended away


def test_open_gaps_are_reported():
    x = _rigid_cluster(300)
    x[:10, 0] = np.nan  # start
    x[290:, 1] = np.nan  # end
    x[100:250, 2] = np.nan  # 1.25 s
    x[50:52, 3] = np.nan
    out = fill_markers(x, RATE, "auto", max_gap=1.0, partners=CLUSTER, names=list("abcde"))
    why = {g.name: g.reason for g in out.gaps}
    assert why["a"] == "at the start of the take" and why["b"] == "at the end of the take"
    assert why["c"].startswith("longer than max_gap") and why["d"] == ""
    assert np.isnan(out.positions[:10, 0]).all() and np.isnan(out.positions[100:250, 2]).all()
    assert fill_markers(x, RATE, "auto", max_gap=2.0).gaps[2].method is not None
    assert {g.reason for g in fill_markers(x, RATE, "hand").gaps if g.start == 50} == {"no hand solve"}
    assert fill_markers(x, RATE, "rigid").gaps[3].reason == "no rigid partners given"
    few = [np.array([1, 2])] * 5
    assert fill_markers(x, RATE, "rigid", partners=few).gaps[3].reason == "fewer than 3 rigid partners"
    assert fill_markers(x, RATE, "auto", partners=few).gaps[3].method in ("pose", "spline")  # auto has no rigid
    with pytest.raises(ValueError, match="method"):
        fill_markers(x, RATE, "woltring")


def test_layout_partners_are_the_rigid_pairs_and_the_palm():
    names = np.array(HAN19.names)
    partners = layout_partners(HAN19)
    assert set(names[partners[HAN19.names.index("ThumbTip")]]) >= {"ThumbIP", "BackHand1", "BackHand2", "BackHand3"}
    assert set(names[partners[HAN19.names.index("BackHand1")]]) >= {"BackHand2", "BackHand3"}
    assert all(m not in p for m, p in enumerate(partners))


def _two_hand_take() -> tuple[Take, np.ndarray, dict]:
    """A labeled take of two hands named L_* / R_* plus one unlabeled point; the truth; the hands."""
    hands = {"left": HandModel(side="left"), "right": HandModel(side="right")}
    left = _synergy_motion(hands["left"], 360, seed=2)
    right = _synergy_motion(hands["right"], 360, seed=3)
    right = right + np.array([0.4, 0.0, 0.0])
    stray = np.full((360, 1, 3), np.nan)
    stray[100:120] = 0.5
    truth = np.concatenate([left, right, stray], axis=1).astype(np.float32)
    names = [f"L_{n}" for n in HAN19.names] + [f"R_{n}" for n in HAN19.names] + ["*40"]
    res = np.where(np.isfinite(truth[..., 0]), 0.0007, np.nan).astype(np.float32)
    return Take(truth.copy(), names, RATE, first_frame=5, residuals=res, source="two.c3d"), truth, hands


def test_fill_gaps_works_per_hand_of_a_two_hand_take():
    take, truth, hands = _two_hand_take()
    tip = HAN19.names.index("ThumbTip")
    take.positions[200:240, tip] = np.nan  # left ThumbTip
    take.positions[60:90, 19 + tip] = np.nan  # right ThumbTip
    solvers = {side: HandSolver(hands[side], HAN19.place(hands[side])[0]) for side in hands}
    solves = [(side, HandSolve(None, solvers[side].solve(take.positions[:, cols].astype(float)), HAN19, RATE, 5, {},
                               solvers[side])) for side, cols in (("left", slice(0, 19)), ("right", slice(19, 38)))]
    result = fill_gaps(take, HAN19, "auto", solves=solves)
    report = result.report()
    assert report["filled"] == 2 and report["open"] == 0  # the stray point is no layout marker
    filled = {g["marker"]: g for g in report["gap_list"] if g["method"]}
    assert set(filled) == {"L_ThumbTip", "R_ThumbTip"}
    assert filled["R_ThumbTip"]["first_frame"] == 65 and filled["R_ThumbTip"]["last_frame"] == 94
    out = result.take
    # each side filled from its own hand: exact but for the prior's floor (the other hand: cm off)
    assert np.abs(out.positions[:, :38] - truth[:, :38]).max() < 3e-4
    assert out.filled.sum() == 70 and out.filled[200:240, tip].all() and out.filled[60:90, 19 + tip].all()
    np.testing.assert_array_equal(out.positions[:, 38], take.positions[:, 38])
    with pytest.raises(MocapInputError, match="two.c3d"):
        fill_gaps(Take(take.positions, [f"x{i}" for i in range(39)], RATE, source="two.c3d"), HAN19, "spline")


def test_c3d_keeps_fills_marked_and_measured_samples_bit_identical(tmp_path):
    take, _, _ = _two_hand_take()
    take.positions[200:240, 5] = np.nan
    before = tmp_path / "labeled.c3d"
    write_c3d(take, before)
    labeled = read_c3d(before)
    assert labeled.filled is None or not labeled.filled.any()
    result = fill_gaps(labeled, HAN19, "spline")
    after = tmp_path / "filled.c3d"
    write_c3d(result.take, after)
    back = read_c3d(after)
    np.testing.assert_array_equal(back.filled, result.take.filled)
    measured = labeled.valid
    assert back.positions[measured].tobytes() == labeled.positions[measured].tobytes()
    assert np.abs(back.positions[back.filled] - result.take.positions[back.filled]).max() < 1e-6
    # The 4th word as the format states it (the c3d package reads it so; ezc3d splits a REAL file's
    # 4th word into two 16-bit integers instead): computed = residual 0 and no camera; measured =
    # a camera bit and the residual (1 mm here, whole millimetres at POINT:SCALE -1).
    c3d = pytest.importorskip("c3d")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        frames = [p.copy() for _, p, _ in c3d.Reader(io.BytesIO(after.read_bytes())).read_frames()]
    words = np.stack(frames)[..., 3:]  # residual and cameras as the c3d package reads them
    assert (words[back.filled] == 0).all()
    assert (words[measured][:, 1] == 1).all() and (words[measured][:, 0] == 1).all()
    np.testing.assert_allclose(back.residuals[measured], labeled.residuals[measured])
