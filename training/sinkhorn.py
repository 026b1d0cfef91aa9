"""Sinkhorn with dustbins: the log-domain form that training differentiates, and the same
iterations in matrix-scaling form that the ONNX graphs run."""

from __future__ import annotations

import torch

#: Log-score standing in for "impossible" (finite: keeps logsumexp free of NaN in float32).
NEG = -1.0e4


def log_sinkhorn_dustbin(scores: torch.Tensor, obs_null: torch.Tensor, label_null: torch.Tensor,
                         mask: torch.Tensor, iters: int) -> torch.Tensor:
    """Optimal-transport couplings between observations and labels, each side with a dustbin.

    Args:
        scores: ``(B, K, M)`` observation-label affinities.
        obs_null: ``(B, K)`` affinity of each observation to "null" (ghost).
        label_null: ``(B, M)`` affinity of each label to "not observed" (occlusion).
        mask: ``(B, K)`` 1.0 for real observations, 0.0 for padding.
        iters: Sinkhorn iterations.

    Returns:
        ``(B, K + 1, M + 1)`` log-probabilities: row ``i < K`` is observation ``i``'s distribution over
        the M labels and null (sums to 1 for a real observation); row ``K`` holds, per label,
        the log-probability that it is not observed.
    """
    z, log_mu, log_nu, norm = _dustbin_problem(scores, obs_null, label_null, mask)
    u = torch.zeros_like(log_mu)
    v = torch.zeros_like(log_nu)
    for _ in range(iters):
        u = log_mu - torch.logsumexp(z + v[:, None, :], dim=2)
        v = log_nu - torch.logsumexp(z + u[:, :, None], dim=1)
    return z + u[:, :, None] + v[:, None, :] - norm[:, None, None]


def scaling_sinkhorn_dustbin(scores: torch.Tensor, obs_null: torch.Tensor, label_null: torch.Tensor,
                             mask: torch.Tensor, iters: int) -> torch.Tensor:
    """:func:`log_sinkhorn_dustbin` in its matrix-scaling form, for the exported graphs.

    The same iterations on ``exp(z - row max)``: sums and divisions instead of a logsumexp per
    step, a third faster in onnxruntime, where the log-domain loop was a quarter of the run time.
    Every column keeps a finite sum (the occlusion row holds ``exp(label_null - max)``), so
    nothing divides by zero; training keeps the log domain, whose gradients are safer.
    Padding rows come out as :data:`NEG`.
    """
    z, log_mu, log_nu, norm = _dustbin_problem(scores, obs_null, label_null, mask)
    shift = z.amax(dim=2, keepdim=True)
    kernel = torch.exp(z - shift)  # (B, K+1, M+1)
    mu, nu = torch.exp(log_mu), torch.exp(log_nu)
    a = torch.ones_like(mu)
    b = torch.ones_like(nu)
    for _ in range(iters):
        a = mu / (kernel * b[:, None, :]).sum(dim=2)
        b = nu / (kernel * a[:, :, None]).sum(dim=1)  # padding rows have mu = 0, so a = 0: no mass
    out = z - shift + torch.log(a)[:, :, None] + torch.log(b)[:, None, :] - norm[:, None, None]
    real = torch.cat([mask > 0.5, torch.ones_like(mask[:, :1], dtype=torch.bool)], dim=1)
    return torch.where(real[:, :, None], out, torch.full_like(out, NEG))


def _dustbin_problem(scores: torch.Tensor, obs_null: torch.Tensor, label_null: torch.Tensor,
                     mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The augmented log-kernel ``(B, K+1, M+1)``, its log-marginals and the log normaliser ``(B,)``."""
    b, k, m = scores.shape
    valid = mask > 0.5
    n = mask.sum(dim=1)  # (B,)
    # M as a tensor, not a Python number: an exported graph must not bake the label count in (set_any
    # labels layouts of any size with one graph).
    labels = torch.ones_like(label_null).sum(dim=1)  # (B,) = M
    norm = -torch.log(n + labels)  # (B,)
    top = torch.cat([scores, obs_null[:, :, None]], dim=2)
    top = torch.where(valid[:, :, None], top, torch.full_like(top, NEG))
    corner = torch.zeros_like(label_null[:, :1])
    bottom = torch.cat([label_null, corner], dim=1)[:, None, :]
    z = torch.cat([top, bottom], dim=1)  # (B, K+1, M+1)
    log_mu = torch.cat([torch.where(valid, norm[:, None].expand(b, k), torch.full_like(mask, NEG)),
                        (torch.log(labels) + norm)[:, None]], dim=1)
    log_nu = torch.cat([norm[:, None].expand(b, m), (torch.log(n) + norm)[:, None]], dim=1)
    return z, log_mu, log_nu, norm
