"""Real spherical harmonics up to degree 3, in the basis and sign convention of 3D-GS."""

from __future__ import annotations

import torch

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
      -0.4570457994644658, 1.445305721320277, -0.5900435899266435)

MAX_DEGREE = 3


def num_coeffs(degree: int) -> int:
    """Number of SH coefficients per colour channel up to ``degree``: (degree + 1)^2."""
    return (degree + 1) ** 2


def rgb_to_sh_dc(rgb: torch.Tensor) -> torch.Tensor:
    """DC coefficients whose colour is ``rgb`` (..., 3) in [0, 1]."""
    return (rgb - 0.5) / C0


def sh_dc_to_rgb(dc: torch.Tensor) -> torch.Tensor:
    """The view-independent colour (..., 3) of DC coefficients (..., 3)."""
    return dc * C0 + 0.5


def eval_sh(degree: int, coeffs: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Colour of SH coefficients seen along unit directions.

    Args:
        degree: highest band used, 0..3.
        coeffs: (N, K, 3) coefficients, K >= (degree + 1)^2; band order as in 3D-GS.
        dirs: (N, 3) unit vectors from the camera centre to each Gaussian.

    Returns:
        (N, 3) colour, offset by +0.5 and clamped at 0 as 3D-GS does.
    """
    # One view per coefficient through ``unbind``: its backward stacks the K gradients once,
    # where indexing coeffs[:, k] would zero-fill an (N, K, 3) gradient for every k.
    c = coeffs.unbind(1)
    result = C0 * c[0]
    if degree > 0:
        x, y, z = dirs[:, 0:1], dirs[:, 1:2], dirs[:, 2:3]
        result = result - C1 * y * c[1] + C1 * z * c[2] - C1 * x * c[3]
        if degree > 1:
            xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
            result = (result + C2[0] * xy * c[4] + C2[1] * yz * c[5]
                      + C2[2] * (2 * zz - xx - yy) * c[6] + C2[3] * xz * c[7]
                      + C2[4] * (xx - yy) * c[8])
            if degree > 2:
                result = (result + C3[0] * y * (3 * xx - yy) * c[9] + C3[1] * xy * z * c[10]
                          + C3[2] * y * (4 * zz - xx - yy) * c[11]
                          + C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * c[12]
                          + C3[4] * x * (4 * zz - xx - yy) * c[13] + C3[5] * z * (xx - yy) * c[14]
                          + C3[6] * x * (xx - 3 * yy) * c[15])
    return torch.clamp_min(result + 0.5, 0.0)
