"""Log-domain Sinkhorn with dustbins, as exported into the ONNX graphs."""

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
    b, k, m = scores.shape
    valid = mask > 0.5
    n = mask.sum(dim=1)  # (B,)
    norm = -torch.log(n + m)  # (B,)
    top = torch.cat([scores, obs_null[:, :, None]], dim=2)
    top = torch.where(valid[:, :, None], top, torch.full_like(top, NEG))
    corner = torch.zeros_like(label_null[:, :1])
    bottom = torch.cat([label_null, corner], dim=1)[:, None, :]
    z = torch.cat([top, bottom], dim=1)  # (B, K+1, M+1)
    log_mu = torch.cat([torch.where(valid, norm[:, None].expand(b, k), torch.full_like(mask, NEG)),
                        (torch.log(torch.full_like(n, float(m))) + norm)[:, None]], dim=1)
    log_nu = torch.cat([norm[:, None].expand(b, m), (torch.log(n) + norm)[:, None]], dim=1)
    u = torch.zeros_like(log_mu)
    v = torch.zeros_like(log_nu)
    for _ in range(iters):
        u = log_mu - torch.logsumexp(z + v[:, None, :], dim=2)
        v = log_nu - torch.logsumexp(z + u[:, :, None], dim=1)
    return z + u[:, :, None] + v[:, None, :] - norm[:, None, None]
