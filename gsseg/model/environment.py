"""A learned environment behind the Gaussians: a colour for every viewing direction.

What lies at infinity (the sky, the far end of a ground plane) is the same from every camera
position. Gaussians can only imitate it by sitting at a finite depth, where they turn into
floaters in front of the objects seen from other views, and a camera at another height sees
past them. The environment takes that part of the image instead: it is composited behind the
Gaussians, ``rgb + (1 - alpha) * env``, and is the sum of two terms:

- spherical harmonics of the ray direction (the 3D-GS basis, degree 3 by default): smooth
  variation in every direction (a bright side of the sky);
- an elevation profile: a colour per elevation angle above the horizon plane (perpendicular
  to the cameras' mean up direction), linearly interpolated between bins about one pixel
  apart. It holds what low-order SH cannot, the sharp step at the horizon between the sky
  and the far ground, without the capacity to learn detail that varies around the horizon.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from dataset_tools.infra.errors import OptionError
from gsseg.model.environment_cpu import environment_image_cpu
from gsseg.model.gaussians import OBJ_FEAT_DIM, Gaussians
from gsseg.model.sh import eval_sh, num_coeffs, rgb_to_sh_dc


def ray_directions(camera: PinholeCamera, cam_from_world: torch.Tensor) -> torch.Tensor:
    """World-space unit directions of the rays through the pixel centres: (H, W, 3)."""
    R = torch.as_tensor(cam_from_world)[:3, :3].float()
    v, u = torch.meshgrid(
        torch.arange(camera.height, device=R.device, dtype=R.dtype) + 0.5,
        torch.arange(camera.width, device=R.device, dtype=R.dtype) + 0.5,
        indexing="ij",
    )
    d_cam = torch.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, torch.ones_like(u)], -1)
    return torch.nn.functional.normalize(d_cam @ R, dim=-1)  # R.T @ d for every pixel


class _ProfileLerp(torch.autograd.Function):
    """(1 - w) profile[lo] + w profile[hi] for (N,) bin indices and (N, 1) weights; the
    backward pass sums each bin's gradient with ``torch.bincount``, which on the CPU adds in
    pixel order, so that the bits do not depend on the threads (indexing's backward adds in
    whatever order the threads reach a bin), and without ``F.embedding``'s sort of the indices
    (the lookup with its gradient at 497x372 pixels: 5.5 ms against 28 on 2 cores)."""

    @staticmethod
    def forward(ctx, profile, lo, hi, w):
        ctx.save_for_backward(lo, hi, w)
        ctx.bins = profile.shape[0]
        return (1 - w) * profile[lo] + w * profile[hi]

    @staticmethod
    def backward(ctx, grad):
        lo, hi, w = ctx.saved_tensors
        lower, upper = (1 - w) * grad, w * grad
        sums = [
            torch.bincount(lo, lower[:, c], minlength=ctx.bins) + torch.bincount(hi, upper[:, c], minlength=ctx.bins)
            for c in range(grad.shape[1])
        ]
        return torch.stack(sums, dim=1), None, None, None


def mean_up(cam_from_world: list[np.ndarray]) -> np.ndarray:
    """The cameras' mean up direction in world space, (3,) unit: the average of each camera's
    -y axis (OpenCV cameras have y pointing down the image)."""
    up = -np.mean([np.asarray(p)[1, :3] for p in cam_from_world], axis=0)
    norm = np.linalg.norm(up)
    if norm < 1e-6:
        raise OptionError(
            "the cameras' up directions cancel out, so there is no common horizon; train with {environment_profile}.",
            environment_profile=False,
        )
    return up / norm


def profile_bins(focal: float) -> int:
    """Number of elevation bins over [-90, 90] degrees about one pixel apart at a focal
    length of ``focal`` pixels."""
    pixel_angle = math.atan(1.0 / focal)
    return math.ceil(math.pi / pixel_angle)


class Environment(torch.nn.Module):
    """Colour as a function of the ray direction: SH coefficients (1, (degree + 1)^2, 3),
    initialised to a uniform grey, plus an elevation profile (bins, 3) about ``up``,
    initialised to zero (``bins`` = 0: SH only)."""

    def __init__(self, degree: int = 3, up: np.ndarray | torch.Tensor | None = None, bins: int = 0):
        super().__init__()
        if bins and up is None:
            raise ValueError("an elevation profile needs an up direction")
        self.degree = degree
        self.coeffs = torch.nn.Parameter(torch.zeros(1, num_coeffs(degree), 3))
        if bins:
            self.profile = torch.nn.Parameter(torch.zeros(bins, 3))
            self.register_buffer("up", torch.as_tensor(np.asarray(up, dtype=np.float32)))
        else:
            self.profile = None

    def elevation_colour(self, dirs: torch.Tensor) -> torch.Tensor:
        """The profile at unit directions (N, 3): (N, 3), linear between bin centres."""
        bins = self.profile.shape[0]
        elevation = torch.asin((dirs @ self.up).clamp(-1.0, 1.0))
        x = (elevation / math.pi + 0.5) * bins - 0.5  # bin k's centre at x = k
        lo = x.floor().clamp(0, bins - 1)
        w = (x - lo).clamp(0.0, 1.0)[:, None]
        lo = lo.long()
        return _ProfileLerp.apply(self.profile, lo, (lo + 1).clamp_max(bins - 1), w)

    def profile_variation(self) -> torch.Tensor:
        """The profile's total variation: the summed absolute step between neighbouring bins
        over the three channels, a scalar (0 without a profile). A horizon is one step; bands
        copied from the scene's near ground are many."""
        if self.profile is None:
            return self.coeffs.new_zeros(())
        return (self.profile[1:] - self.profile[:-1]).abs().sum()

    def forward(self, camera: PinholeCamera, cam_from_world: torch.Tensor) -> torch.Tensor:
        """The background image of one camera, (H, W, 3): for float32 on the CPU by the numba
        kernels of :mod:`gsseg.model.environment_cpu` (the same image and gradients without the
        per-pixel tables), else by :meth:`image_torch`."""
        if self.coeffs.device.type == "cpu" and self.coeffs.dtype == torch.float32:
            up = self.up if self.profile is not None else None
            return environment_image_cpu(self.coeffs[0], self.profile, up, camera, cam_from_world)
        return self.image_torch(camera, cam_from_world)

    def image_torch(self, camera: PinholeCamera, cam_from_world: torch.Tensor) -> torch.Tensor:
        """The background image of one camera, (H, W, 3), in tensor operations."""
        dirs = ray_directions(camera, cam_from_world).to(self.coeffs.device).reshape(-1, 3)
        colour = eval_sh(self.degree, self.coeffs[0], dirs)
        if self.profile is not None:
            colour = colour + self.elevation_colour(dirs)
        return colour.reshape(camera.height, camera.width, 3)

    @classmethod
    def from_state(cls, state: dict[str, torch.Tensor]) -> Environment:
        """The environment saved by ``state_dict`` (runs from before the profile have none)."""
        profile = state.get("profile")
        env = cls(
            num_coeffs_to_degree(state["coeffs"].shape[1]),
            up=state.get("up"),
            bins=0 if profile is None else profile.shape[0],
        )
        env.load_state_dict(state)
        return env


