"""Fill what a removal uncovers and no photo saw.

Removing an object's Gaussians uncovers what stood behind it. Where some training view saw
that surface, the model already holds it; where none did, the removal shows whatever the
training left there (a smear, the environment). :func:`fill_removal` finds those pixels and
fits new Gaussians to a 2D inpainting of them, with the rest of the model frozen:

1. **Unseen pixels.** In each training view the object shows in (at most
   :attr:`FillOptions.fit_views` of them, spread over them) the object's silhouette is where
   the removed Gaussians held most of the blended weight (widened by its rim). Each of its
   pixels shows, after the removal, a surface point (its rendered depth) or the environment
   (a direction); the point is seen when another training view's render of the *whole* model
   shows it there (the depths agree within :attr:`FillOptions.depth_tolerance`), the
   direction when another view shows the environment there. The rest is unseen.
2. **Inpainting.** In each of those views the removal's render is inpainted over its unseen
   pixels by frequency-selective reconstruction (OpenCV's ``xphoto``), which carries textures on
   where a diffusion (Telea) leaves a flat smudge. What stands in front of the object (its
   footprint, rendered alone, where it does not show) continues no surface into the hole, and
   the inpainting does not draw from it.
3. **Gaussians on the surface around the hole.** In up to :attr:`FillOptions.views` views
   spread over those with unseen pixels, new Gaussians are seeded on a pixel grid of the
   unseen pixels, at the inpainted colour and on the plane of the surface around the hole
   (fitted robustly to the depth of the pixels around it, so that an occluder's edge in the
   ring does not tilt it, and not to what stands in front of the object), each the size of
   its grid cell; a seed in space some view saw
   through (in front of the nearest surface it shows within a pixel, or where it shows the
   environment) is dropped, there is nothing there.
4. **A fit across the views.** The new Gaussians alone (positions, colours, opacities) are
   optimised, a few hundred steps, to those views' inpainted renders around the object (a
   crop: its silhouette and a margin, where the target is the removal's render as it is, so
   the fill must not show there): the views disagree where their inpaintings do, and the fit
   keeps what they share. Those left nearly transparent, or moved into space a view saw
   through, are dropped.

It cannot invent what the surroundings do not suggest: a hole larger than the textures around
it comes back as a smooth continuation of them, not as the scenery a photo would have shown.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np
import torch
from scipy.optimize import least_squares
from tqdm import tqdm

from dataset_tools.cameras import PinholeCamera
from dataset_tools.infra.engine import task_cpus
from dataset_tools.label_maps import mask_box
from gsseg.fill_options import FillOptions
from gsseg.model.environment import Environment, background_image
from gsseg.model.gaussians import Gaussians, gaussians_from_points
from gsseg.render import Backend, get_backend, render, surface_depth, to_uint8
from gsseg.render.contributions import Masked
from gsseg.render.pixel_labels import render_labels
from gsseg.run.loaded import Run
from gsseg.train.config import LearningRates
from gsseg.train.losses import photometric_loss
from gsseg.train.optim import GaussianOptimizer

FITTED = ("means", "opacity_logits", "sh_dc")  # what the fit moves; sizes stay those of the seeding grid


@dataclass(frozen=True)
class Filled:
    """A removal with its fill.

    Attributes:
        gaussians: the model without the removed Gaussians, with the fill (new ones last).
        added: new Gaussians.
        unseen_share: share of the silhouettes' pixels, over the views tested, that no other
            view saw behind the object.
        seconds: wall time of the fill.
        steps: optimisation steps of the fit (:attr:`FillOptions.steps`; 0 where nothing was unseen).
    """

    gaussians: Gaussians
    added: int
    unseen_share: float
    seconds: float
    steps: int

    def record(self) -> dict:
        """What ``edit.json`` says of the fill."""
        return {
            "added": self.added,
            "unseen_share": round(self.unseen_share, 4),
            "seconds": round(self.seconds, 1),
            "steps": self.steps,
        }


@dataclass
class _Shown:
    """One view in which the removed object showed, after the removal."""

    index: int  # into the views
    silhouette: np.ndarray  # (H, W) bool, the object's, widened by its rim
    unseen: np.ndarray  # (H, W) bool, the silhouette's pixels no other view saw behind the object
    in_front: np.ndarray  # (H, W) bool, what hides the object: its footprint where it does not show
    rgb: np.ndarray  # (H, W, 3) uint8 render of the removal
    depth: np.ndarray  # (H, W) its surface depth, 0 where it shows the environment


@dataclass
class _Crop:
    """What one view's step of the fit renders and compares."""

    camera: PinholeCamera  # of the crop around the object
    pose: torch.Tensor  # (3, 4)
    target: torch.Tensor  # (h, w, 3) in [0, 1]: the removal's render, inpainted where unseen
    background: torch.Tensor | None  # (h, w, 3) the environment in the crop
    drawn: Gaussians  # the kept Gaussians drawn in the crop


