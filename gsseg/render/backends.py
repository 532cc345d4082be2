"""The rasterizer backends, one object each, and the one place that chooses among them.

``cpu``    numba kernels (the default without a GPU),
``torch``  plain PyTorch, the reference the others are tested against,
``gsplat`` gsplat on CUDA (chosen automatically where it is installed and a GPU is present).

Every backend turns projected Gaussians into an image of blended values plus alpha and
depth (:meth:`Backend.rasterize`), and sums each Gaussian's blended weight alpha_i T_i per
mask label over a view (:meth:`Backend.contributions`, the pass behind FlashSplat's
contribution matrix). Callers name a backend by string or pass one; :func:`get_backend`
resolves ``auto`` and checks availability.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import torch

from dataset_tools.cameras import PinholeCamera
from dataset_tools.infra.errors import InputError, OptionError
from gsseg.render import cpu_kernels
from gsseg.render.blend_rules import ALPHA_MAX
from gsseg.render.cpu_blend import as_float32_array, bin_tiles, blend_cpu
from gsseg.render.cpu_projection import project_gaussians_cpu
from gsseg.render.gsplat_blend import GSPLAT_ALPHA_MAX, gsplat_available, rasterize_gsplat
from gsseg.render.projection import TILE_SIZE, Projection, project_gaussians
from gsseg.render.torch_blend import blend_torch


@dataclass
class Raster:
    """What a backend draws for one camera.

    Attributes:
        image: (H, W, C) blended values, sum_i alpha_i T_i v_i.
        alpha: (H, W) accumulated opacity.
        depth: (H, W) alpha-weighted camera depth, sum_i alpha_i T_i z_i.
        means2d: screen centres, (N, 2) or (1, N, 2); after ``backward`` its ``.grad`` is the
            view-space positional gradient densification uses.
        radii: (N,) int32 footprint radii in pixels, 0 where a Gaussian is not seen.
    """

    image: torch.Tensor
    alpha: torch.Tensor
    depth: torch.Tensor
    means2d: torch.Tensor
    radii: torch.Tensor


class Backend:
    """A rasterizer: its name, the torch device it works on, and its capabilities.

    Attributes:
        name: ``cpu``, ``torch`` or ``gsplat``.
        device: the torch device its tensors live on.
        alpha_max: the clamp of one Gaussian's alpha at one pixel (3D-GS: 0.99).
        default_schedule: the training schedule it is fast enough for by default (``cpu``:
            3000 iterations; ``gpu``: the paper's 30k).
    """

    name: str
    device: str = "cpu"
    alpha_max: float = ALPHA_MAX
    default_schedule: str = "cpu"

    def available(self) -> bool:
        return True

    def rasterize(
        self,
        means: torch.Tensor,
        quats: torch.Tensor,
        scales: torch.Tensor,
        opacities: torch.Tensor,
        values: torch.Tensor,
        cam_from_world: torch.Tensor,
        camera: PinholeCamera,
    ) -> Raster:
        """Project and blend N Gaussians (means (N, 3), quats (N, 4), scales (N, 3),
        opacities (N,)) carrying ``values`` (N, C) into ``camera``; differentiable."""
        raise NotImplementedError

    def rasterize_beside(
        self,
        means: torch.Tensor,
        quats: torch.Tensor,
        scales: torch.Tensor,
        opacities: torch.Tensor,
        values: torch.Tensor,
        beside: torch.Tensor,
        cam_from_world: torch.Tensor,
        camera: PinholeCamera,
        pixels: torch.Tensor | None = None,
    ) -> tuple[Raster, torch.Tensor]:
        """:meth:`rasterize` ``values`` (N, C), and ``beside`` (N, E) blended by the same
        Gaussians with gradients that reach ``beside`` alone, not the geometry: the raster and
        the (H, W, E) image of ``beside``, or its (P, E) values at the flat pixel indices
        ``pixels`` (P,) (y W + x) when they are given. By default a second pass over the
        detached geometry, at every pixel."""
        raster = self.rasterize(means, quats, scales, opacities, values, cam_from_world, camera)
        detached = (x.detach() for x in (means, quats, scales, opacities))
        image = self.rasterize(*detached, beside, cam_from_world, camera).image
        return raster, image if pixels is None else image.reshape(-1, image.shape[-1])[pixels]

    def contributions(
        self,
        means: torch.Tensor,
        quats: torch.Tensor,
        scales: torch.Tensor,
        opacities: torch.Tensor,
        cam_from_world: torch.Tensor,
        camera: PinholeCamera,
        rows: np.ndarray,
        n_rows: int,
    ) -> torch.Tensor:
        """(n_rows, N) float32 on the backend's device: each Gaussian's alpha_i T_i summed over
        the pixels whose ``rows`` entry (an (H, W) int array) is r; pixels with row -1 count
        nowhere.

        By default the gradient of sum_p <rendered values, one_hot(rows(p))> with respect to
        per-Gaussian values, which is exactly those sums: one n_rows-channel render and its
        backward pass, with the backend's own blending rules.
        """
        probe = torch.zeros(len(means), n_rows, device=means.device, requires_grad=True)
        raster = self.rasterize(means, quats, scales, opacities, probe, cam_from_world, camera)
        row = torch.as_tensor(rows, device=means.device, dtype=torch.int64)[..., None]  # (H, W, 1)
        (raster.image.gather(-1, row.clamp_min(0)) * (row >= 0)).sum().backward()
        return probe.grad.T

    def __repr__(self) -> str:
        return f"<{self.name} backend on {self.device}>"


class _Projecting(Backend):
    """The backends that project as :func:`project_gaussians` does and blend on their own."""

    @staticmethod
    def project(means, quats, scales, cam_from_world, camera, opacities) -> Projection:
        """The screen-space footprints of the Gaussians, differentiable."""
        return project_gaussians(means, quats, scales, cam_from_world, camera, opacities)

    def blend(self, means2d, conics, opacities, values, depths, radii, width, height):
        """(H, W, C) image and (H, W) alpha of ``values`` (N, C), differentiable."""
        raise NotImplementedError

    def rasterize(self, means, quats, scales, opacities, values, cam_from_world, camera):
        proj = self._projected(means, quats, scales, opacities, cam_from_world, camera)
        image, alpha = self.blend(*_blend_args(proj, opacities, values, camera))
        return _raster(image, alpha, proj)

    def _projected(self, means, quats, scales, opacities, cam_from_world, camera) -> Projection:
        """:meth:`project`, keeping the gradient of ``means2d`` that densification reads."""
        proj = self.project(means, quats, scales, cam_from_world, camera, opacities)
        if proj.means2d.requires_grad:
            proj.means2d.retain_grad()
        return proj


def _blend_args(proj: Projection, opacities: torch.Tensor, values: torch.Tensor, camera: PinholeCamera) -> tuple:
    """The arguments of :meth:`_Projecting.blend` for ``values`` (N, C) and the depth after
    them, (N, C + 1)."""
    with_depth = torch.cat([values, proj.depths[:, None]], dim=1)
    return proj.means2d, proj.conics, opacities, with_depth, proj.depths, proj.radii, camera.width, camera.height


def _raster(image: torch.Tensor, alpha: torch.Tensor, proj: Projection) -> Raster:
    """The raster of a blend of :func:`_blend_args`' values."""
    return Raster(image[..., :-1], alpha, image[..., -1], proj.means2d, proj.radii)


class CpuBackend(_Projecting):
    """numba kernels: the projection (:mod:`gsseg.render.cpu_projection`) and the blending,
    16x16 tiles with pixels as SIMD lanes (:mod:`gsseg.render.cpu_kernels`)."""

    name = "cpu"
    project = staticmethod(project_gaussians_cpu)

    def blend(self, *args):
        return blend_cpu(*args)[:2]

    def rasterize_beside(self, means, quats, scales, opacities, values, beside, cam_from_world, camera, pixels=None):
        """One projection and one blend of ``values``, depth and ``beside`` together, whose
        backward pass lets only ``values`` and depth reach the geometry; with ``pixels``,
        ``beside`` is blended at those pixels alone."""
        proj = self._projected(means, quats, scales, opacities, cam_from_world, camera)
        image, alpha, beside_image = blend_cpu(*_blend_args(proj, opacities, values, camera), beside, pixels)
        return _raster(image, alpha, proj), beside_image

    @torch.no_grad()
    def contributions(self, means, quats, scales, opacities, cam_from_world, camera, rows, n_rows):
        """A forward-only numba pass that adds alpha_i T_i into the row of each pixel."""
        proj = self.project(means, quats, scales, cam_from_world, camera, opacities)
        offsets, ids = bin_tiles(proj.means2d, proj.radii, proj.depths, camera.width, camera.height)
        arrays = [as_float32_array(x) for x in (proj.means2d, proj.conics, opacities)]
        out = cpu_kernels.accumulate_weights(
            *arrays,
            offsets,
            ids,
            camera.width,
            camera.height,
            TILE_SIZE,
            np.ascontiguousarray(rows, dtype=np.int32),
            n_rows,
            numba.get_num_threads(),
        )
        return torch.from_numpy(out)


class TorchBackend(_Projecting):
    """Dense tensor algebra per tile, differentiated by autograd: the reference."""

    name = "torch"

    def blend(self, *args):
        return blend_torch(*args)


class GsplatBackend(Backend):
    """gsplat's CUDA kernels (it clamps alpha at 0.999 where 3D-GS clamps at 0.99)."""

    name = "gsplat"
    device = "cuda"
    alpha_max = GSPLAT_ALPHA_MAX
    default_schedule = "gpu"

    def available(self) -> bool:
        return gsplat_available()

    def rasterize(self, means, quats, scales, opacities, values, cam_from_world, camera):
        image, alpha, means2d, radii = rasterize_gsplat(means, quats, scales, opacities, values, cam_from_world, camera)
        return Raster(image[..., :-1], alpha, image[..., -1], means2d, radii)


BACKENDS: dict[str, Backend] = {b.name: b for b in (CpuBackend(), TorchBackend(), GsplatBackend())}


def backend_schedule(backend: str) -> str:
    """The training schedule of the backend called ``backend``
    (:attr:`Backend.default_schedule`); ``auto`` is the one it resolves to here. A backend
    that cannot run here still names its schedule (training then says why it cannot run)."""
    if backend == "auto":
        return get_backend(backend).default_schedule
    if backend not in BACKENDS:
        raise OptionError(f"{{backend}}: choose one of auto, {', '.join(BACKENDS)}.", backend=backend)
    return BACKENDS[backend].default_schedule


def get_backend(backend: str | Backend = "auto") -> Backend:
    """The backend called ``backend`` (or ``backend`` itself): ``auto`` is ``gsplat`` where it
    can run, else ``cpu``. Raises InputError for an unknown or unavailable name."""
    if isinstance(backend, Backend):
        return backend
    if backend == "auto":
        return BACKENDS["gsplat"] if BACKENDS["gsplat"].available() else BACKENDS["cpu"]
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r}; choose one of auto, {', '.join(BACKENDS)}.")
    if not BACKENDS[backend].available():
        raise OptionError("{backend} needs a CUDA GPU and `pip install gsplat`; use the cpu backend.", backend=backend)
    return BACKENDS[backend]
