"""Temporal labeling: voting with exclusivity, swaps, constraints, Viterbi, confidence, label_take."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import ROOT, data_path
from mocap_autolabel.core.checks import occlusion_note, work_limit_warning
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.labeling import EMPTY, NULL, Constraint, labeled_take, segments_from_runs
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.metrics import segments_right
from mocap_autolabel.core.pipeline import label_take
from mocap_autolabel.core.process import layout_doubt
from mocap_autolabel.core.settings import Corrections, LabelSettings
from mocap_autolabel.core.stages.refine import DOUBTFUL_SHARE
from mocap_autolabel.core.synth.generate import GHOST, TakeCorruption, corrupt_take, synthesize
from mocap_autolabel.core.take import Take, read_take
from mocap_autolabel.core.temporal.confidence import (
    SHORT_LABEL,
    fit_calibration,
    load_continuity,
    load_null_prior,
    load_occlusion_prior,
    load_partner,
    load_switch_cost,
    split_doubtful_edges,
)
from mocap_autolabel.core.temporal.partners import (
    OWN_TOLERANCE,
    TOLERANCE,
    TOLERANCE_SHARE,
    RigidPairs,
    partner_logp,
    rigid_pairs,
    take_distances,
)
from mocap_autolabel.core.temporal.viterbi import viterbi_labels
from mocap_autolabel.core.temporal.voting import (
    Samples,
    Segments,
    exclusive_assignment,
    find_swaps,
    segment_of,
    split_segments,
    tracklet_share,
    vote,
)
from mocap_autolabel.core.tracklets import Tracklets, break_rate, find_crossings, mask_runs


def _segments(starts, stops, slots=None) -> Segments:
    n = len(starts)
    slots = np.arange(n) if slots is None else np.asarray(slots)
    return Segments(np.asarray(slots, dtype=np.int64), np.asarray(starts, dtype=np.int64),
                    np.asarray(stops, dtype=np.int64))


def _brute_force(weights, segs, locked, switch=None):
    n, m1 = weights.shape
    m = m1 - 1
    switch = np.zeros(n) if switch is None else switch
    best = -np.inf
    for combo in itertools.product(range(m1), repeat=n):
        if any((combo[s] if combo[s] < m else NULL) != lab for s, lab in locked.items()):
            continue
        ok = True
        for a in range(n):
            for b in range(a + 1, n):
                overlap = segs.start[a] < segs.stop[b] and segs.start[b] < segs.stop[a]
                if overlap and combo[a] == combo[b] and combo[a] < m:
                    ok = False
        if ok:
            paid = sum(switch[s] for s in range(1, n) if combo[s] != combo[s - 1])
            best = max(best, sum(weights[s, combo[s]] for s in range(n)) - paid)
    return best


@pytest.mark.parametrize("seed", range(12))
def test_exclusive_assignment_is_optimal(seed):
    rng = np.random.default_rng(seed)
    n, m = 6, 3
    start = rng.integers(0, 20, n)
    segs = _segments(start, start + rng.integers(1, 15, n))
    weights = rng.normal(size=(n, m + 1)) * 5
    weights[:, :m] += 4.0  # real labels usually beat null, so conflicts happen
    locked = {0: int(rng.integers(-1, m))} if seed % 3 == 0 else {}
    labels = exclusive_assignment(weights, segs, locked, candidates=m)
    col = np.where(labels == NULL, m, labels)
    got = weights[np.arange(n), col].sum()
    assert got == pytest.approx(_brute_force(weights, segs, locked))
    for s, lab in locked.items():
        assert labels[s] == lab
    for a in range(n):  # exclusivity holds
        for b in range(a + 1, n):
            if segs.start[a] < segs.stop[b] and segs.start[b] < segs.stop[a] and labels[a] >= 0:
                assert labels[a] != labels[b]


def test_the_relaxed_assignment_is_exclusive_keeps_the_locks_and_is_near_the_exact_one():
    """The first vote of a pass settles clashes by the integer programme's linear relaxation, rounded
    in the order of its values: the labels stay exclusive in time, the locks hold, the same problem
    gives the same labels, and the labeling weighs more than the greedy one (on these dense random
    problems, within 11 % of the exact one; its labels are evidence for the vote that decides)."""
    from mocap_autolabel.core.temporal.voting import _greedy_assignment, _objective

    rng = np.random.default_rng(7)
    n, m = 80, 4
    for trial in range(6):
        start = rng.integers(0, 60, n)
        segs = _segments(start, start + rng.integers(1, 20, n))
        weights = rng.normal(size=(n, m + 1)) * 5
        weights[:, :m] += 4.0
        switch = np.where(rng.random(n) < 0.3, 3.0, 0.0)
        locked = {1: 2, 7: NULL}
        relaxed = exclusive_assignment(weights, segs, locked, candidates=m, switch=switch, exact_pairs=0)
        again = exclusive_assignment(weights, segs, locked, candidates=m, switch=switch, exact_pairs=0)
        exact = exclusive_assignment(weights, segs, locked, candidates=m, switch=switch)
        assert np.array_equal(relaxed, again)
        assert relaxed[1] == 2 and relaxed[7] == NULL
        for a in range(n):
            for b in range(a + 1, n):
                if segs.start[a] < segs.stop[b] and segs.start[b] < segs.stop[a] and relaxed[a] >= 0:
                    assert relaxed[a] != relaxed[b], (trial, a, b)
        col = lambda labels: np.where(labels == NULL, m, labels)  # noqa: E731
        var_seg, var_lab = np.nonzero(np.ones((n, m + 1), dtype=bool))
        greedy = _objective(weights, _greedy_assignment(weights, segs, var_seg, var_lab, locked, switch), switch)
        best, got = _objective(weights, col(exact), switch), _objective(weights, col(relaxed), switch)
        assert best >= got > greedy, (trial, best, got, greedy)


def test_exclusive_assignment_at_the_smallest_work_bound_still_labels():
    """Stopped by the smallest work bound (no search node), the vote still labels: the better of the
    solver's best and the greedy labeling, which keeps the locks and exclusivity and weighs at least
    as much as the greedy one. No clock decides: the same problem gives the same labels whatever
    the bound costs in time."""
    from mocap_autolabel.core.temporal.voting import _greedy_assignment, _objective

    rng = np.random.default_rng(1)
    n, m = 60, 3
    start = rng.integers(0, 50, n)
    segs = _segments(start, start + rng.integers(1, 15, n))
    weights = rng.normal(size=(n, m + 1)) * 5
    weights[:, :m] += 4.0
    locked = {0: 1, 5: NULL}
    facts, facts_solved = {}, {}
    hurried = exclusive_assignment(weights, segs, locked, candidates=m, node_limit=0, facts=facts)
    again = exclusive_assignment(weights, segs, locked, candidates=m, node_limit=0)
    solved = exclusive_assignment(weights, segs, locked, candidates=m, facts=facts_solved)
    assert facts == {"work_limited": 1} and facts_solved == {"work_limited": 0}
    assert np.array_equal(hurried, again)
    assert (hurried >= 0).sum() > n // 4  # labels, not all null
    col = lambda labels: np.where(labels == NULL, m, labels)  # noqa: E731
    zero = np.zeros(n)
    var_seg, var_lab = np.nonzero(np.ones((n, m + 1), dtype=bool))
    greedy = _greedy_assignment(weights, segs, var_seg, var_lab, locked, zero)
    assert _objective(weights, col(hurried), zero) >= _objective(weights, greedy, zero) - 1e-9
    assert _objective(weights, col(solved), zero) >= _objective(weights, col(hurried), zero) - 1e-9
    labeling = label_take(synthesize(load_layout("glove13"), 240, seed=4).take, load_layout("glove13"))
    assert labeling.info["work_limited"] == 0 and work_limit_warning(labeling) is None
    labeling.info["work_limited"] = 2
    assert "reached its work bound 2 time(s) (1000 search nodes" in work_limit_warning(labeling)
    for labels in (hurried, solved):
        assert labels[0] == 1 and labels[5] == NULL
        for a in range(n):
            for b in range(a + 1, n):
                if segs.start[a] < segs.stop[b] and segs.start[b] < segs.stop[a] and labels[a] >= 0:
                    assert labels[a] != labels[b]


def test_a_programme_whose_relaxation_leaves_too_many_pairs_undecided_is_rounded_and_counted(monkeypatch):
    """The node bound does not bound HiGHS's root; a relaxation with more than FRACTIONAL_PAIRS
    fractional pairs is rounded instead of solved, and counted as work-limited."""
    import mocap_autolabel.core.temporal.voting as voting

    rng = np.random.default_rng(7)
    n, m = 80, 4
    locked = {1: 2, 7: NULL}
    for _ in range(6):  # the first of these dense problems whose relaxation leaves pairs fractional
        start = rng.integers(0, 60, n)
        segs = _segments(start, start + rng.integers(1, 20, n))
        weights = rng.normal(size=(n, m + 1)) * 5
        weights[:, :m] += 4.0
        switch = np.where(rng.random(n) < 0.3, 3.0, 0.0)
        exact_facts, rounded_facts = {}, {}
        exact = exclusive_assignment(weights, segs, locked, candidates=m, switch=switch, facts=exact_facts)
        relaxed = exclusive_assignment(weights, segs, locked, candidates=m, switch=switch, exact_pairs=0)
        if not np.array_equal(exact, relaxed):
            break
    assert not np.array_equal(exact, relaxed)
    integer_solves = []
    solve = voting.milp

    def spy(cost, **kw):
        integer_solves.append(bool(kw["integrality"].any()))
        return solve(cost, **kw)

    monkeypatch.setattr(voting, "milp", spy)
    monkeypatch.setattr(voting, "FRACTIONAL_PAIRS", 0)
    rounded = exclusive_assignment(weights, segs, locked, candidates=m, switch=switch, facts=rounded_facts)
    assert np.array_equal(rounded, relaxed) and integer_solves == [False]
    assert exact_facts == {"work_limited": 0} and rounded_facts == {"work_limited": 1}


def test_a_sparse_take_read_with_the_dense_layout_is_labeled_without_an_unbounded_solve(monkeypatch):
    """The helper's report: a fingertip take labeled with the default han19 ran in HiGHS's root for
    over ten minutes. Every integer programme solved exactly must have a relaxation within the
    bound (the spy fails at once otherwise, rather than hang)."""
    import mocap_autolabel.core.temporal.voting as voting

    solve = voting.milp
    widest = []

    def spy(cost, **kw):
        if kw["integrality"].any():
            lp = solve(cost, **{**kw, "integrality": np.zeros_like(kw["integrality"])})
            values = np.round(lp.x[:int(kw["integrality"].sum())], 6)
            widest.append(int(((values > 0) & (values < 1)).sum()))
            assert widest[-1] <= voting.FRACTIONAL_PAIRS, f"an exact solve of {widest[-1]} fractional pairs"
        return solve(cost, **kw)

    monkeypatch.setattr(voting, "milp", spy)
    take = synthesize(load_layout("tips5_hand3"), 1500, seed=3).take
    labeling = label_take(take, load_layout("han19"))
    assert labeling.info["work_limited"] >= 1  # the bound acted: this take does pose such a programme
    assert "reached its work bound" in work_limit_warning(labeling)


@pytest.mark.parametrize("seed", range(12))
def test_exclusive_assignment_with_paid_switches_is_optimal(seed):
    """Pieces of one trajectory pay to change label between them; the assignment stays optimal
    and exclusive (checked against brute force)."""
    rng = np.random.default_rng(100 + seed)
    m, slots, starts, stops = 3, [], [], []
    for slot in range(3):
        edges = np.cumsum(np.concatenate([[rng.integers(0, 6)], rng.integers(2, 8, rng.integers(1, 4))]))
        slots += [slot] * (len(edges) - 1)
        starts += edges[:-1].tolist()
        stops += edges[1:].tolist()
    segs = _segments(starts, stops, slots)
    n = len(segs)
    weights = rng.normal(size=(n, m + 1)) * 5
    weights[:, :m] += 3.0
    joined = np.r_[False, (segs.slot[1:] == segs.slot[:-1]) & (segs.start[1:] == segs.stop[:-1])]
    switch = np.where(joined, rng.uniform(0.5, 12.0, n), 0.0)
    locked = {n - 1: int(rng.integers(-1, m))} if seed % 3 == 0 else {}
    labels = exclusive_assignment(weights, segs, locked, switch=switch)
    col = np.where(labels == NULL, m, labels)
    paid = sum(switch[s] for s in range(1, n) if col[s] != col[s - 1])
    assert weights[np.arange(n), col].sum() - paid == pytest.approx(_brute_force(weights, segs, locked, switch))
    for s, lab in locked.items():
        assert labels[s] == lab
    for a in range(n):
        for b in range(a + 1, n):
            if segs.start[a] < segs.stop[b] and segs.start[b] < segs.stop[a] and labels[a] >= 0:
                assert labels[a] != labels[b]


def test_a_trajectory_changes_label_only_where_its_evidence_pays_for_the_switch():
    """Three pieces of one trajectory: a middle stretch that reads as label 1 by 30 nats stays
    label 0 when a switch costs 20 nats (two switches: 40), and changes when it costs 10. A last
    piece that reads as label 2 by 50 nats changes (a real swap), and only there."""
    segs = _segments([0, 40, 80], [40, 80, 120], slots=[0, 0, 0])
    weights = np.array([[60.0, 0.0, 0.0, 0.0], [0.0, 30.0, 0.0, 0.0], [60.0, 0.0, 0.0, 0.0]])
    for cost, expect in ((20.0, [0, 0, 0]), (10.0, [0, 1, 0])):
        assert exclusive_assignment(weights, segs, switch=np.array([0.0, cost, cost])).tolist() == expect
    weights[1:] = [[5.0, 15.0, 0.0, 0.0], [0.0, 0.0, 50.0, 0.0]]
    assert exclusive_assignment(weights, segs, switch=np.array([0.0, 20.0, 20.0])).tolist() == [0, 0, 2]
    assert exclusive_assignment(weights, segs).tolist() == [0, 1, 2]  # no cost: each piece alone


def test_a_segment_whose_best_labels_are_taken_takes_its_next_free_one():
    """Every label that outweighs null is a candidate, not only a segment's first few (a thumb tip
    inside a fist reads as the four finger markers around it, which their own segments hold)."""
    m = 6
    weights = np.zeros((5, m + 1))
    weights[0, :5] = [10.0, 9.0, 8.0, 7.0, 6.0]  # the 5th label, free, still beats null (0)
    for s in range(1, 5):
        weights[s, s - 1] = 100.0  # overlapping segments that own labels 0-3
    segs = _segments([0, 0, 5, 10, 15], [20, 20, 20, 20, 20])
    labels = exclusive_assignment(weights, segs)
    assert labels.tolist() == [4, 0, 1, 2, 3]
    assert exclusive_assignment(weights, segs, candidates=4)[0] == NULL  # the old cut-off lost it


def test_null_prior_is_paid_once_per_segment():
    """A label must beat null by the prior over the whole segment: a 3-frame flicker with a weak
    lead becomes null, a 50-frame track with the same per-frame lead keeps its label."""
    frame = np.concatenate([np.arange(60, 63), np.arange(50)])  # the flicker comes after the track
    slot = np.concatenate([np.zeros(3), np.ones(50)]).astype(np.int64)
    logp = np.tile(np.log(np.array([[0.6, 0.05, 0.05, 0.3]], dtype=np.float32)), (len(frame), 1))
    samples = Samples(frame=frame, slot=slot, logp=logp, label=np.zeros(len(frame), dtype=np.int64),
                      confidence=np.full(len(frame), 0.6, dtype=np.float32))
    segs = _segments([60, 0], [63, 50], slots=[0, 1])
    locked_at = np.full((70, 2), EMPTY, dtype=np.int16)
    _, labels, _, _ = vote(samples, segs, locked_at, split_swaps=False)
    assert labels.tolist() == [0, 0]
    _, labels, _, _ = vote(samples, segs, locked_at, split_swaps=False, null_prior=(4.0, 0.0))  # lead 3 x 0.69
    assert labels.tolist() == [NULL, 0]


def test_break_rate_counts_trajectory_ends_before_the_last_frame_per_second_tracked():
    valid = np.zeros((240, 3), dtype=bool)
    valid[:, 0] = True  # tracked throughout: no break
    valid[:100, 1] = valid[130:, 1] = True  # one break
    valid[50:52, 2] = True  # a two-frame flicker is no trajectory
    # 240 + 100 + 110 frames tracked at 120 Hz: 3.75 s, one end before the last frame.
    tracklets = Tracklets(*mask_runs(valid))
    assert break_rate(tracklets, 240, 120.0) == pytest.approx(1 / 3.75)
    assert break_rate(tracklets, 240, 60.0) == pytest.approx(1 / 7.5)
    assert break_rate(Tracklets(*mask_runs(np.zeros((10, 2), dtype=bool))), 10, 120.0) == 0.0


def test_the_occlusion_prior_keeps_more_markers_under_heavy_occlusion_and_leaves_other_takes_alone(monkeypatch):
    layout = load_layout("han19")
    knee, slope = load_occlusion_prior("set", "vote", "han19")
    assert knee > 0.0 and slope > 0.0  # fitted by training.confidence --fit occlusion
    s = synthesize(layout, 900, seed=7)
    heavy = TakeCorruption(gaps_per_minute=138, mean_gap_s=0.125, persistent_ghosts=3, noise_sd=0.001)
    take, truth, _ = corrupt_take(s.markers, s.take.rate, seed=7, cfg=heavy)
    shipped = label_take(take, layout)
    without = label_take(take, layout, LabelSettings(occlusion_prior=(0.0, 0.0)))
    assert shipped.info["break_rate"] > knee + 0.5 and shipped.info["occlusion_prior"] == [knee, slope]
    marker = take.valid & (truth >= 0)

    def counts(labeling):
        per = labeling.per_sample()
        return int((per[marker] == NULL).sum()), int((per[marker] == truth[marker]).sum())

    (null_with, right_with), (null_without, right_without) = counts(shipped), counts(without)
    assert null_with < null_without and right_with > right_without
    assert occlusion_note(shipped).startswith("heavy occlusion: the take's trajectories break")
    assert occlusion_note(without) is None  # the prior did not act
    # Another layout is tried on the evidence alone: on its markers the label bonus makes nearly
    # every label worth a segment, and the vote's programme grows by an order of magnitude.
    import mocap_autolabel.core.process as process

    tried = []

    def spy(take, layout, settings, **kw):
        tried.append((layout.name, settings.occlusion_prior))
        return label_take(take, layout, settings, **kw)

    monkeypatch.setattr(process, "label_take", spy)
    process.layout_doubt(take, layout, shipped)
    assert ("glove13", (0.0, 0.0)) in tried
    # A take whose trajectories seldom break is labeled as without the prior.
    plain = label_take(s.take, layout)
    assert plain.info["break_rate"] < knee and occlusion_note(plain) is None
    assert (plain.per_sample() ==
            label_take(s.take, layout, LabelSettings(occlusion_prior=(0.0, 0.0))).per_sample()).all()


def test_label_take_uses_the_shipped_vote_settings_unless_given_them():
    layout = load_layout("glove13")
    s = synthesize(layout, 240, seed=4)
    shipped, switch = load_null_prior("set", "vote", "glove13"), load_switch_cost("set", "vote", "glove13")
    partner, continuity = load_partner("set", "vote", "glove13"), load_continuity("set", "vote", "glove13")
    # Fitted by training.confidence for the default pipeline.
    assert shipped[0] > 0.0 and switch[1] > 0.0 and any(partner) and any(continuity)
    info = label_take(s.take, layout).info
    assert info["null_prior"] == list(shipped) and info["switch_cost"] == list(switch)
    assert info["partner"] == list(partner) and info["continuity"] == list(continuity)
    info = label_take(s.take, layout, LabelSettings(null_prior=(0.0, 0.0), switch_cost=(0.0, 0.0),
                                                   partner=(0.0, 0.0))).info
    assert info["null_prior"] == [0.0, 0.0] and info["switch_cost"] == [0.0, 0.0] and info["partner"] == [0.0, 0.0]
    info = label_take(s.take, layout, LabelSettings(vote_score="power")).info  # fitted for the likelihood score only
    assert info["null_prior"] == [0.0, 0.0] and info["switch_cost"] == [0.0, 0.0] and info["partner"] == [0.0, 0.0]
    for load in (load_null_prior, load_switch_cost, load_partner):
        assert load("set", "vote", "no_such_layout") == (0.0, 0.0)


@pytest.mark.parametrize(("glove", "chosen"), [("han19", "glove13"),
                                             pytest.param("glove13", "han19", marks=pytest.mark.slow)])
def test_a_take_labeled_with_the_wrong_layout_names_the_right_one(glove, chosen):
    take = synthesize(load_layout(glove), 600, seed=3).take
    wrong = label_take(take, load_layout(chosen))
    doubt = layout_doubt(take, load_layout(chosen), wrong)
    assert doubt is not None and doubt.layout == chosen and doubt.better == glove
    assert doubt.share == wrong.summary()["confident_share"] < DOUBTFUL_SHARE <= doubt.better_share
    assert f"is this a {glove} take?" in str(doubt)
    right = label_take(take, load_layout(glove))
    assert layout_doubt(take, load_layout(glove), right) is None


def test_a_quick_reading_settles_clashes_by_the_relaxation_and_the_layout_check_reads_quickly(monkeypatch):
    """On another layout's markers a clash's integer programme could take minutes (a 400-frame take: 3 min
    within the node bound, all in HiGHS's root); ``exact_pairs=0`` settles every clash by the rounded
    relaxation, and the layout check reads the other layouts so."""
    import mocap_autolabel.core.temporal.voting as voting

    solves = []
    real = voting.milp

    def counted(*args, **kwargs):
        solves.append(int(np.sum(kwargs["integrality"])))
        return real(*args, **kwargs)

    monkeypatch.setattr(voting, "milp", counted)
    take = synthesize(load_layout("glove13"), 300, seed=3).take
    exact = label_take(take, load_layout("han19"))
    assert any(solves)  # the wrong layout's clashes: integer programmes
    solves.clear()
    quick = label_take(take, load_layout("han19"), LabelSettings(exact_pairs=0))
    assert solves and not any(solves)  # clashes, each settled by its relaxation
    per = quick.per_sample()
    for label in range(len(quick.names)):  # still exclusive: a label once per frame
        assert ((per == label).sum(axis=1) <= 1).all()
    assert exact.per_sample().shape == per.shape
    solves.clear()
    exact.confidence[:] = 0.5  # doubtful, as if labeled with another layout: glove13 and han19 are tried
    assert layout_doubt(take, load_layout("tips5"), exact).better == "glove13"
    assert solves and not any(solves)  # han19's clashes among glove13's markers


def test_a_sparse_layouts_own_take_is_not_called_a_dense_layouts_of_as_many_markers():
    """A studio's 13-marker set (tips10_hand3) labels its own take with set_any, whose raw confidences seldom
    reach 0.95; glove13's calibrated ones claimed the take ("is this a glove13 take?"). Only layouts of more
    markers are tried against an uncalibrated labeling, so a han19 or glove13 take labeled with a sparse
    layout of fewer markers is still named."""
    take = synthesize(load_layout("tips10_hand3"), 400, seed=11).take
    own = label_take(take, load_layout("tips10_hand3"))
    assert own.info["confidence"].startswith("raw") and own.summary()["confident_share"] < DOUBTFUL_SHARE
    assert layout_doubt(take, load_layout("tips10_hand3"), own) is None
    glove = synthesize(load_layout("glove13"), 600, seed=3).take
    wrong = label_take(glove, load_layout("tips5"))
    doubt = layout_doubt(glove, load_layout("tips5"), wrong)
    assert doubt is not None and doubt.better == "glove13"


def test_a_low_confidence_alone_raises_no_layout_doubt():
    """Short right takes can score low (8 of han2018's 316 raw takes: 20-49 %): no other layout
    does clearly better there, so nothing is said."""
    layout = load_layout("han19")
    take = synthesize(layout, 600, seed=3).take
    labeling = label_take(take, layout)
    labeling.confidence[:] = 0.5  # as doubtful as a wrong layout, but glove13 fits no better
    assert labeling.summary()["confident_share"] == 0.0
    assert layout_doubt(take, layout, labeling) is None


def test_a_take_crowded_past_the_labelers_cap_labels():
    """Far points beyond the cap are not scored, but their trajectories (here with a gap) are still
    checked for continuity; that indexed past the scored slots (two real C3D files crashed so)."""
    layout = load_layout("han19")
    s = synthesize(layout, 300, seed=2)
    rng = np.random.default_rng(0)
    far = np.repeat(rng.normal(size=(1, 50, 3)) * 0.5 + [3.0, 0.0, 0.0], 300, axis=0).astype(np.float32)
    far[100:110] = np.nan
    take = Take(positions=np.concatenate([s.take.positions, far], axis=1),
                names=s.take.names + [f"far{i}" for i in range(50)], rate=s.take.rate)
    labeling = label_take(take, layout)
    per = labeling.per_sample()
    assert (per[:, s.take.n_points:][take.valid[:, s.take.n_points:]] == NULL).all()  # never scored: null
    assert (per[:, :s.take.n_points] == label_take(s.take, layout).per_sample()).all()  # the hand as without them


def test_exclusivity_is_an_assignment_not_greedy():
    # Both overlapping segments prefer label 0. Greedy (strongest first) gives segment 1 label 0
    # and segment 0 label 1: 10.5 + 2. The assignment gives 10 + 9.8.
    segs = _segments([0, 5], [10, 15])
    weights = np.array([[10.0, 2.0, 0.0], [10.5, 9.8, 0.0]])
    assert list(exclusive_assignment(weights, segs)) == [0, 1]


def test_split_segments_and_lookup():
    segs = split_segments(_segments([0, 0], [10, 8], slots=[0, 1]), {0: [4, 7, 12], 1: [0]})
    assert list(zip(segs.slot, segs.start, segs.stop)) == [(0, 0, 4), (0, 4, 7), (0, 7, 10), (1, 0, 8)]
    got = segment_of(segs, np.array([0, 4, 9, 10, 3]), np.array([0, 0, 0, 0, 1]))
    assert list(got) == [0, 1, 2, -1, 3]


def test_find_swaps_cuts_where_the_evidence_flips():
    frames, m = 60, 4
    logp = np.full((frames, m + 1), -8.0, dtype=np.float32)
    logp[:35, 1] = -0.05
    logp[35:, 2] = -0.05
    logp[20, 3] = -0.01  # one odd frame is no swap
    samples = Samples(frame=np.arange(frames), slot=np.zeros(frames, dtype=np.int64), logp=logp,
                      label=np.argmax(logp, axis=1), confidence=np.ones(frames, dtype=np.float32))
    segs = _segments([0], [frames])
    assert find_swaps(samples, np.zeros(frames, dtype=np.int64), segs) == {0: [35]}
    logp[35:, 2], logp[35:, 1] = -8.0, -0.05  # no flip: no cut
    samples.label = np.argmax(logp, axis=1)
    assert find_swaps(samples, np.zeros(frames, dtype=np.int64), segs) == {}


def test_find_swaps_cuts_a_swap_in_the_first_or_last_frames():
    """A capture system's swap one frame into a tracklet leaves too few frames for a change point:
    a short end run that is sure of another label is cut off; a doubtful one is not."""
    frames, m = 60, 4
    logp = np.full((frames, m + 1), -12.0, dtype=np.float32)
    logp[:, 1] = -0.01
    logp[0, 1], logp[0, 2] = -12.0, -0.01  # the first frame is another marker
    logp[57:, 1], logp[57:, 3] = -12.0, -0.01  # and the last three are a third one
    samples = Samples(frame=np.arange(frames), slot=np.zeros(frames, dtype=np.int64), logp=logp,
                      label=np.argmax(logp, axis=1), confidence=np.ones(frames, dtype=np.float32))
    seg, segs = np.zeros(frames, dtype=np.int64), _segments([0], [frames])
    assert find_swaps(samples, seg, segs) == {0: [1, 57]}
    logp[0, 1], logp[0, 2] = -1.5, -0.3  # a doubtful first frame: kept
    assert find_swaps(samples, seg, segs) == {0: [57]}


def test_segments_from_runs_round_trip():
    labels = np.array([[0, 1], [0, 1], [2, NULL], [2, NULL]])
    valid = np.array([[True, True], [True, False], [True, True], [True, True]])
    lab = segments_from_runs(["a", "b", "c"], labels, valid, {})
    assert list(zip(lab.slot, lab.start, lab.stop, lab.label)) == [(0, 0, 2, 0), (0, 2, 4, 2), (1, 0, 1, 1),
                                                                   (1, 2, 4, NULL)]
    per = lab.per_sample()
    assert (per[valid] == labels[valid]).all() and (per[~valid] == EMPTY).all()
    truth = np.array([[0, 1], [0, 1], [2, GHOST], [1, GHOST]])  # frame 3 of slot 0 is really label 1
    assert list(segments_right(lab, truth, valid)) == [True, False, True, True]


@pytest.fixture(scope="module")
def synth_take(han19):
    return synthesize(han19, 1500, seed=11)


def _accuracy(labeling, take, truth):
    per = labeling.per_sample()
    t = np.where(truth == GHOST, NULL, truth)
    return float((per[take.valid] == t[take.valid]).mean())


def test_vote_fixes_per_frame_flicker(han19, synth_take):
    none = label_take(synth_take.take, han19, LabelSettings(temporal="none"))
    vote = label_take(synth_take.take, han19, LabelSettings(temporal="vote"))
    a_none, a_vote = _accuracy(none, synth_take.take, synth_take.labels), _accuracy(vote, synth_take.take,
                                                                                   synth_take.labels)
    assert a_vote > a_none and a_vote > 0.995
    # Exclusivity: no label twice in a frame.
    per = vote.per_sample()
    for j in range(len(han19)):
        assert ((per == j).sum(axis=1) <= 1).all()
    assert vote.info["seconds"]["total"] > 0 and 0 <= vote.confidence.min() <= vote.confidence.max() <= 1


def test_constraints_are_honoured_and_propagate(han19, synth_take):
    take, _truth = synth_take.take, synth_take.labels
    base = label_take(take, han19)
    # Lock the longest labeled segment to the label of another segment that overlaps it.
    order = np.argsort(-base.length)
    a = next(i for i in order if base.label[i] >= 0)
    overlap = (base.start < base.stop[a]) & (base.start[a] < base.stop) & (base.label >= 0)
    overlap &= base.slot != base.slot[a]
    b = int(np.flatnonzero(overlap)[0])
    ghost = next(i for i in order if base.label[i] >= 0 and i not in (a, b) and base.slot[i] != base.slot[b])
    cons = [Constraint(int(base.slot[a]), int(base.start[a]), int(base.stop[a]), int(base.label[b])),
            Constraint(int(base.slot[ghost]), int(base.start[ghost]), int(base.stop[ghost]), NULL)]
    for temporal in ("vote", "none", "viterbi"):
        lab = label_take(take, han19, LabelSettings(temporal=temporal), corrections=Corrections(constraints=cons))
        per = lab.per_sample()
        rows = slice(base.start[a], base.stop[a])
        on_a = per[rows, base.slot[a]]
        assert (on_a[take.valid[rows, base.slot[a]]] == base.label[b]).all(), temporal
        others = np.delete(per[rows], base.slot[a], axis=1)
        assert not (others == base.label[b]).any(), temporal  # the label is taken there
        g = slice(base.start[ghost], base.stop[ghost])
        assert (per[g, base.slot[ghost]][take.valid[g, base.slot[ghost]]] == NULL).all(), temporal
        locked = lab.locked
        assert locked.any() and (lab.confidence[locked] == 1.0).all()


def test_conflicting_or_bad_constraints_are_clear_errors(han19, synth_take):
    take = synth_take.take
    with pytest.raises(ValueError, match="constraints conflict"):
        label_take(take, han19, corrections=Corrections(constraints=[Constraint(0, 0, 10, 3), Constraint(1, 5, 20, 3)]))
    with pytest.raises(ValueError, match="outside the take"):
        label_take(take, han19, corrections=Corrections(constraints=[Constraint(999, 0, 10, 3)]))
    with pytest.raises(ValueError, match="not in the layout"):
        label_take(take, han19, corrections=Corrections(constraints=[Constraint(0, 0, 10, 42)]))


def test_crossing_trajectories_that_trade_markers_are_cut_where_they_trade():
    # Two markers on straight lines 4 mm apart at frame 30, moving 6 mm per frame in opposite
    # directions along x; slot 2 keeps clear of both.
    t = np.arange(60)[:, None]
    a = np.concatenate([0.006 * (t - 30), np.full((60, 1), 0.002), np.zeros((60, 1))], axis=1)
    b = np.concatenate([-0.006 * (t - 30), np.full((60, 1), -0.002), np.zeros((60, 1))], axis=1)
    far = a + np.array([0.0, 0.5, 0.0])
    noise = np.random.default_rng(0).normal(0.0, 3e-4, size=(60, 3, 3))
    straight = np.stack([a, b, far], axis=1) + noise
    assert find_crossings(Take(positions=straight.astype(np.float32), names=["*0", "*1", "*2"], rate=120.0)) == {}
    traded = straight.copy()
    traded[31:, [0, 1]] = traded[31:, [1, 0]]  # the tracker swaps them after the closest frame
    cuts = find_crossings(Take(positions=traded.astype(np.float32), names=["*0", "*1", "*2"], rate=120.0))
    assert cuts == {0: [31], 1: [31]}


def test_pieces_of_one_tracklet_share_its_null_prior():
    segs = Segments(np.array([0, 0, 0, 1]), np.array([0, 10, 45, 0]), np.array([10, 40, 50, 5]))
    np.testing.assert_allclose(tracklet_share(segs), [0.25, 0.75, 1.0, 1.0])  # a gap ends a tracklet
    # A 10-frame piece cut from a 40-frame trajectory, 1 nat per frame for label 0 over null:
    # paying the whole 12-nat prior it would go null; its share (3 nats) it beats.
    frames = np.arange(40)
    logp = np.tile(np.log(np.array([0.6, 0.05, 0.35])), (40, 1)).astype(np.float32)
    logp[:30] = np.log(np.array([0.05, 0.9, 0.05]))  # the first 30 frames are label 1
    samples = Samples(frame=frames, slot=np.zeros(40, dtype=np.int64), logp=logp,
                      label=np.zeros(40, dtype=np.int64), confidence=np.ones(40))
    whole = Segments(np.array([0, 0]), np.array([0, 30]), np.array([30, 40]))
    locked = np.full((40, 1), EMPTY, dtype=np.int16)
    _, labels, _, _ = vote(samples, whole, locked, split_swaps=False, null_prior=(12.0, 0.0))
    assert list(labels) == [1, 0]


def test_swap_inside_a_tracklet_is_split(han19):
    seen = 0
    for seed in range(6):
        markers = synthesize(han19, 600, seed=200 + seed).markers
        take, truth, facts = corrupt_take(markers, 120.0, seed, TakeCorruption(
            swap_share=1.0, swap_distance=0.05, gaps_per_minute=0, fragments_per_minute=0,
            flicker_ghosts_per_frame=0, persistent_ghosts=0))
        if not facts["swaps"]:
            continue
        seen += 1
        lab = label_take(take, han19)
        # Cut at the swap (by the crossing test, or by the evidence a few frames off) in both slots.
        valid = take.valid
        changed = valid[1:] & valid[:-1] & (truth[1:] != truth[:-1])
        frames, slots = np.nonzero(changed)
        assert len(slots) == 2
        for f, slot in zip(frames + 1, slots):
            starts = lab.start[lab.slot == slot]
            assert (np.abs(starts - f) <= 3).any()
        # Around a split the few frames where the two markers nearly touch can go either way: the
        # shipped models get 98.9-100 % of these takes right.
        assert _accuracy(lab, take, truth) > 0.985
    assert seen


def test_viterbi_follows_motion_when_a_frame_is_ambiguous():
    # Two markers on straight lines; in frame 10 the scores favour swapping them, slightly.
    frames, m = 20, 2
    t = np.arange(frames)[:, None] / 120.0
    a = np.concatenate([t * 0.3, np.zeros((frames, 2))], axis=1)
    b = a + np.array([0.0, 0.01, 0.0])
    points = np.stack([a, b], axis=1).astype(np.float32)
    scores = np.full((frames, 2, m + 1), -6.0)
    scores[:, 0, 0] = scores[:, 1, 1] = -0.1
    scores[10, 0, 0] = scores[10, 1, 1] = -1.0
    scores[10, 0, 1] = scores[10, 1, 0] = -0.8
    mask = np.ones((frames, 2), dtype=bool)
    labels = viterbi_labels(scores, mask, points, 120.0)
    assert (labels[:, 0] == 0).all() and (labels[:, 1] == 1).all()


def test_calibration_is_monotone_and_conservative():
    rng = np.random.default_rng(0)
    p = rng.random(4000)
    correct = rng.random(4000) < p  # the mean probability is itself calibrated here
    evidence = np.column_stack([p, np.ones(4000), np.zeros(4000), np.full(4000, 50.0)])
    cal = fit_calibration(evidence, correct)
    xs = np.linspace(0, 1, 101)
    grid = np.column_stack([xs, np.ones(101), np.zeros(101), np.full(101, 50.0)])
    ys = cal(grid)
    assert (np.diff(ys) >= -1e-9).all()
    assert (ys <= xs + 0.05).all()  # never promises more than the data shows
    short = grid.copy()
    short[:, 3] = 2.0
    assert (cal(short) == 0.0).all()  # no short segments seen: no confidence
    assert ys.max() < 0.95  # nowhere were segments right 99.9 % of the time


def test_confidence_of_095_is_earned_by_a_pure_group():
    rng = np.random.default_rng(1)
    p = np.concatenate([np.full(3000, 0.99), rng.uniform(0, 0.9, 3000)])
    correct = np.concatenate([np.ones(3000, bool), rng.random(3000) < p[3000:]])
    evidence = np.column_stack([p, np.ones(6000), np.zeros(6000), np.full(6000, 50.0)])
    cal = fit_calibration(evidence, correct)
    sure = cal(evidence) >= 0.95
    assert sure[:3000].all() and sure[3000:].mean() < 0.02  # the pure group, and hardly anything else
    assert correct[sure].mean() >= 0.999


def test_segments_tied_at_the_sure_threshold_are_all_counted():
    # 2,000 right segments scored highest, then 100 tied ones of which 10 are wrong: the tie
    # cannot be cut, so it stays below "sure" and the promise holds.
    n_top, n_tie = 2000, 100
    p = np.concatenate([np.full(n_top, 0.999), np.full(n_tie, 0.99), np.linspace(0.1, 0.9, 2000)])
    correct = np.concatenate([np.ones(n_top, bool), np.arange(n_tie) < 90, np.arange(2000) % 2 == 0])
    evidence = np.column_stack([p, np.ones(len(p)), np.zeros(len(p)), np.full(len(p), 50.0)])
    cal = fit_calibration(evidence, correct)
    sure = cal(evidence) >= 0.95
    assert sure[:n_top].all() and not sure[n_top:].any()
    assert correct[sure].mean() >= 0.999


def test_a_short_marker_label_is_never_sure_but_a_short_null_can_be():
    rng = np.random.default_rng(2)
    n = 6000
    length = np.where(np.arange(n) % 2 == 0, SHORT_LABEL - 1.0, 50.0)  # short and long segments
    good = np.arange(n) < 4000  # strong evidence and right; the rest weak and mostly wrong
    p = np.where(good, 0.99, 0.5)
    evidence = np.column_stack([p, np.where(good, 1.0, 0.5), np.where(good, 8.0, 0.5), length])
    cal = fit_calibration(evidence, good | (rng.random(n) < 0.3))
    short = length < SHORT_LABEL
    labeled = rng.random(n) < 0.5
    assert (cal(evidence)[good] >= 0.95).all()  # without labels, every strong segment earned it
    conf = cal(evidence, labeled=labeled)[good]
    short, labeled = short[good], labeled[good]
    assert (conf[short & labeled] < 0.95).all()
    assert (conf[short & ~labeled] >= 0.95).all() and (conf[~short] >= 0.95).all()


def test_short_marker_labels_do_not_count_against_the_sure_threshold():
    # 3-frame segments: 2,000 nulls, all right, and 40 marker labels, all wrong, with the same top
    # evidence (a ghost left out and a ghost taken for a marker look alike); then 2,000 weaker ones.
    # Counted, the 40 hold the top group below 99.9 %. They are never sure anyway, so told which
    # segments are labels, the fit makes the nulls sure.
    n, bad = 2000, 40
    p = np.concatenate([np.full(n + bad, 0.999), np.linspace(0.1, 0.9, 2000)])
    evidence = np.column_stack([p, np.ones(len(p)), np.full(len(p), 8.0), np.full(len(p), 3.0)])
    correct = np.concatenate([np.ones(n, bool), np.zeros(bad, bool), np.arange(2000) % 2 == 0])
    labeled = np.zeros(len(p), dtype=bool)
    labeled[n:n + bad] = True
    blind = fit_calibration(evidence, correct)
    told = fit_calibration(evidence, correct, labeled)
    assert not (blind(evidence, labeled) >= 0.95).any()
    sure = told(evidence, labeled) >= 0.95
    assert sure[:n].all() and not sure[n:].any()


def test_calibration_takes_vary_in_length_and_keep_their_truth():
    from training.confidence import FIT_FRAMES, MIN_FRAMES, validation_takes

    takes = validation_takes(load_layout("glove13"), 6, 500)
    lengths = [take.n_frames for take, _, _ in takes]
    assert all(MIN_FRAMES <= n <= 500 for n in lengths) and len(set(lengths)) == 6
    assert lengths == [take.n_frames for take, _, _ in validation_takes(load_layout("glove13"), 6, 500)]  # seeded
    for take, truth, markers in takes:
        assert truth.shape == take.positions.shape[:2] and len(markers) == take.n_frames + FIT_FRAMES


def test_calibration_takes_wear_the_glove_their_model_was_trained_for():
    from mocap_autolabel.core.labelers.onnx_labeler import load_card, shipped_model

    from training.confidence import glove_placement

    frames = load_card(shipped_model("set", "han19"))["training"]["recipe"]["frames"]
    assert glove_placement(load_layout("han19")) == {"placement_sd": frames["placement_sd"],
                                                     "tip_convergence": frames["tip_convergence"]}
    assert frames["placement_sd"] > 0 and frames["tip_convergence"] > 0
    assert glove_placement(load_layout("glove13")) == {"placement_sd": 0.0, "tip_convergence": 0.0}
    assert glove_placement(load_layout("tips5")) == {"placement_sd": 0.0, "tip_convergence": 0.0}  # no model


def test_vote_settings_are_refitted_until_the_switch_cost_is_stable(monkeypatch):
    import training.confidence as fit

    # A made-up share surface: the best switch cost is 500 below a prior of 4 nats and 300 above;
    # the best prior is 8, the best partner evidence (1, 4) and the best continuity (0, 4),
    # whatever the rest (the prior's term outweighs a switch cost fitted at another prior).
    def shares(data, layout, method, labelers, grid, **fixed):
        out = []
        for setting in grid:
            s = {"continuity": (0.0, 0.0), **fixed, **setting}
            target = 500.0 if s["null_prior"][0] < 4 else 300.0
            inside, outside = s["partner"]
            share = (99.0 - abs(s["switch_cost"][1] - target) / 100 - abs(s["null_prior"][0] - 8)
                     - (abs(inside - 1) + abs(outside - 4)) / 10 - abs(s["continuity"][1] - 4) / 10)
            out.append((share, 90.0 + share / 100))
        return out

    monkeypatch.setattr(fit, "vote_shares", shares)
    switch, prior, partner, continuity, tried = fit.fit_vote_settings([], None, "set", [], 0.0, (0.0, 0.0),
                                                                      (0.0, 0.0))
    # Fitted once, the switch cost would have stayed at 500 (chosen at the starting prior of 0).
    assert (switch, prior, partner, continuity) == (300.0, 8.0, (1.0, 4.0), (0.0, 4.0))
    assert set(tried) == {"switch_cost", "prior_partner", "continuity"}
    assert max(tried["switch_cost"], key=tried["switch_cost"].get) == 300.0
    assert max(tried["continuity"], key=tried["continuity"].get) == (0.0, 4.0)


def test_vote_settings_within_tolerance_of_the_best_instances():
    import training.confidence as fit

    tried = {(0.0, 2.0): (99.740, 97.59), (0.0, 4.0): (99.745, 97.69), (1.0, 4.0): (99.744, 97.69),
             (0.0, 8.0): (99.720, 97.80)}
    assert sorted(fit.near_best(tried)) == [(0.0, 2.0), (0.0, 4.0), (1.0, 4.0)]  # frames recorded, not used


def test_continuity_alone_is_refitted_at_the_shipped_vote_settings(tmp_path):
    import json
    import shutil

    from mocap_autolabel.core.temporal.confidence import CALIBRATIONS

    import training.confidence as fit

    out = tmp_path / "confidence.json"
    shutil.copy(CALIBRATIONS, out)
    before = json.loads(out.read_text())
    assert fit.main(["--layouts", "han19", "--only", "set/vote", "--fit", "continuity", "--takes", "2",
                     "--frames", "150", "--out", str(out)]) == 0
    after = json.loads(out.read_text())
    old, new = before["set/vote/han19"], after["set/vote/han19"]
    for kept in ("switch_cost", "null_prior", "partner", "switch_cost_tried", "prior_partner_tried"):
        assert new[kept] == old[kept], kept
    assert tuple(new["continuity"]) in fit.CONTINUITIES
    assert set(new["continuity_tried"]) == {str(list(c)) for c in fit.CONTINUITIES}
    assert new["source"].startswith("2 synthetic takes")
    assert {k: v for k, v in after.items() if k != "set/vote/han19"} == {
        k: v for k, v in before.items() if k != "set/vote/han19"}


@pytest.mark.slow
def test_empty_and_ghost_flooded_takes(han19, synth_take):
    empty = Take(positions=np.full((10, 3, 3), np.nan, dtype=np.float32), names=["*0", "*1", "*2"], rate=100.0,
                 source="empty.c3d")
    with pytest.raises(MocapInputError, match="empty.c3d: the take has no marker samples"):
        label_take(empty, han19)
    # Thousands of ghosts per frame: bounded work, the hand still labeled.
    rng = np.random.default_rng(1)
    hand = synth_take.take.positions[:30]
    ghosts = rng.uniform(-3, 3, size=(30, 3000, 3)).astype(np.float32)
    take = Take(positions=np.concatenate([hand, ghosts], axis=1), names=[f"*{i}" for i in range(hand.shape[1] + 3000)],
                rate=120.0)
    lab = label_take(take, han19)
    per = lab.per_sample()
    far = np.linalg.norm(ghosts - np.nanmean(hand, axis=1, keepdims=True), axis=2) > 0.3
    assert (per[:, hand.shape[1]:][far] == NULL).all()  # ghosts away from the hand: never labeled
    assert (per[:, :hand.shape[1]] >= 0).sum() > 0.9 * (synth_take.labels[:30] >= 0).sum()


def _conserved(take: Take, labeled: Take) -> None:
    assert labeled.valid.sum() == take.valid.sum()
    for f in range(0, take.n_frames, max(1, take.n_frames // 50)):
        a = np.sort(take.positions[f][take.valid[f]], axis=0)
        b = np.sort(labeled.positions[f][labeled.valid[f]], axis=0)
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("name", ["hands/qualisys_glove13/recording_part1.tsv",
                                  pytest.param("c3d/auto-marker-label/data/S01_Pronetokneel01_mksrem.c3d",
                                               marks=pytest.mark.slow)])
def test_every_sample_lands_in_exactly_one_output_point(name, tmp_path, han19):
    from mocap_autolabel.core.formats.c3d import write_c3d

    take = read_take(data_path(*name.split("/")))
    layout = load_layout("glove13") if "glove13" in name else han19
    lab = label_take(take, layout)
    out = labeled_take(take, lab)
    _conserved(take, out)
    path = tmp_path / "out.c3d"
    write_c3d(out, path)
    back = read_take(path)
    assert back.names[:len(layout)] == layout.names and back.valid.sum() == take.valid.sum()



def test_rigid_pairs_are_the_markers_that_keep_their_distance(han19):
    rigid = rigid_pairs(han19)
    pairs = {(han19.names[a], han19.names[b]) for a, b in rigid.pairs}
    assert {("ThumbIP", "ThumbTip"), ("ThumbTip", "ThumbIP"), ("BackHand1", "BackHand2")} <= pairs
    assert ("PinkyPIP", "PinkyTip") in pairs  # across the DIP joint, which bends with the PIP joint
    assert ("IndexMCP", "IndexPIP") not in pairs  # across the free MCP joint: the distance bends
    assert ("ThumbTip", "IndexTip") not in pairs
    assert len(pairs) == len(rigid) == 34  # 17 pairs, both orders
    tip, ip = han19.names.index("ThumbTip"), han19.names.index("ThumbIP")
    d = rigid.distance[(rigid.pairs[:, 0] == tip) & (rigid.pairs[:, 1] == ip)][0]
    assert 0.02 < d < 0.03
    assert not len(rigid_pairs(load_layout("tips5")))


def test_a_pair_labeled_together_long_enough_takes_the_takes_own_distance():
    rigid = RigidPairs(np.array([[0, 1], [1, 0], [0, 2], [2, 0], [0, 3], [3, 0]]),
                       np.array([0.03, 0.03, 0.03, 0.03, 0.08, 0.08]), np.full(6, 0.0085))
    frames = 40
    # Labels 0 and 1 are 35 mm apart in every frame (a larger hand); label 2 is seen in 10 frames;
    # label 3 is 85 mm from label 0 (a knuckle and the back of the hand).
    positions = np.zeros((frames, 4, 3))
    positions[:, 1, 0] = 0.035
    positions[:, 2, 1] = 0.05
    positions[:, 3, 2] = 0.085
    label = np.tile([0, 1, 2, 3], (frames, 1))
    label[10:, 2] = NULL
    frame = np.repeat(np.arange(frames), 4)
    own = take_distances(rigid, positions.reshape(-1, 3), frame, label.ravel(), 4, min_frames=30)
    assert np.allclose(own.distance, [0.035, 0.035, 0.03, 0.03, 0.085, 0.085])  # label 2: too few frames
    # Below the cap the tolerance is the usual one; a long pair at its own distance is capped,
    # while at the average hand's distance it keeps the share for hand size.
    assert np.allclose(own.tolerance[:4], TOLERANCE + TOLERANCE_SHARE * own.distance[:4])
    assert np.allclose(own.tolerance[4:], OWN_TOLERANCE)
    assert TOLERANCE + TOLERANCE_SHARE * 0.085 > OWN_TOLERANCE
    fewer = take_distances(rigid, positions.reshape(-1, 3), frame, label.ravel(), 4, min_frames=41)
    assert np.allclose(fewer.distance, [0.03, 0.03, 0.03, 0.03, 0.08, 0.08])
    assert np.allclose(fewer.tolerance, TOLERANCE + TOLERANCE_SHARE * fewer.distance)


def test_partner_evidence_counts_each_labeled_partner_at_its_distance():
    rigid = RigidPairs(np.array([[0, 1], [1, 0]]), np.array([0.03, 0.03]), np.array([0.005, 0.005]))
    # Frame 0: label 1 at the origin, a sample 31 mm away, one 60 mm away. Frame 1: no label 1.
    positions = np.array([[0.0, 0, 0], [0.031, 0, 0], [0.06, 0, 0], [0.03, 0, 0]])
    frame = np.array([0, 0, 0, 1])
    label = np.array([1, NULL, NULL, NULL])
    out = partner_logp(positions, frame, label, 3, rigid, inside=2.0, outside=1.0)
    assert out.shape == (4, 4)
    assert out[:, 0].tolist() == [0.0, 2.0, -1.0, 0.0]  # the partner itself is not its own partner
    assert (out[:, 1:] == 0).all()  # label 0 is never labeled here, so label 1 earns nothing; null never


def test_a_thumb_tip_read_as_null_is_labeled_at_its_rigid_distance_from_thumb_ip(han19):
    """A long trajectory that the labeler finds slightly more null than ThumbTip in every frame is
    left null by the vote alone, and labeled ThumbTip once it counts that it keeps its distance
    to the labeled ThumbIP."""
    from mocap_autolabel.core.labelers import pack_frames
    from mocap_autolabel.core.labelers.base import Labeler
    from mocap_autolabel.core.synth.generate import clean_config

    s = synthesize(han19, 300, seed=5, config=clean_config())
    tip = han19.names.index("ThumbTip")
    batch = pack_frames(s.take.positions, max_points=64)
    f, k = np.nonzero(batch.mask)
    of_position = {tuple(batch.points[a, b]): int(s.labels[a, batch.slots[a, b]]) for a, b in zip(f, k)}

    class TruthLabeler(Labeler):
        layout = han19

        def scores(self, points, mask):
            # Called on some of the take's frames (the vote scores every other frame of a
            # trajectory): each observation's truth is the take sample at its position.
            truth = np.full(mask.shape, -1)
            rows, cols = np.nonzero(mask)
            truth[rows, cols] = [of_position[tuple(points[r, c])] for r, c in zip(rows, cols)]
            p = np.full(points.shape[:2] + (len(han19) + 1,), 0.002)
            p[rows, cols, truth[rows, cols]] = 0.9
            thumb = mask & (truth == tip)
            p[thumb, tip], p[thumb, -1] = 0.4, 0.55
            return np.log(p)

    labeler = TruthLabeler()
    without = label_take(s.take, han19, LabelSettings(partner=(0.0, 0.0)), labeler=labeler)
    with_partner = label_take(s.take, han19, LabelSettings(partner=(2.0, 2.0)), labeler=labeler)
    slot = int(np.flatnonzero((s.labels == tip).any(axis=0))[0])
    assert set(without.per_sample()[:, slot].tolist()) == {NULL}
    assert set(with_partner.per_sample()[:, slot].tolist()) == {tip}
    assert with_partner.info["partner"] == [2.0, 2.0]
    assert _accuracy(with_partner, s.take, s.labels) == 1.0


def _continuity_case(gap: int = 5, held: int = 30):
    """Three labels moving together at 0.2 m/s on slots 2-4; label 0 on slot 0 until frame 30,
    hidden for ``gap`` frames, then back on slot 1 where the motion carries it, while a ghost on
    slot 5 flickers up 3 cm away. Returns the continuity_logp arguments (100 Hz)."""
    from mocap_autolabel.core.temporal.voting import Segments

    rate, back = 100.0, 30 + gap
    frames = back + 60
    t = np.arange(frames)[:, None] / rate * np.array([0.2, 0.0, 0.0])
    home = np.array([[0.0, 0, 0], [0.02, 0, 0], [0, 0.02, 0], [0, 0, 0.02]])
    rows = [(f, 0, 0, t[f] + home[0]) for f in range(30)]
    rows += [(f, 1, -1, t[f] + home[0]) for f in range(back, frames)]
    rows += [(f, 1 + k, k, t[f] + home[k]) for k in (1, 2, 3) for f in range(frames)]
    rows += [(f, 5, -1, t[f] + home[0] + [0, 0, 0.03]) for f in range(back, frames)]
    rows.sort(key=lambda r: (r[1], r[0]))
    frame = np.array([r[0] for r in rows])
    slot = np.array([r[1] for r in rows])
    label = np.array([r[2] for r in rows])
    positions = np.array([r[3] for r in rows])
    held_for = np.where(slot == 0, held, frames)
    tracklets = Segments(np.array([0, 1, 2, 3, 4, 5]), np.array([0, back, 0, 0, 0, back]),
                         np.array([30, frames, frames, frames, frames, frames]))
    return (positions, frame, slot, label, held_for, tracklets, 4, rate), frame, slot


def test_continuity_favours_the_trajectory_that_continues_a_hidden_marker():
    from mocap_autolabel.core.temporal.continuity import WINDOW, continuity_logp

    args, frame, slot = _continuity_case()
    logp = continuity_logp(*args, inside=1.0, outside=4.0)
    assert logp.shape == (len(frame), 5) and (logp[:, 4] == 0).all()
    start = (slot == 1) & (frame < 35 + WINDOW)
    assert (logp[start, 0] == 1.0).all()  # the marker back where its neighbours carried it
    assert (logp[(slot == 5) & (frame < 35 + WINDOW), 0] == -4.0).all()  # the ghost 3 cm off
    assert (logp[(slot == 1) & (frame >= 35 + WINDOW), 0] == 0).all()  # only the ends earn it
    # Labels held by their own trajectories across no gap are left alone.
    assert (logp[np.isin(slot, [2, 3, 4]), 1:4] == 0).all()


@pytest.mark.parametrize("case", [{"held": 5}, {"gap": 60}])
def test_continuity_needs_a_held_anchor_and_a_short_gap(case):
    from mocap_autolabel.core.temporal.continuity import continuity_logp

    args, frame, slot = _continuity_case(**case)
    # An anchor held a few frames (a ghost the first vote labeled) or a gap longer than
    # MAX_GAP_S says nothing.
    assert (continuity_logp(*args, inside=1.0, outside=4.0)[:, 0] == 0).all()
    assert (continuity_logp(*_continuity_case()[0], inside=0.0, outside=0.0) == 0).all()


def test_perm_and_cnn_vote_with_sets_settings_and_are_calibrated_at_them(tmp_path):
    """perm and cnn showed every segment as uncertain with calibrations made at no vote settings;
    they are now calibrated as set's are, at set's fitted vote settings, and say when (as on the
    validation takes) none of their segments can be rated confident."""
    import json
    import shutil

    from mocap_autolabel.core.temporal.confidence import CALIBRATIONS, load_calibration

    import training.confidence as fit

    shipped = json.loads(open(CALIBRATIONS, encoding="utf-8").read())
    for layout in ("han19", "glove13"):
        donor = shipped[f"set/vote/{layout}"]
        for method in ("perm", "cnn"):
            entry = shipped[f"{method}/vote/{layout}"]
            assert entry["vote_settings_from"] == "set/vote"
            for key in ("null_prior", "switch_cost", "partner", "continuity"):
                assert entry[key] == donor[key], (method, layout, key)
            assert entry["source"] == "64 synthetic takes of 150-2000 frames, seeds 50000+"
            assert load_calibration(method, "vote", layout).never_sure  # 73-90 % of segments right: no promise
    assert not load_calibration("set", "vote", "han19").never_sure
    demo = read_take(ROOT / "samples" / "demo_take.c3d")
    lab = label_take(demo, load_layout("han19"), LabelSettings(method="perm"))
    assert lab.info["null_prior"] == shipped["set/vote/han19"]["null_prior"] and lab.info["never_confident"]
    assert "never_confident" not in label_take(demo, load_layout("han19")).info
    out = tmp_path / "confidence.json"  # the training script's path for them, on two short takes
    shutil.copy(CALIBRATIONS, out)
    assert fit.main(["--layouts", "han19", "--only", "perm/vote", "--takes", "2", "--frames", "150",
                     "--out", str(out)]) == 0
    new = json.loads(out.read_text())["perm/vote/han19"]
    assert new["vote_settings_from"] == "set/vote" and new["switch_cost"] == shipped["set/vote/han19"]["switch_cost"]
    assert new["source"].startswith("2 synthetic takes")


def test_split_segments_matches_a_plain_split():
    """Vectorised splitting equals cutting each segment at the cuts strictly inside it."""
    from mocap_autolabel.core.temporal.voting import Segments, split_segments

    def plain(segments, cuts):
        out = []
        for s, a, b in zip(segments.slot.tolist(), segments.start.tolist(), segments.stop.tolist()):
            edges = sorted({a, b, *(c for c in cuts.get(s, ()) if a < c < b)})
            out += [(s, x, y) for x, y in zip(edges[:-1], edges[1:])]
        return out

    rng = np.random.default_rng(1)
    for _ in range(300):
        rows = []
        for s in range(int(rng.integers(1, 6))):
            f = 0
            for _ in range(int(rng.integers(1, 5))):
                a = f + int(rng.integers(0, 3))
                f = a + int(rng.integers(1, 8))
                rows.append((s, a, f))
        segments = Segments(*(np.array(c, dtype=np.int64) for c in zip(*rows)))
        cuts = {int(s): [int(x) for x in rng.integers(-2, 40, int(rng.integers(0, 6)))]
                for s in rng.integers(0, 7, int(rng.integers(1, 4)))}
        got = split_segments(segments, cuts)
        assert list(zip(got.slot.tolist(), got.start.tolist(), got.stop.tolist())) == plain(segments, cuts)


def _samples_of(labels: np.ndarray, valid: np.ndarray, own: np.ndarray) -> Samples:
    frame, slot = np.nonzero(valid)
    m = int(labels.max()) + 1
    logp = np.full((len(frame), m + 1), -9.0, dtype=np.float32)
    return Samples(frame=frame, slot=slot, logp=logp, label=own[frame, slot],
                   confidence=np.ones(len(frame), dtype=np.float32))


def test_doubtful_edges_are_cut_off_for_review_and_the_labels_stay():
    """A trajectory whose last frame the per-frame labeler gives another marker, and a swap the vote
    placed between scored frames: those frames become short segments of their own, with the same
    labels (never sure: too short), and the vote's segment lengths are kept for the next vote."""
    frames = 40
    labels = np.full((frames, 3), NULL, dtype=np.int16)
    labels[:, 0] = 0
    labels[:20, 1], labels[20:, 1] = 1, 2  # one trajectory: the vote changed its label at frame 20
    labels[:, 2] = NULL
    valid = np.ones((frames, 3), dtype=bool)
    split = np.zeros((frames, 3), dtype=bool)
    lab = segments_from_runs(["a", "b", "c"], labels, valid, {}, split=split)
    own = labels.astype(np.int32).copy()
    own[38:, 0] = 2  # the labeler calls the last two frames of slot 0 "c"
    cut = split_doubtful_edges(lab, _samples_of(labels, valid, own), stride=4)
    np.testing.assert_array_equal(cut.per_sample(), lab.per_sample())  # no label changes
    pieces = {(int(s), int(a), int(b)) for s, a, b in zip(cut.slot, cut.start, cut.stop)}
    assert {(0, 0, 38), (0, 38, 40)} <= pieces  # the disputed end
    assert {(1, 0, 17), (1, 17, 20), (1, 20, 23), (1, 23, 40)} <= pieces  # 3 unscored frames each side
    assert cut.held is not None and cut.held[(cut.slot == 0) & (cut.start == 38)][0] == 40
    assert split_doubtful_edges(lab, _samples_of(labels, valid, labels.astype(np.int32)), stride=1) is lab
