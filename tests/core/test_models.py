"""The shipped ONNX models: cards, checksums, invariances, errors; torch vs onnxruntime agreement."""

from __future__ import annotations

import hashlib
import json
import shutil

import numpy as np
import pytest
from mocap_autolabel.core.errors import MocapInputError
from mocap_autolabel.core.labelers import ONNX_METHODS, assign, make_labeler
from mocap_autolabel.core.labelers.onnx_labeler import OnnxLabeler, card_path, shipped_model
from mocap_autolabel.core.layout import load_layout
from mocap_autolabel.core.metrics import score_labeling
from mocap_autolabel.core.rotations import random_rotations
from mocap_autolabel.core.synth.frames import FrameConfig, sample_frames

SHIPPED = [(m, layout) for layout in ("han19", "glove13") for m in ONNX_METHODS]


@pytest.mark.parametrize(("method", "layout_name"), SHIPPED)
def test_shipped_model_card_matches_layout_and_file(method, layout_name):
    path = shipped_model(method, layout_name)
    card = json.load(open(card_path(path)))
    assert card["method"] == method
    assert card["layout"]["labels"] == load_layout(layout_name).names
    assert card["sha256"] == hashlib.sha256(open(path, "rb").read()).hexdigest()
    assert card["training"]["data"].startswith("synthetic")
    assert 0 < card["metrics"]["train_seconds"] < 30 * 60  # the 30-minute budget on 2 cores
    make_labeler(method, load_layout(layout_name))  # loads


@pytest.mark.parametrize("method", ONNX_METHODS)
def test_shipped_models_label_synthetic_frames(method):
    layout = load_layout("han19")
    cfg = FrameConfig(drop=(0, 2), ghosts=(0, 1), distractor_share=0.0)
    fr = sample_frames(layout, 400, np.random.default_rng(123), cfg)
    labels, conf = make_labeler(method, layout).label_points(fr.points, fr.mask)
    s = score_labeling(labels, fr.labels, fr.mask, len(layout))
    # Far above chance (1/20); the benchmark reports the real figures.
    assert s.accuracy > {"set": 0.8, "cnn": 0.4, "perm": 0.25}[method]
    assert ((conf >= 0) & (conf <= 1)).all()


def test_set_is_invariant_to_rotation_translation_mirroring_and_order():
    layout = load_layout("glove13")
    fr = sample_frames(layout, 64, np.random.default_rng(7))
    labeler = make_labeler("set", layout)
    base = labeler.scores(fr.points, fr.mask)
    rng = np.random.default_rng(8)
    rot = random_rotations(rng, 64) * np.array([-1.0, 1.0, 1.0])  # improper: mirrors, as a right hand does
    moved = ((rot[:, None] @ fr.points[..., None].astype(np.float64))[..., 0] + rng.normal(size=(64, 1, 3))).astype(
        np.float32)
    order = np.argsort(rng.random(fr.mask.shape) + ~fr.mask * 2, axis=1)
    shuffled = np.take_along_axis(moved, order[..., None], axis=1)
    mask = np.take_along_axis(fr.mask, order, axis=1)
    out = labeler.scores(shuffled, mask)
    back = np.empty_like(out)
    np.put_along_axis(back, order[..., None], out, axis=1)
    valid = fr.mask
    # Invariant by construction; what differs is float32 rounding of the rotated inputs, which the
    # sharpest attention logits amplify to a few 1e-3 of probability (shipped models: up to 3e-3).
    assert np.abs(np.exp(back[valid]) - np.exp(base[valid])).max() < 5e-3
    a, _ = assign(base, valid)
    b, _ = assign(back, valid)
    assert (a == b).mean() > 0.99


@pytest.mark.parametrize("method", ONNX_METHODS)
def test_scores_do_not_depend_on_padding_or_batch_order(method):
    """The labeler runs frames in batches of like size, each cut to its widest frame: the same
    frames padded wider, with their observations scattered among the padding, score the same."""
    layout = load_layout("han19")
    fr = sample_frames(layout, 300, np.random.default_rng(11), FrameConfig(drop=(0, 5), ghosts=(0, 3)))
    labeler = make_labeler(method, layout)
    labeler.batch = 64
    base = labeler.scores(fr.points, fr.mask)
    n, k = fr.mask.shape
    wide = np.zeros((n, k + 9, 3), dtype=np.float32)
    cols = np.sort(np.random.default_rng(12).permuted(np.tile(np.arange(k + 9), (n, 1)), axis=1)[:, :k], axis=1)
    np.put_along_axis(wide, cols[..., None], fr.points, axis=1)
    mask = np.zeros((n, k + 9), dtype=bool)
    np.put_along_axis(mask, cols, fr.mask, axis=1)
    out = labeler.scores(wide, mask)
    back = np.take_along_axis(out, cols[..., None], axis=1)
    assert np.allclose(back[fr.mask], base[fr.mask], atol=1e-5)


