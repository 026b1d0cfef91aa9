"""The networks behind the ONNX labelers. Input conventions are recorded in each model's card."""

from __future__ import annotations

import math

import torch
from torch import nn

from .sinkhorn import NEG, log_sinkhorn_dustbin, scaling_sinkhorn_dustbin
from .subnormals import RBF_EXPONENT_FLOOR


class PairBiasAttention(nn.Module):
    """Multi-head self-attention whose logits get a per-head bias from pairwise geometry."""

    def __init__(self, dim: int, heads: int, rbf: int):
        super().__init__()
        self.heads, self.head_dim = heads, dim // heads
        self.qkv = nn.Linear(dim, 3 * dim)
        self.out = nn.Linear(dim, dim)
        self.geometry = nn.Linear(heads * rbf, dim, bias=False)

    def forward(self, x: torch.Tensor, bias: torch.Tensor, rbf: torch.Tensor) -> torch.Tensor:
        """``rbf``: ``(B, K, K, R)`` encoded pair distances; each head also reports the distances it attended to."""
        b, k, d = x.shape
        qkv = self.qkv(x).reshape(b, k, 3, self.heads, self.head_dim).permute(2, 0, 3, 1, 4)
        q, key, v = qkv[0], qkv[1], qkv[2]  # (B, H, K, dh)
        logits = q @ key.transpose(-1, -2) * (1.0 / math.sqrt(self.head_dim)) + bias
        att = torch.softmax(logits, dim=-1)
        seen = (att.transpose(1, 2) @ rbf).reshape(b, k, -1)  # (B, K, H*R): attention-weighted distance profile
        return self.out((att @ v).transpose(1, 2).reshape(b, k, d)) + self.geometry(seen)


class Block(nn.Module):
    def __init__(self, dim: int, heads: int, hidden: int, rbf: int):
        super().__init__()
        self.norm1, self.norm2 = nn.LayerNorm(dim), nn.LayerNorm(dim)
        self.att = PairBiasAttention(dim, heads, rbf)
        self.ffn = nn.Sequential(nn.Linear(dim, hidden), nn.ReLU(), nn.Linear(hidden, dim))

    def forward(self, x: torch.Tensor, bias: torch.Tensor, rbf: torch.Tensor) -> torch.Tensor:
        x = x + self.att(self.norm1(x), bias, rbf)
        return x + self.ffn(self.norm2(x))


class LabelQueries(nn.Module):
    """Cross-attention of the label vectors over the observations: each label looks for its point
    in this frame, so that its scores (and its cost of staying empty) depend on the frame."""

    def __init__(self, dim: int, heads: int, hidden: int):
        super().__init__()
        self.heads, self.head_dim = heads, dim // heads
        self.norm_q = nn.LayerNorm(dim)
        self.q = nn.Linear(dim, dim)
        self.out = nn.Linear(dim, dim)

    def forward(self, labels: torch.Tensor, x: torch.Tensor, padding: torch.Tensor) -> torch.Tensor:
        """``labels`` ``(B or 1, M, D)``, ``x`` ``(B, K, D)`` (normalised), ``padding`` ``(B, 1, 1, K)``
        additive bias. Returns ``(B, M, D)``."""
        b, k, d = x.shape
        m = labels.shape[1]
        # The first block's labels are the same in every frame: its query is computed once. Keys and
        # values are the points' own (normalised) vectors, split in heads: no projections, since
        # this block must cost little next to the point blocks.
        q = self.q(self.norm_q(labels)).reshape(labels.shape[0], m, self.heads, self.head_dim).transpose(1, 2)
        kv = x.reshape(b, k, self.heads, self.head_dim).transpose(1, 2)  # (B, H, K, dh)
        att = torch.softmax(q @ kv.transpose(-1, -2) * (1.0 / math.sqrt(self.head_dim)) + padding, dim=-1)
        return labels + self.out((att @ kv).transpose(1, 2).reshape(b, m, d))