def num_coeffs_to_degree(k: int) -> int:
    """The SH degree with ``k`` coefficients per channel."""
    degree = round(k**0.5) - 1
    if num_coeffs(degree) != k:
        raise ValueError(f"{k} is not a number of SH coefficients")
    return degree


def background_image(
    environment: Environment | None, camera: PinholeCamera, cam_from_world: torch.Tensor
) -> torch.Tensor | None:
    """The background of one camera for :func:`gsseg.render.render`: the environment's
    (H, W, 3) image on the pose's device, or None (black) without an environment."""
    if environment is None:
        return None
    return environment.to(cam_from_world.device)(camera, cam_from_world)


# The environment as ordinary Gaussians, for renderers that know nothing of it (exports).
SHELL_DISTANCE = 50.0  # the shell's radius in camera extents: a parallax of at most ~1 degree
SHELL_FAR = 500.0  # ... but nearer than this (scene units): web viewers clip at 1000 by default
SHELL_NEAREST = 5.0  # ... and never nearer than this many camera extents
SHELL_PIXELS = 2.0  # neighbouring shell Gaussians this many pixels apart at the finest camera
SHELL_MAX_GAUSSIANS = 200_000  # the spacing widens past this count
SHELL_OPACITY = 0.99  # the most a 3D-GS renderer lets one Gaussian cover