def crop_camera(camera: PinholeCamera, x0: int, y0: int, x1: int, y1: int) -> PinholeCamera:
    """The camera of the pixels [y0, y1) x [x0, x1) of ``camera``'s image. It renders the
    crop of the whole image, but for Gaussians far outside the crop, whose projection 3D-GS
    clamps at 1.3 half-widths of the image it is rendered to."""
    return PinholeCamera(x1 - x0, y1 - y0, camera.fx, camera.fy, camera.cx - x0, camera.cy - y0, camera.near)


SurfaceView = tuple[PinholeCamera, np.ndarray, np.ndarray]  # camera, (3, 4) cam_from_world, (H, W) surface depth


def _pixel_rays(xs: np.ndarray, ys: np.ndarray, camera: PinholeCamera) -> np.ndarray:
    """(P, 3) camera-space rays through the centres of the pixels (xs, ys) (P,), at depth 1."""
    return np.stack([(xs + 0.5 - camera.cx) / camera.fx, (ys + 0.5 - camera.cy) / camera.fy, np.ones(len(xs))], 1)


def _shown_depth(
    pc: np.ndarray, camera: PinholeCamera, depth: np.ndarray, min_z: float
) -> tuple[np.ndarray, np.ndarray]:
    """The rows of the camera-space points ``pc`` (P, 3) deeper than ``min_z`` that fall in
    ``camera``'s image, and the ``depth`` (H, W) it shows at each of them."""
    rows, u, v = camera.pixels(pc, min_z)
    return rows, depth[v, u]


def unseen_pixels(
    hole: np.ndarray,
    depth: np.ndarray,
    camera: PinholeCamera,
    cam_from_world: np.ndarray,
    others: Sequence[SurfaceView],
    tolerance: float,
) -> np.ndarray:
    """(H, W) bool: the pixels of ``hole`` (H, W) bool whose surface no other view sees.

    Args:
        depth: (H, W) camera depth of the surface each pixel shows after the removal, 0 where
            it shows the environment (then its direction is what another view must see).
        others: (camera, (3, 4) cam_from_world, (H', W') surface depth of the whole model, 0
            where it shows the environment) of every other view.
        tolerance: relative depth difference under which a view sees a point.
    """
    ys, xs = np.nonzero(hole)
    z = depth[ys, xs].astype(np.float64)
    far = z <= 0
    rays = _pixel_rays(xs, ys, camera)
    R, t = cam_from_world[:3, :3], cam_from_world[:3, 3]
    points = (rays * np.where(far, 1.0, z)[:, None] - t) @ R  # world points; directions where far
    directions = rays @ R
    unseen = np.arange(len(xs))  # the pixels no view has seen yet; each view tests only those
    for cam, pose, other_depth in others:
        Ro, to = pose[:3, :3], pose[:3, 3]
        pc = np.where(far[unseen, None], directions[unseen] @ Ro.T, points[unseen] @ Ro.T + to)
        rows, shown = _shown_depth(pc, cam, other_depth, 1e-9)
        agree = np.where(far[unseen[rows]], shown <= 0, np.abs(shown - pc[rows, 2]) <= tolerance * pc[rows, 2])
        unseen = np.delete(unseen, rows[agree])
    out = np.zeros_like(hole)
    out[ys[unseen], xs[unseen]] = True
    return out


def seen_through(points: np.ndarray, views: Sequence[SurfaceView], tolerance: float) -> np.ndarray:
    """(P,) bool: which world ``points`` (P, 3) lie in space some view saw through: in its
    image, in front of the nearest surface it shows within a pixel by more than ``tolerance``
    (relative), or where it shows the environment all around. A pixel on an occluder's edge
    blends it with what lies behind, so the depth it shows is the occluder's neighbour's.
    ``views``: (camera, (3, 4) cam_from_world, (H, W) surface depth of the whole model, 0
    where it shows the environment)."""
    out = np.zeros(len(points), bool)
    for cam, pose, depth in views:
        pc = points @ pose[:3, :3].T + pose[:3, 3]
        nearest = cv2.erode(np.where(depth > 0, depth, np.inf).astype(np.float32), np.ones((3, 3), np.uint8))
        rows, shown = _shown_depth(pc, cam, np.where(np.isfinite(nearest), nearest, 0.0), cam.near)
        out[rows[(shown <= 0) | (pc[rows, 2] < (1 - tolerance) * shown)]] = True
    return out