class SetLabeler(nn.Module):
    """``set``: attention over the observed point set, invariant to order, rotation, translation and mirroring.

    Geometry enters only through distances: each point's distances to its nearest neighbours and
    to the centroid (its features), and radial-basis-encoded pairwise distances (attention biases).
    With ``queries`` > 0, the label vectors then attend over the points (:class:`LabelQueries`), so
    that each label's scores and its cost of staying empty fit the frame. Scores against the labels
    and the two dustbins go through a log-domain Sinkhorn.

    Input: ``points`` float32 ``(B, K, 3)`` metres, ``mask`` float32 ``(B, K)``, ``axes`` float32
    ``(B, 3, 3)`` principal axes of the frame (only |coordinates| on them are used).
    Output: ``(B, K + 1, M + 1)`` log-probabilities (see :func:`log_sinkhorn_dustbin`).
    """

    def __init__(self, n_labels: int, dim: int = 48, heads: int = 4, layers: int = 3, hidden: int = 96,
                 knn: int = 8, rbf: int = 16, rbf_max: float = 0.24, iters: int = 10, queries: int = 0):
        super().__init__()
        self.n_labels, self.knn, self.iters, self.heads, self.layers = n_labels, knn, iters, heads, layers
        self.register_buffer("centres", torch.linspace(0.0, rbf_max, rbf))
        self.width = rbf_max / (rbf - 1)
        self.embed = nn.Sequential(nn.Linear(knn + 5, dim), nn.ReLU(), nn.Linear(dim, dim))
        self.pair = nn.Linear(rbf, heads * layers)  # one linear map: the (B, K, K) pair tensors dominate run time
        self.blocks = nn.ModuleList(Block(dim, heads, hidden, rbf) for _ in range(layers))
        self.norm = nn.LayerNorm(dim)
        self.project = nn.Linear(dim, dim)
        self.labels = nn.Parameter(torch.randn(n_labels, dim) * 0.1)
        self.obs_null = nn.Linear(dim, 1)
        self.label_null = nn.Parameter(torch.zeros(n_labels))
        self.queries = nn.ModuleList(LabelQueries(dim, heads, hidden) for _ in range(queries))
        if queries:
            self.query_null = nn.Linear(dim, 1)

    def forward(self, points: torch.Tensor, mask: torch.Tensor, axes: torch.Tensor,
                sinkhorn=log_sinkhorn_dustbin) -> torch.Tensor:
        """``axes``: ``(B, 3, 3)`` principal axes of each frame's cloud (columns, largest variance first);
        ``sinkhorn``: its log-domain form (training) or the scaling form (export), same result."""
        x = self.encode_points(points, mask, axes)
        return self.match(x, mask, self.labels[None], self.label_null[None], sinkhorn)

    def encode_points(self, points: torch.Tensor, mask: torch.Tensor, axes: torch.Tensor) -> torch.Tensor:
        """The observations' vectors ``(B, K, D)``, normalised, from their geometry alone."""
        b, k, _ = points.shape
        n = mask.sum(dim=1, keepdim=True)
        centroid = (points * mask[:, :, None]).sum(1, keepdim=True) / n[:, :, None]
        centred = points - centroid  # distances are exact either way; centring keeps float32 precise
        sq = (centred * centred).sum(-1)
        dist = torch.sqrt(torch.relu(sq[:, :, None] + sq[:, None, :] - 2.0 * centred @ centred.transpose(1, 2)) + 1e-12)
        pair_ok = mask[:, :, None] * mask[:, None, :]
        far = torch.where(pair_ok > 0.5, dist, torch.full_like(dist, 1.0))
        far = far + torch.eye(k, dtype=dist.dtype, device=dist.device)[None] * 1.0  # a point is not its own neighbour
        near = torch.topk(far, min(self.knn, k), dim=2, largest=False).values
        if k < self.knn:
            near = torch.cat([near, torch.ones(b, k, self.knn - k, dtype=near.dtype, device=near.device)], dim=2)
        radial = torch.sqrt(sq + 1e-12)
        # |coordinates| on the principal axes: blind to the axes' arbitrary signs (and to mirroring).
        canon = torch.abs(centred @ axes) * 10.0
        feats = torch.cat([torch.clamp(near, max=0.3) * 10.0, (radial * 10.0)[:, :, None],
                           torch.log(n)[:, :, None].expand(b, k, 1), canon], dim=2)
        x = self.embed(feats)
        bias, rbf = self.pair_terms(dist, self.pair, mask)
        for i, block in enumerate(self.blocks):
            x = block(x, bias[:, i * self.heads:(i + 1) * self.heads], rbf)
        return self.norm(x)

    def pair_terms(self, dist: torch.Tensor, pair: nn.Linear,
                   mask: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """Attention biases ``(B, heads * layers, K, K)`` and radial bases ``(B, K, K, R)`` of pair distances."""
        b, k = dist.shape[0], dist.shape[1]
        # Radial basis of every pair distance, laid out (B, R, K*K) so that the per-head biases are
        # one matrix product with no transposes (the pair tensors dominate the run time).
        scaled = dist.reshape(b, 1, k * k) * (1.0 / self.width) - (self.centres / self.width)[None, :, None]
        # Floored: far from a centre the basis underflows into subnormal floats, many times slower to
        # compute with on CPUs and no signal (training/subnormals.py).
        rbf = torch.exp(torch.clamp(-scaled * scaled, min=RBF_EXPONENT_FLOOR))  # (B, R, K*K)
        bias = (pair.weight @ rbf + pair.bias[None, :, None]).reshape(b, -1, k, k)
        rbf = rbf.transpose(1, 2).reshape(b, k, k, -1)
        if mask is not None:
            bias = bias + (1.0 - mask)[:, None, None, :] * NEG  # no attention to padding
        return bias, rbf

    def match(self, x: torch.Tensor, mask: torch.Tensor, labels: torch.Tensor, label_null: torch.Tensor,
              sinkhorn=log_sinkhorn_dustbin) -> torch.Tensor:
        """Scores of observations ``x`` ``(B, K, D)`` against ``labels`` ``(1, M, D)`` (costs of staying
        empty ``label_null`` ``(1, M)``), through the Sinkhorn with dustbins: ``(B, K + 1, M + 1)``."""
        b = x.shape[0]
        label_null = label_null.expand(b, -1)
        if len(self.queries):
            padding = ((1.0 - mask) * NEG)[:, None, None, :]
            for q in self.queries:
                labels = q(labels, x, padding)
            label_null = label_null + self.query_null(labels)[..., 0]
        scores = self.project(x) @ labels.transpose(1, 2) * (1.0 / math.sqrt(x.shape[-1]))
        return sinkhorn(scores, self.obs_null(x)[..., 0], label_null, mask, self.iters)


#: Hand length (metres) that turns a descriptor's rest position back into distances.
DESCRIPTOR_HAND_LENGTH = 0.19


class AnyLayoutLabeler(SetLabeler):
    """``set`` for any layout: each label's vector is computed from where its marker sits on the
    template hand (:func:`mocap_autolabel.core.layout.marker_descriptors`), not learned per label.

    The descriptors pass a small attention encoder over the layout's own markers (biased by their
    rest distances), so that a label knows its neighbours in this layout: a fingertip's vector
    differs where the layout also has the knuckle below it. Trained on random layouts
    (:mod:`mocap_autolabel.core.synth.layouts`), one per batch.

    Input: as :class:`SetLabeler`, plus ``layout`` float32 ``(M, F)`` descriptors. Output:
    ``(B, K + 1, M + 1)`` log-probabilities.
    """

    def __init__(self, descriptor: int, label_layers: int = 2, **kw):
        super().__init__(1, **kw)
        del self.labels, self.label_null
        dim, heads, hidden = self.norm.normalized_shape[0], self.heads, self.blocks[0].ffn[0].out_features
        rbf = self.centres.shape[0]
        self.label_embed = nn.Sequential(nn.Linear(descriptor, dim), nn.ReLU(), nn.Linear(dim, dim))
        self.label_pair = nn.Linear(rbf, heads * label_layers)
        self.label_blocks = nn.ModuleList(Block(dim, heads, hidden, rbf) for _ in range(label_layers))
        self.label_norm = nn.LayerNorm(dim)
        self.label_null_head = nn.Linear(dim, 1)

    def encode_layout(self, layout: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Label vectors ``(1, M, D)`` and costs of staying empty ``(1, M)`` of descriptors ``(M, F)``."""
        rest = layout[None, :, :3] * DESCRIPTOR_HAND_LENGTH
        diff = rest[:, :, None, :] - rest[:, None, :, :]
        dist = torch.sqrt((diff * diff).sum(-1) + 1e-12)
        bias, rbf = self.pair_terms(dist, self.label_pair, None)
        y = self.label_embed(layout)[None]
        for i, block in enumerate(self.label_blocks):
            y = block(y, bias[:, i * self.heads:(i + 1) * self.heads], rbf)
        y = self.label_norm(y)
        return y, self.label_null_head(y)[..., 0]

    def forward(self, points: torch.Tensor, mask: torch.Tensor, axes: torch.Tensor, layout: torch.Tensor,
                sinkhorn=log_sinkhorn_dustbin) -> torch.Tensor:
        labels, label_null = self.encode_layout(layout)
        return self.match(self.encode_points(points, mask, axes), mask, labels, label_null, sinkhorn)


class ObservationScores(nn.Module):
    """Export wrapper of :class:`SetLabeler`: the scaling-form Sinkhorn, and only the observation
    rows, ``(B, K, M + 1)``, the labeler protocol's scores."""

    def __init__(self, net: SetLabeler):
        super().__init__()
        self.net = net

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        return self.net(*inputs, sinkhorn=scaling_sinkhorn_dustbin)[:, :-1, :]


def sinkhorn_normalise(d: torch.Tensor, iters: int) -> torch.Tensor:
    """Alternate row and column normalisation of a positive ``(B, S, S)`` matrix (Ghorbani: 5 iterations)."""
    for _ in range(iters):
        d = d / d.sum(dim=2, keepdim=True)
        d = d / d.sum(dim=1, keepdim=True)
    return d


class PermLabeler(nn.Module):
    """``perm`` (Ghorbani 2019): a residual MLP from S canonical slots to an S x S permutation.

    Three residual blocks of three dense layers with Leaky ReLU; a sigmoid, then 5 Sinkhorn
    iterations. Columns are the M labels then S - M null columns.
    Input ``x`` float32 ``(B, S, 3)``; output log of the doubly stochastic matrix ``(B, S, S)``.
    """

    def __init__(self, n_labels: int, slots: int, width: int = 256, iters: int = 5):
        super().__init__()
        self.slots, self.iters = slots, iters
        self.inp = nn.Linear(3 * slots, width)
        self.blocks = nn.ModuleList(
            nn.Sequential(nn.Linear(width, width), nn.LeakyReLU(0.2), nn.Linear(width, width), nn.LeakyReLU(0.2),
                          nn.Linear(width, width)) for _ in range(3))
        self.act = nn.LeakyReLU(0.2)
        self.out = nn.Linear(width, slots * slots)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.act(self.inp(x.reshape(x.shape[0], -1)))
        for block in self.blocks:
            h = self.act(h + block(h))
        d = torch.sigmoid(self.out(h).reshape(-1, self.slots, self.slots)) + 1e-6
        return torch.log(sinkhorn_normalise(d, self.iters))


class DepthCNN(nn.Module):
    """``cnn`` (Han 2018): VGG-style convolutions on the 52 x 52 depth image, regressing M positions.

    Han's widths (64-64-pool-128-128-128-pool, FC 2048) are quartered and a third pool added so
    that training fits the 30-minute CPU budget; the structure is the paper's.
    Input ``image`` ``(B, 1, 52, 52)``; output ``(B, 3M)`` canonical coordinates.
    """

    def __init__(self, n_labels: int, width: int = 16, hidden: int = 512):
        super().__init__()
        w = width

        def conv(a: int, b: int) -> list:
            return [nn.Conv2d(a, b, 3, padding=1), nn.ReLU()]

        self.features = nn.Sequential(*conv(1, w), *conv(w, w), nn.MaxPool2d(2),
                                      *conv(w, 2 * w), *conv(2 * w, 2 * w), *conv(2 * w, 2 * w), nn.MaxPool2d(2),
                                      nn.MaxPool2d(2))
        self.head = nn.Sequential(nn.Flatten(), nn.Linear(2 * w * 6 * 6, hidden), nn.ReLU(),
                                  nn.Linear(hidden, 3 * n_labels))

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(image))
