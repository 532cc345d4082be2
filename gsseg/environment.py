"""A learned environment behind the Gaussians: a colour for every viewing direction.

What lies at infinity (the sky, the far end of a ground plane) is the same from every camera
position. Gaussians can only imitate it by sitting at a finite depth, where they turn into
floaters in front of the objects seen from other views. An environment map expressed in
spherical harmonics of the ray direction (the 3D-GS basis, degree 3 by default) takes that
part of the image instead: it is composited behind the Gaussians, ``rgb + (1 - alpha) * env``.
"""

from __future__ import annotations

import torch

from dataset_tools.cameras import PinholeCamera
from gsseg.sh import eval_sh, num_coeffs


def ray_directions(camera: PinholeCamera, cam_from_world: torch.Tensor) -> torch.Tensor:
    """World-space unit directions of the rays through the pixel centres: (H, W, 3)."""
    R = torch.as_tensor(cam_from_world)[:3, :3].float()
    v, u = torch.meshgrid(torch.arange(camera.height, device=R.device, dtype=R.dtype) + 0.5,
                          torch.arange(camera.width, device=R.device, dtype=R.dtype) + 0.5, indexing="ij")
    d_cam = torch.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, torch.ones_like(u)], -1)
    return torch.nn.functional.normalize(d_cam @ R, dim=-1)  # R.T @ d for every pixel


class Environment(torch.nn.Module):
    """Colour as a function of the ray direction: SH coefficients (1, (degree + 1)^2, 3),
    initialised to a uniform grey."""

    def __init__(self, degree: int = 3):
        super().__init__()
        self.degree = degree
        self.coeffs = torch.nn.Parameter(torch.zeros(1, num_coeffs(degree), 3))

    def forward(self, camera: PinholeCamera, cam_from_world: torch.Tensor) -> torch.Tensor:
        """The background image of one camera, (H, W, 3)."""
        dirs = ray_directions(camera, cam_from_world).to(self.coeffs.device)
        return eval_sh(self.degree, self.coeffs[0], dirs.reshape(-1, 3)).reshape(camera.height, camera.width, 3)

    @classmethod
    def from_state(cls, state: dict[str, torch.Tensor]) -> Environment:
        env = cls(num_coeffs_to_degree(state["coeffs"].shape[1]))
        env.load_state_dict(state)
        return env


def num_coeffs_to_degree(k: int) -> int:
    """The SH degree with ``k`` coefficients per channel."""
    degree = round(k ** 0.5) - 1
    if num_coeffs(degree) != k:
        raise ValueError(f"{k} is not a number of SH coefficients")
    return degree


def background_image(environment: Environment | None, camera: PinholeCamera,
                     cam_from_world: torch.Tensor) -> torch.Tensor | None:
    """The background of one camera for :func:`gsseg.render.render`: the environment's
    (H, W, 3) image on the pose's device, or None (black) without an environment."""
    if environment is None:
        return None
    return environment.to(cam_from_world.device)(camera, cam_from_world)