def inpaint(rgb: np.ndarray, missing: np.ndarray, excluded: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 3) uint8 ``rgb`` with its ``missing`` (H, W) bool pixels, widened by one pixel,
    filled from the rest but the ``excluded`` (H, W) bool pixels (kept as they are) by
    frequency-selective reconstruction (OpenCV's ``xphoto``), which carries textures on."""
    missing = cv2.dilate(missing.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    known = ~missing if excluded is None else ~(missing | excluded)
    filled = np.empty_like(rgb)
    cv2.xphoto.inpaint(rgb, known.astype(np.uint8), filled, cv2.xphoto.INPAINT_FSR_FAST)
    return np.where(missing[..., None], filled, rgb)


def surface_across(
    hole: np.ndarray, depth: np.ndarray, camera: PinholeCamera, radius: int, tolerance: float
) -> np.ndarray:
    """(H, W) float32 ``depth`` (H, W), 0 where nothing is seen, carried across each connected
    part of ``hole`` (H, W) bool on the plane of the surface around it: the pixels within
    ``radius`` of the part that see a surface, their inverse depth fitted as an affine function
    of the pixel's ray (a plane in space) with a robust loss (relative depth errors beyond
    ``tolerance`` count less), the part's pixels at that plane's depth; 0 where their ray
    misses it, or where fewer than three pixels around the part see a surface."""
    out = np.where(hole, 0.0, depth).astype(np.float32)
    count, parts = cv2.connectedComponents(hole.astype(np.uint8), connectivity=8)
    ring_kernel = np.ones((2 * radius + 1,) * 2, np.uint8)
    for k in range(1, count):
        part = parts == k
        ring = (cv2.dilate(part.astype(np.uint8), ring_kernel) > 0) & ~hole & (depth > 0)
        ys, xs = np.nonzero(ring)
        if len(ys) < 3:
            continue
        rays = _pixel_rays(xs, ys, camera)  # (P, 3): x/z, y/z, 1
        z = depth[ys, xs].astype(np.float64)
        plane0 = np.linalg.lstsq(rays, 1 / z, rcond=None)[0]  # 1/z = plane . ray
        fit = least_squares(lambda q: z * (rays @ q) - 1, plane0, loss="cauchy", f_scale=tolerance)
        ys, xs = np.nonzero(part)
        inverse = _pixel_rays(xs, ys, camera) @ fit.x
        out[ys, xs] = np.where(inverse > 0, 1 / np.maximum(inverse, 1e-12), 0.0)
    return out


def _spread(items: list, count: int) -> list:
    """At most ``count`` of ``items``, evenly spread over them."""
    if len(items) <= count:
        return items
    return [items[int(i)] for i in np.linspace(0, len(items) - 1, count).round()]


def _grid_points(
    unseen: np.ndarray, depth: np.ndarray, rgb: np.ndarray, camera: PinholeCamera, pose: np.ndarray, stride: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points (P, 3), uint8 colours (P, 3) and sizes (P,) on a ``stride`` grid of the
    ``unseen`` pixels, at their (inpainted) ``depth``; a size is half the grid's spacing there."""
    grid = np.zeros_like(unseen)
    grid[stride // 2 :: stride, stride // 2 :: stride] = True
    ys, xs = np.nonzero(unseen & grid & (depth > 0))
    z = depth[ys, xs].astype(np.float64)
    points = (_pixel_rays(xs, ys, camera) * z[:, None] - pose[:3, 3]) @ pose[:3, :3]
    return points, rgb[ys, xs], 0.5 * stride * z / camera.fx


def fill_removal(
    gaussians: Gaussians,
    removed: np.ndarray,
    views: Sequence[Masked],
    *,
    environment: Environment | None,
    sh_degree: int,
    extent: float,
    options: FillOptions = FillOptions(),
    backend: str | Backend = "cpu",
    progress: bool = True,
) -> Filled:
    """Remove the ``removed`` (N,) bool Gaussians of ``gaussians`` and fill what no view of
    ``views`` (the training views, posed; their masks are not read) saw behind them.

    Args:
        environment: the run's learned background (None: black).
        sh_degree: the SH degree the run renders at.
        extent: the scene's extent, which scales the positions' learning rate as in training.
    """
    start = time.perf_counter()
    backend = get_backend(backend)
    kept = gaussians.detach().to(backend.device).select(torch.as_tensor(~removed, device=backend.device))
    shown, seen_by = _removal_views(gaussians, removed, kept, views, environment, sh_degree, options, backend, progress)
    share = sum(int(s.unseen.sum()) for s in shown) / max(sum(int(s.silhouette.sum()) for s in shown), 1)
    holes = [s for s in shown if s.unseen.any()]
    if not holes:
        return Filled(kept.to(gaussians.means.device), 0, share, time.perf_counter() - start, 0)
    with ThreadPoolExecutor(task_cpus()) as pool:  # OpenCV's inpainting runs on one core, without the GIL
        targets = dict(
            zip(
                [s.index for s in holes],
                pool.map(inpaint, [s.rgb for s in holes], [s.unseen for s in holes], [s.in_front for s in holes]),
            )
        )
    seeds = _seed(_spread(holes, options.views), targets, views, seen_by, kept.obj_feat.shape[1], options)
    crops = [_crop(s, targets.get(s.index, s.rgb), views[s.index], kept, environment, options, backend) for s in shown]
    fill = _fit(seeds.to(backend.device), crops, sh_degree, extent, options, backend, progress)
    with torch.no_grad():
        visible = (fill.opacities > 0.02).cpu().numpy() & ~seen_through(
            fill.means.cpu().numpy().astype(np.float64), seen_by, options.depth_tolerance
        )
        fill = fill.select(torch.as_tensor(visible, device=fill.means.device))
    out = Gaussians.concat(kept, fill)
    return Filled(out.to(gaussians.means.device), len(fill), share, time.perf_counter() - start, options.steps)


def fill_run_removal(
    run: Run,
    removed: np.ndarray,
    views: Sequence[Masked],
    *,
    gaussians: Gaussians | None = None,
    options: FillOptions = FillOptions(),
    backend: str | Backend = "cpu",
    progress: bool = True,
) -> Filled:
    """:func:`fill_removal` of the ``removed`` (N,) bool Gaussians of a trained ``run`` (or of
    its edited ``gaussians``, N of them too: recoloured), seen by its training ``views``."""
    return fill_removal(
        run.gaussians if gaussians is None else gaussians,
        removed,
        views,
        environment=run.environment,
        sh_degree=run.config.sh_degree,
        extent=run.record.extent,
        options=options,
        backend=backend,
        progress=progress,
    )


def _removal_views(
    gaussians: Gaussians,
    removed: np.ndarray,
    kept: Gaussians,
    views: Sequence[Masked],
    environment: Environment | None,
    sh_degree: int,
    options: FillOptions,
    backend: Backend,
    progress: bool,
) -> tuple[list[_Shown], list[SurfaceView]]:
    """Up to :attr:`FillOptions.fit_views` of the views in which the removed Gaussians showed,
    spread over them (:class:`_Shown`), and every view with its surface depth of the whole
    model."""
    whole = gaussians.detach().to(backend.device)
    alone = whole.select(torch.as_tensor(removed, device=backend.device))
    poses = [torch.as_tensor(v.cam_from_world, dtype=torch.float32, device=backend.device) for v in views]
    rim = np.ones((2 * options.rim + 1,) * 2, np.uint8)
    silhouettes, depths = [], []
    with torch.no_grad():
        for view, pose in zip(tqdm(views, desc="fill: silhouettes", unit="view", disable=not progress), poses):
            labels, out = render_labels(whole, removed.astype(np.uint8), view.camera, pose, backend=backend)
            depths.append(surface_depth(out))
            silhouettes.append(cv2.dilate((labels == 1).astype(np.uint8), rim) > 0)
        seen_by = [(v.camera, np.asarray(v.cam_from_world, np.float64), d) for v, d in zip(views, depths)]
        shown = []
        for i in _spread([i for i, s in enumerate(silhouettes) if s.any()], options.fit_views):
            view, pose = views[i], poses[i]
            bg = background_image(environment, view.camera, pose)
            out = render(
                kept, view.camera, pose, sh_degree=sh_degree, background=bg, with_features=False, backend=backend
            )
            depth = surface_depth(out)
            alone_out = render(alone, view.camera, pose, sh_degree=0, with_features=False, backend=backend)
            in_front = (surface_depth(alone_out) > 0) & ~silhouettes[i]  # its footprint where it does not show
            others = seen_by[:i] + seen_by[i + 1 :]
            unseen = unseen_pixels(silhouettes[i], depth, *seen_by[i][:2], others, options.depth_tolerance)
            unseen = cv2.morphologyEx(unseen.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8)) > 0
            shown.append(_Shown(i, silhouettes[i], unseen, in_front, to_uint8(out.rgb), depth))
    return shown, seen_by


def _seed(
    holes: list[_Shown],
    targets: dict[int, np.ndarray],
    views: Sequence[Masked],
    seen_by: list[SurfaceView],
    features: int,
    options: FillOptions,
) -> Gaussians:
    """New Gaussians on the unseen pixels of ``holes``, at their inpainted colour and on the
    surface around each hole (:func:`surface_across`), none in space a view saw through."""
    points, colours, sizes = [], [], []
    for s in holes:
        view = views[s.index]
        ring_depth = np.where(s.in_front, 0.0, s.depth)  # what stands in front carries no surface across
        depth = surface_across(s.unseen, ring_depth, view.camera, options.depth_radius, options.depth_tolerance)
        p, c, r = _grid_points(
            s.unseen, depth, targets[s.index], view.camera, np.asarray(view.cam_from_world), options.stride
        )
        points.append(p)
        colours.append(c)
        sizes.append(r)
    points, colours, sizes = np.concatenate(points), np.concatenate(colours), np.concatenate(sizes)
    hidden = ~seen_through(points, seen_by, options.depth_tolerance)
    seeds = gaussians_from_points(points[hidden], colours[hidden], initial_opacity=options.initial_opacity)
    seeds.log_scales = torch.log(torch.as_tensor(sizes[hidden], dtype=torch.float32))[:, None].repeat(1, 3)
    seeds.obj_feat = torch.zeros(len(seeds), features)
    return seeds


def _crop(
    shown: _Shown,
    target: np.ndarray,
    view: Masked,
    kept: Gaussians,
    environment: Environment | None,
    options: FillOptions,
    backend: Backend,
) -> _Crop:
    """The fit's step in one view: its silhouette's box widened by the margin."""
    rows, cols = mask_box(shown.silhouette, options.margin)
    x0, y0, x1, y1 = cols.start, rows.start, cols.stop, rows.stop
    camera = crop_camera(view.camera, x0, y0, x1, y1)
    pose = torch.as_tensor(view.cam_from_world, dtype=torch.float32, device=backend.device)
    with torch.no_grad():  # the environment is frozen too
        drawn = render(kept, camera, pose, sh_degree=0, with_features=False, backend=backend).radii > 0
        background = background_image(environment, camera, pose)
    pixels = torch.as_tensor(target[y0:y1, x0:x1], dtype=torch.float32, device=backend.device) / 255
    return _Crop(camera, pose, pixels, background, kept.select(drawn))


def _fit(
    seeds: Gaussians,
    crops: list[_Crop],
    sh_degree: int,
    extent: float,
    options: FillOptions,
    backend: Backend,
    progress: bool,
) -> Gaussians:
    """``seeds`` optimised (:data:`FITTED` alone) in front of the crops' frozen Gaussians to
    their targets, one crop a step."""
    if not len(seeds):
        return seeds
    optimizer = GaussianOptimizer(seeds, LearningRates(), extent)
    for name in set(Gaussians.field_names()) - set(FITTED):
        optimizer.params[name].requires_grad_(False)
    order = np.random.default_rng(options.seed).integers(0, len(crops), options.steps)
    with torch.enable_grad():  # also where the caller renders without gradients
        for k in tqdm(order, desc="fill: fitting", unit="step", disable=not progress):
            crop, fill = crops[k], optimizer.gaussians
            scene = Gaussians.concat(crop.drawn, fill)
            out = render(
                scene,
                crop.camera,
                crop.pose,
                sh_degree=sh_degree,
                background=crop.background,
                with_features=False,
                backend=backend,
            )
            photometric_loss(out.rgb, crop.target, options.lambda_dssim).backward()
            optimizer.step()
    return optimizer.gaussians.detach()
