"""The training loss: 3D-GS photometric loss plus cross-entropy on the object features."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from gsseg.train.ssim_cpu import SSIM_SIGMA, SSIM_WINDOW, mean_ssim_cpu


def photometric_loss(rendered: torch.Tensor, target: torch.Tensor, lambda_dssim: float) -> torch.Tensor:
    """(1 - lambda) L1 + lambda (1 - SSIM) of two (H, W, 3) images, ``target`` a constant: the
    mean SSIM of :func:`ssim_map`, for float32 on the CPU by the numba kernels of
    :mod:`gsseg.train.ssim_cpu` (the same value and gradient in half the time)."""
    if rendered.device.type == "cpu" and rendered.dtype == torch.float32:
        ssim = mean_ssim_cpu(rendered, target)
    else:
        ssim = ssim_map(rendered.permute(2, 0, 1)[None], target.permute(2, 0, 1)[None]).mean()
    return (1 - lambda_dssim) * (rendered - target).abs().mean() + lambda_dssim * (1 - ssim)


def ssim_map(a: torch.Tensor, b: torch.Tensor, c1: float = 0.01**2, c2: float = 0.03**2) -> torch.Tensor:
    """(N, C, H, W) SSIM of two (N, C, H, W) images in [0, 1]: local means and (co)variances
    under an 11x11 Gaussian window (sigma 1.5), reflect-padded, as ``kornia.metrics.ssim``
    computes them. The five local moments are filtered together, two grouped 1D
    convolutions in all, which on the CPU takes 0.4x the time of filtering each on its own
    (forward and backward, 3x372x497)."""
    c = a.shape[1]
    t = torch.arange(SSIM_WINDOW, dtype=a.dtype, device=a.device) - SSIM_WINDOW // 2
    g = torch.exp(-(t**2) / (2 * SSIM_SIGMA**2))
    g = g / g.sum()
    k, r = 5 * c, SSIM_WINDOW // 2
    moments = F.pad(torch.cat([a, b, a * a, b * b, a * b], dim=1), (r, r, r, r), mode="reflect")
    moments = F.conv2d(moments, g.view(1, 1, 1, -1).expand(k, 1, 1, -1), groups=k)
    moments = F.conv2d(moments, g.view(1, 1, -1, 1).expand(k, 1, -1, 1), groups=k)
    mu_a, mu_b, aa, bb, ab = moments.split(c, dim=1)
    var_a, var_b, cov = aa - mu_a**2, bb - mu_b**2, ab - mu_a * mu_b
    return ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a**2 + mu_b**2 + c1) * (var_a + var_b + c2))


def sample_pixels(
    n_pixels: int, count: int, generator: torch.Generator | None = None, device: torch.device | str = "cpu"
) -> torch.Tensor | None:
    """``count`` flat indices (count,) of an image of ``n_pixels`` pixels drawn without
    replacement, for the object loss; None (every pixel) unless 0 < count < n_pixels."""
    if 0 < count < n_pixels:
        return torch.randperm(n_pixels, generator=generator, device=device)[:count]
    return None


def object_loss(features: torch.Tensor, labels: torch.Tensor, classifier: torch.nn.Linear) -> torch.Tensor:
    """Mean cross-entropy of the classifier on rendered features (..., F) against the mask's
    IDs (...) at the same pixels."""
    return F.cross_entropy(classifier(features.reshape(-1, features.shape[-1])), labels.reshape(-1))


def psnr_from_mse(mse: float) -> float:
    """PSNR in dB of a mean squared error of images in [0, 1] (computed in float32, as the
    progress display has always shown it)."""
    return float("inf") if mse == 0 else -10.0 * torch.log10(torch.tensor(mse)).item()


def knn_identity_loss(
    means: torch.Tensor,
    obj_feat: torch.Tensor,
    classifier: torch.nn.Linear,
    samples: int,
    k: int,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Gaussian Grouping's 3D identity term: the mean KL divergence between the class
    distribution of ``samples`` Gaussians drawn at random and that of each of their ``k``
    nearest Gaussians in 3D (means (N, 3), obj_feat (N, F)). Neighbours agree on their object."""
    from scipy.spatial import cKDTree

    n = len(means)
    if n <= k:
        return obj_feat.new_zeros(())
    pick = torch.randperm(n, generator=generator, device=means.device)[: min(samples, n)]
    points = means.detach().cpu().numpy()
    _, nearest = cKDTree(points).query(points[pick.cpu().numpy()], k=k + 1)
    nearest = torch.as_tensor(nearest[:, 1:], device=means.device)  # (m, k), itself left out
    # embedding, not indexing, for a backward pass that sums repeated rows in a fixed order
    log_p = torch.log_softmax(classifier(obj_feat[pick]), dim=-1)  # (m, C)
    log_q = torch.log_softmax(classifier(F.embedding(nearest, obj_feat)), dim=-1)  # (m, k, C)
    return (log_p.exp()[:, None] * (log_p[:, None] - log_q)).sum(-1).mean()