@pytest.mark.parametrize("method", ONNX_METHODS)
def test_frames_with_fewer_points_than_the_models_neighbourhood_are_scored(method):
    """``set`` looks at 8 nearest neighbours; frames (and whole takes) with fewer points work."""
    layout = load_layout("han19")
    fr = sample_frames(layout, 40, np.random.default_rng(13), FrameConfig(drop=(13, 17), ghosts=(0, 0),
                                                                               distractor_share=0.0))
    few = fr.points[:, :6], fr.mask[:, :6]
    scores = make_labeler(method, layout).scores(*few)
    assert scores.shape == (40, 6, len(layout) + 1) and np.isfinite(scores[few[1]]).all()


def test_model_errors_name_the_file(tmp_path):
    layout = load_layout("han19")
    src = shipped_model("set", "han19")
    with pytest.raises(MocapInputError, match="model file not found") as e:
        OnnxLabeler(tmp_path / "none.onnx", layout)
    assert "none.onnx" in str(e.value)
    # Corrupt: bytes changed after the card was written.
    bad = tmp_path / "bad.onnx"
    data = bytearray(open(src, "rb").read())
    data[len(data) // 2] ^= 0xFF
    bad.write_bytes(bytes(data))
    shutil.copy(card_path(src), card_path(bad))
    with pytest.raises(MocapInputError, match="corrupt"):
        OnnxLabeler(bad, layout)
    # Garbage with a matching checksum: onnxruntime refuses it, one clear line.
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    card = json.load(open(card_path(src)))
    card["sha256"] = hashlib.sha256(b"not a model").hexdigest()
    (tmp_path / "junk.json").write_text(json.dumps(card))
    with pytest.raises(MocapInputError, match="not a usable ONNX model"):
        OnnxLabeler(junk, layout)
    # Another layout's model.
    with pytest.raises(MocapInputError, match="for layout 'glove13'") as e:
        OnnxLabeler(shipped_model("set", "glove13"), layout)
    assert "set_glove13.onnx" in str(e.value)
    # No card.
    lone = tmp_path / "lone.onnx"
    shutil.copy(src, lone)
    with pytest.raises(MocapInputError, match="card lone.json is missing"):
        OnnxLabeler(lone, layout)
    # A perm model asked for as set.
    with pytest.raises(MocapInputError, match="'perm' model, not 'set'"):
        make_labeler("set", layout, model=shipped_model("perm", "han19"))


@pytest.mark.parametrize(("method", "model"), [(m, {}) for m in ONNX_METHODS] + [("set", {"queries": 1})])
def test_onnxruntime_agrees_with_torch(method, model, tmp_path):
    torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch==2.13.0)")
    pytest.importorskip("onnx", reason="onnx is not installed")
    from training.inputs import get_method

    torch.manual_seed(0)
    layout = load_layout("glove13")
    m = get_method(method, layout.names, **model)
    net = m.build().eval()
    fr = sample_frames(layout, 96, np.random.default_rng(0))
    path = str(tmp_path / f"{method}.onnx")
    m.export(net, fr[:4], path)
    import onnxruntime as ort

    inputs, _ = m.feeds(fr)
    with torch.no_grad():
        expected = m.export_module(net)(*inputs).numpy()
    got = ort.InferenceSession(path).run(None, {n: t.numpy() for n, t in zip(m.input_names, inputs)})[0]
    assert got.shape == expected.shape
    if method == "set":
        expected, got = expected[fr.mask], got[fr.mask]  # padded rows are not outputs
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-4)


def test_the_layout_conditioned_model_runs_in_onnxruntime_as_in_torch_for_any_layout(tmp_path):
    torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch==2.13.0)")
    pytest.importorskip("onnx", reason="onnx is not installed")
    from training.any_layout import AnyRecipe, build, export_any, feeds
    from training.models import ObservationScores

    torch.manual_seed(0)
    recipe = AnyRecipe(model={"dim": 32, "hidden": 64, "layers": 2, "queries": 1, "label_layers": 1})
    net = build(recipe).eval()
    path = tmp_path / "set_any.onnx"
    export_any(net, recipe, {"null_offset": 0.0}, str(path))
    for name in ("tips3", "tips5_hand3", "han19"):  # one graph, label sets of any size
        layout = load_layout(name)
        fr = sample_frames(layout, 32, np.random.default_rng(1))
        with torch.no_grad():
            expected = ObservationScores(net)(*feeds(fr, layout)).numpy()
        got = OnnxLabeler(path, layout).scores(fr.points, fr.mask)  # the labeler feeds the layout's descriptors
        assert got.shape == (32, fr.points.shape[1], len(layout) + 1)
        np.testing.assert_allclose(got[fr.mask], expected[fr.mask], rtol=1e-4, atol=1e-4)
    with pytest.raises(MocapInputError, match="labels any layout: name the layout"):
        OnnxLabeler(path)