def fibonacci_directions(count: int) -> np.ndarray:
    """``count`` unit directions spread evenly over the sphere (a Fibonacci lattice): (count, 3)."""
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    azimuth = math.pi * (3.0 - math.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(azimuth), r * np.sin(azimuth), z], 1)


def _quats_from_z(dirs: np.ndarray) -> np.ndarray:
    """(N, 4) (w, x, y, z) quaternions turning the local z axis onto the unit ``dirs`` (N, 3)."""
    w = 1.0 + dirs[:, 2]
    q = np.stack([w, -dirs[:, 1], dirs[:, 0], np.zeros(len(dirs))], 1)
    q[w < 1e-6] = (0.0, 1.0, 0.0, 0.0)  # straight down: half a turn about x
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def shell_radius(extent: float) -> float:
    """The shell's radius for cameras ``extent`` apart: ``SHELL_DISTANCE`` extents, at most
    ``SHELL_FAR`` scene units where that leaves ``SHELL_NEAREST`` extents."""
    return max(min(SHELL_DISTANCE * extent, SHELL_FAR), SHELL_NEAREST * extent)


def shell_spacing(finest_focal: float) -> float:
    """The angle between neighbouring shell Gaussians (radians): ``SHELL_PIXELS`` pixels at a
    focal length of ``finest_focal`` pixels, widened so that the sphere needs at most
    ``SHELL_MAX_GAUSSIANS``."""
    return max(SHELL_PIXELS / finest_focal, math.sqrt(4 * math.pi / SHELL_MAX_GAUSSIANS))


@torch.no_grad()
def environment_shell(environment: Environment, center: np.ndarray, radius: float, spacing: float) -> Gaussians:
    """The environment as a sphere of flat, nearly opaque Gaussians about ``center``.

    Each Gaussian takes the environment's colour in its direction from ``center``, as SH degree
    0, so that any 3D-GS renderer shows behind the model what ``rgb + (1 - alpha) * env``
    shows; a camera at distance d from ``center`` sees it turned by at most d / ``radius``
    radians. Neighbours are ``spacing`` radians apart, each a disk tangent to the sphere with
    a standard deviation of one spacing, so the shell is opaque between them.

    Args:
        environment: the learned environment.
        center: (3,) the shell's centre (the cameras' mean centre).
        radius: its radius, far outside the scene.
        spacing: angle between neighbouring Gaussians, radians.

    Returns:
        Gaussians (N, ...) with zero object features; N = ceil(4 pi / spacing^2).
    """
    dirs = fibonacci_directions(math.ceil(4 * math.pi / spacing**2))
    d = torch.as_tensor(dirs, dtype=torch.float32)
    env = environment.to("cpu")
    colour = eval_sh(env.degree, env.coeffs[0], d)
    if env.profile is not None:
        colour = colour + env.elevation_colour(d)
    n = len(dirs)
    sigma = spacing * radius
    return Gaussians(
        means=torch.as_tensor(np.asarray(center, np.float64) + radius * dirs, dtype=torch.float32),
        log_scales=torch.log(torch.tensor([sigma, sigma, 1e-3 * sigma])).repeat(n, 1),
        quats=torch.as_tensor(_quats_from_z(dirs), dtype=torch.float32),
        opacity_logits=torch.full((n,), math.log(SHELL_OPACITY / (1 - SHELL_OPACITY))),
        sh_dc=rgb_to_sh_dc(colour.clamp_min(0.0)),
        sh_rest=torch.zeros(n, num_coeffs(3) - 1, 3),
        obj_feat=torch.zeros(n, OBJ_FEAT_DIM),
    )
