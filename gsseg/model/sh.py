"""Real spherical harmonics up to degree 3, in the basis and sign convention of 3D-GS."""

from __future__ import annotations

import torch

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)

MAX_DEGREE = 3


def num_coeffs(degree: int) -> int:
    """Number of SH coefficients per colour channel up to ``degree``: (degree + 1)^2."""
    return (degree + 1) ** 2


def rgb_to_sh_dc(rgb: torch.Tensor) -> torch.Tensor:
    """DC coefficients whose colour is ``rgb`` (..., 3) in [0, 1]."""
    return (rgb - 0.5) / C0


def sh_basis(degree: int, dirs: torch.Tensor) -> torch.Tensor:
    """The real SH basis functions up to ``degree`` at unit directions, in the order and signs
    of 3D-GS: (N, 3) -> (N, (degree + 1)^2)."""
    x, y, z = dirs.unbind(-1)
    columns = [torch.full_like(x, C0)]
    if degree > 0:
        columns += [-C1 * y, C1 * z, -C1 * x]
    if degree > 1:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        columns += [C2[0] * xy, C2[1] * yz, C2[2] * (2 * zz - xx - yy), C2[3] * xz, C2[4] * (xx - yy)]
    if degree > 2:
        columns += [
            C3[0] * y * (3 * xx - yy),
            C3[1] * xy * z,
            C3[2] * y * (4 * zz - xx - yy),
            C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
            C3[4] * x * (4 * zz - xx - yy),
            C3[5] * z * (xx - yy),
            C3[6] * x * (xx - 3 * yy),
        ]
    return torch.stack(columns, dim=-1)


def eval_sh(degree: int, coeffs: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Colour of SH coefficients seen along unit directions.

    Args:
        degree: highest band used, 0..3.
        coeffs: (N, K, 3) coefficients of each direction, or (K, 3) shared by all of them,
            K >= (degree + 1)^2; band order as in 3D-GS.
        dirs: (N, 3) unit vectors (for Gaussians: from the camera centre to each of them).

    Returns:
        (N, 3) colour, offset by +0.5 and clamped at 0 as 3D-GS does.
    """
    basis = sh_basis(degree, dirs)
    k = basis.shape[1]
    if coeffs.dim() == 2:
        colour = basis @ coeffs[:k]
    else:  # one (1, K) x (K, 3) product per direction
        colour = torch.bmm(basis[:, None], coeffs[:, :k]).squeeze(1)
    return torch.clamp_min(colour + 0.5, 0.0)