def test_scaling_sinkhorn_matches_the_log_domain_one():
    """The exported graphs run Sinkhorn in matrix-scaling form; it must equal the log-domain form
    that training differentiates, also for the wide score ranges of trained models and padding."""
    torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch==2.13.0)")
    from training.sinkhorn import NEG, log_sinkhorn_dustbin, scaling_sinkhorn_dustbin

    gen = torch.Generator().manual_seed(0)
    b, k, m = 64, 24, 19
    scores = torch.randn(b, k, m, generator=gen) * 12.0  # logits spanning about 100 nats
    obs_null = torch.randn(b, k, generator=gen) * 6.0
    label_null = torch.randn(b, m, generator=gen) * 3.0
    mask = (torch.rand(b, k, generator=gen) < 0.8).float()
    mask[:, 0] = 1.0
    mask[0] = 1.0  # a frame with no padding
    expected = log_sinkhorn_dustbin(scores, obs_null, label_null, mask, 10)
    got = scaling_sinkhorn_dustbin(scores, obs_null, label_null, mask, 10)
    real = torch.cat([mask > 0.5, torch.ones(b, 1, dtype=torch.bool)], dim=1)
    assert torch.isfinite(got).all()
    np.testing.assert_allclose(got[real].numpy(), expected[real].numpy(), rtol=1e-4, atol=2e-4)
    assert (got[~real] == NEG).all()


def test_training_batches_group_frames_of_similar_size_and_use_each_frame_once():
    pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch==2.13.0)")
    from training.train import _batches

    layout = load_layout("han19")
    pool = sample_frames(layout, 1000, np.random.default_rng(0))  # distractors in half of the frames
    batches = _batches(pool, 100, np.random.default_rng(1))
    assert len(batches) == 10 and all(len(b) == 100 for b in batches)
    seen = np.concatenate([b.points[:, 0, 0] for b in batches])
    np.testing.assert_array_equal(np.sort(seen), np.sort(pool.points[:, 0, 0]))  # a partition of the pool
    counts = [b.mask.sum(axis=1) for b in batches]
    spread = [int(c.max() - c.min()) for c in counts]
    assert max(spread) < int(pool.mask.sum(axis=1).max() - pool.mask.sum(axis=1).min())
    means = [float(c.mean()) for c in counts]
    assert means != sorted(means)  # batch order is shuffled, not small to large


def _unfloored(model):
    """``model`` with :func:`training.subnormals.floor_radial_exponents`' edit taken out again."""
    floors = {n.output[0]: n.input[0] for n in model.graph.node if n.op_type == "Max" and n.name.endswith("_floor")}
    kept = [n for n in model.graph.node if n.output[0] not in floors]
    for n in kept:
        n.input[:] = [floors.get(i, i) for i in n.input]
    del model.graph.node[:]
    model.graph.node.extend(kept)
    return model


@pytest.mark.parametrize(("layout_name", "model_layout"), [("han19", "han19"), ("glove13", "glove13"),
                                                           ("tips5_hand3", "any")])
def test_the_set_models_radial_bases_are_floored_and_score_as_without_the_floor(layout_name, model_layout, tmp_path):
    """Subnormal floats are many times slower to compute with; the floor must not change a score."""
    onnx = pytest.importorskip("onnx", reason="onnx is not installed")
    from training.subnormals import floor_radial_exponents, radial_exps

    path = shipped_model("set", model_layout)
    shipped = onnx.load(path)
    assert not radial_exps(shipped.graph)  # every radial basis of the shipped graph is floored
    assert floor_radial_exponents(shipped) == 0
    plain = _unfloored(onnx.load(path))
    assert radial_exps(plain.graph)  # the test takes the edit out: it sees the floors it must see
    card = json.load(open(card_path(path)))
    unfloored = tmp_path / "unfloored.onnx"
    onnx.save(plain, unfloored)
    card["sha256"] = hashlib.sha256(open(unfloored, "rb").read()).hexdigest()
    json.dump(card, open(card_path(unfloored), "w"))
    layout = load_layout(layout_name)
    # Hands far apart and ghosts far off: pair distances far beyond the bases' centres.
    fr = sample_frames(layout, 64, np.random.default_rng(5), FrameConfig(ghosts=(2, 4), distractor_share=1.0,
                                                                       distractors=(4, 8)))
    got = OnnxLabeler(path, layout).scores(fr.points, fr.mask)[fr.mask]
    expected = OnnxLabeler(unfloored, layout).scores(fr.points, fr.mask)[fr.mask]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-4)
    assert (got.argmax(axis=-1) == expected.argmax(axis=-1)).all()


def test_the_networks_radial_bases_never_underflow_into_subnormal_floats():
    torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install torch==2.13.0)")
    from training.models import SetLabeler
    from training.subnormals import RBF_EXPONENT_FLOOR

    net = SetLabeler(5)
    dist = torch.tensor([[[0.0, 0.02, 1.5], [0.02, 0.0, 3.0], [1.5, 3.0, 0.0]]])  # metres: near and far pairs
    _, rbf = net.pair_terms(dist, net.pair, None)
    rbf = rbf.numpy()
    assert rbf.min() >= np.float32(np.exp(RBF_EXPONENT_FLOOR)) > np.finfo(np.float32).tiny
    assert rbf.max() > 0.5  # near pairs still read as near
