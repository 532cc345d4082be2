"""The synthetic scene generator: layout, ray casting, SfM points with tracks, scene folder."""

from __future__ import annotations

import colorsys
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from dataset_tools import colmap
from dataset_tools.cameras import PinholeCamera
from dataset_tools.image_files import encode_png
from dataset_tools.infra.atomic import atomic_directory, write_bytes_atomic
from dataset_tools.infra.errors import OptionError, OutputExists, check_seed
from dataset_tools.mask_manifest import MANIFEST, manifest_bytes
from dataset_tools.scene import GT_MASKS, llff_test_names
from dataset_tools.synth import camera_paths
from dataset_tools.synth.primitives import Box, Cylinder, Plane, Primitive, Sphere
from dataset_tools.synth.textures import Texture

MAX_OBJECTS = 255
LIGHT = np.array([0.45, -0.35, 0.82]) / np.linalg.norm([0.45, -0.35, 0.82])
AMBIENT = 0.4
PATHS = ("orbit", "forward")  # a camera orbit around the objects, or a forward-facing sweep
GROUNDS = ("checker", "speckle")


@dataclass(frozen=True)
class SynthConfig:
    """Options of a synthetic scene. The same options give the same bytes."""

    views: int = 24
    res: int = 256
    objects: int = 6
    path: str = "orbit"  # one of PATHS
    seed: int = 0
    wall: bool | None = None  # None: a back wall for ``forward`` only
    ground: str = "checker"  # one of GROUNDS; speckle: irregular, for structure from motion
    points_per_view: int = 200
    supersample: int = 2
    fov_deg: float = 50.0

    def validate(self) -> None:
        if not 1 <= self.objects <= MAX_OBJECTS:
            raise OptionError(
                f"{{objects}}: a scene holds 1..{MAX_OBJECTS} objects (8-bit masks); choose fewer.",
                objects=self.objects,
            )
        if self.views < 2:
            raise OptionError("{views}: at least 2 views are needed for SfM tracks.", views=self.views)
        if not 16 <= self.res <= 4096:
            raise OptionError("{res}: the resolution must lie in 16..4096 pixels.", res=self.res)
        if self.path not in PATHS:
            raise OptionError(f"{{path}}: use {' or '.join(PATHS)}.", path=self.path)
        if self.ground not in GROUNDS:
            raise OptionError(f"{{ground}}: use {' or '.join(GROUNDS)}.", ground=self.ground)
        check_seed(self.seed)


@dataclass(frozen=True)
class SceneObject:
    """An object of the scene: its mask ID, shape and texture."""

    id: int
    kind: str
    shape: Primitive
    texture: Texture

    @property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        s = self.shape
        if isinstance(s, Sphere):
            return np.asarray(s.center), s.radius
        if isinstance(s, Box):
            return np.asarray(s.center), float(np.linalg.norm(s.half))
        c = np.asarray(s.base) + [0.0, 0.0, s.height / 2]
        return c, float(np.hypot(s.radius, s.height / 2))


@dataclass
class Layout:
    objects: list[SceneObject]
    background: list[tuple[Plane, Texture]]  # ground, optional wall; mask ID 0
    center: np.ndarray  # (3,) point the cameras look at
    extent: float  # radius of the region holding the objects


@dataclass
class SynthResult:
    """What the generator wrote, plus ground truth that a scene folder cannot hold."""

    root: Path
    layout: Layout
    point_object_ids: np.ndarray  # (P,) object ID of every points3D row (0 = background)


def _object_color(k: int, offset: float) -> tuple[tuple[float, ...], tuple[float, ...]]:
    hue = (offset + 0.618033988749895 * k) % 1.0
    return colorsys.hsv_to_rgb(hue, 0.7, 0.9), colorsys.hsv_to_rgb((hue + 0.06) % 1.0, 0.55, 0.5)


def make_layout(cfg: SynthConfig, rng: np.random.Generator) -> Layout:
    """Place ``cfg.objects`` non-overlapping primitives standing on the ground plane."""
    scale = min(1.0, np.sqrt(6 / cfg.objects))
    extent = 1.3 * np.sqrt(max(cfg.objects, 6) / 6) * scale**0.5
    depth = 0.6 * extent if cfg.path == "forward" else extent
    hue_offset = rng.uniform()
    placed: list[tuple[float, float, float]] = []
    objects = []
    for k in range(1, cfg.objects + 1):
        kind = str(rng.choice(["sphere", "box", "cylinder"]))
        size = rng.uniform(0.25, 0.45) * scale
        footprint = {"sphere": size, "box": size * 1.2, "cylinder": size * 0.8}[kind]
        for _ in range(5000):
            x, y = rng.uniform(-extent, extent), rng.uniform(-depth, depth)
            if cfg.path == "orbit" and np.hypot(x, y) > extent:
                continue
            if all(np.hypot(x - px, y - py) > footprint + pr + 0.06 * scale for px, py, pr in placed):
                break
        else:
            raise OptionError(
                "{objects}: cannot place that many objects without overlap; choose fewer.", objects=cfg.objects
            )
        placed.append((x, y, footprint))
        if kind == "sphere":
            shape: Primitive = Sphere((x, y, size), size)
        elif kind == "box":
            half = (size * rng.uniform(0.6, 0.85), size * rng.uniform(0.6, 0.85), size * rng.uniform(0.7, 1.3))
            shape = Box((x, y, half[2]), half, float(rng.uniform(0, np.pi)))
        else:
            shape = Cylinder((x, y, 0.0), size * 0.8, size * rng.uniform(1.5, 2.6))
        color_a, color_b = _object_color(k, hue_offset)
        pattern = str(rng.choice(["checker", "stripes", "waves", "plain"]))
        axis = rng.normal(size=3)
        texture = Texture(
            pattern,
            color_a,
            color_b,
            origin=(x, y, 0.0),
            scale=size * rng.uniform(0.35, 0.7),
            axis=tuple(axis / np.linalg.norm(axis)),
        )
        objects.append(SceneObject(k, kind, shape, texture))
    ground = (
        Plane((0.0, 0.0, 1.0), 0.0),
        Texture("checker", (0.72, 0.68, 0.6), (0.45, 0.42, 0.38), scale=0.5, fade=4 * extent)
        if cfg.ground == "checker"
        else Texture("speckle", (0.78, 0.72, 0.62), (0.3, 0.27, 0.24), scale=0.25),
    )
    background = [ground]
    if cfg.wall if cfg.wall is not None else cfg.path == "forward":
        wall = Plane((0.0, -1.0, 0.0), -(depth + 1.0))
        background.append(
            (wall, Texture("stripes", (0.62, 0.66, 0.7), (0.5, 0.55, 0.6), scale=0.35, axis=(1.0, 0.0, 0.3)))
        )
    max_h = max(o.bounding_sphere[0][2] + o.bounding_sphere[1] for o in objects)
    return Layout(objects, background, np.array([0.0, 0.0, 0.3 * max_h]), extent)


@dataclass
class Hits:
    """Nearest intersections of N rays: distance (inf for sky), surface index (-1 for sky;
    background planes first, then objects), unit normal."""

    t: np.ndarray  # (N,)
    surface: np.ndarray  # (N,) int
    normal: np.ndarray  # (N, 3)


def trace(layout: Layout, origin: np.ndarray, d: np.ndarray) -> Hits:
    """Nearest surface along rays from one ``origin`` (3,) along unit directions ``d`` (N, 3)."""
    n = len(d)
    o = np.broadcast_to(origin, d.shape)
    hits = Hits(np.full(n, np.inf), np.full(n, -1), np.zeros((n, 3)))

    def keep_closer(rows: np.ndarray, t: np.ndarray, nrm: np.ndarray, s: int) -> None:
        closer = t < hits.t[rows]
        idx = rows[closer]
        hits.t[idx], hits.surface[idx], hits.normal[idx] = t[closer], s, nrm[closer]

    everything = np.arange(n)
    for s, (plane, _) in enumerate(layout.background):
        keep_closer(everything, *plane.intersect(o, d), s)
    for k, ob in enumerate(layout.objects):
        c, r = ob.bounding_sphere
        b = d @ (origin - c)  # rays that pass within r of the centre, ahead of the camera
        cand = np.flatnonzero((b * b >= np.sum((origin - c) ** 2) - r * r) & (b < r))
        if len(cand):
            keep_closer(cand, *ob.shape.intersect(o[cand], d[cand]), len(layout.background) + k)
    return hits


def object_ids(layout: Layout, hits: Hits) -> np.ndarray:
    """Mask ID of every ray: the object's ID, 0 for ground, wall and sky. (N,) int64."""
    ids_of_surface = np.array([0] * len(layout.background) + [ob.id for ob in layout.objects])
    return np.where(hits.surface >= 0, ids_of_surface[np.maximum(hits.surface, 0)], 0)


def shade(
    layout: Layout, origin: np.ndarray, d: np.ndarray, hits: Hits, sky: tuple[float, float, float] | None = None
) -> np.ndarray:
    """Colour of every ray in [0, 1], (N, 3): albedo times ambient + Lambert, or the sky (a
    gradient by elevation, or the flat colour ``sky``)."""
    textures = [tex for _, tex in layout.background] + [ob.texture for ob in layout.objects]
    if sky is None:
        w = np.clip(d[:, 2], 0.0, 1.0)[:, None] ** 0.5
        rgb = (1 - w) * np.array([0.86, 0.9, 0.95]) + w * np.array([0.45, 0.62, 0.86])
    else:
        rgb = np.tile(np.asarray(sky, float), (len(d), 1))
    points = origin + np.where(np.isfinite(hits.t), hits.t, 0.0)[:, None] * d
    light = AMBIENT + (1 - AMBIENT) * np.clip(hits.normal @ LIGHT, 0.0, 1.0)
    for s in np.unique(hits.surface[hits.surface >= 0]):
        m = hits.surface == s
        rgb[m] = textures[s].albedo(points[m]) * light[m, None]
    return rgb


def _rays(cam: PinholeCamera, pose: np.ndarray, du: float, dv: float) -> tuple[np.ndarray, np.ndarray]:
    """World rays through pixel positions (j + du, i + dv): the camera centre (3,) and unit
    directions (H*W, 3)."""
    u, v = np.meshgrid(np.arange(cam.width) + du, np.arange(cam.height) + dv)
    dirs_cam = np.stack([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, np.ones_like(u)], -1).reshape(-1, 3)
    R, t = pose[:, :3], pose[:, 3]
    d = dirs_cam @ R  # R.T @ d_cam for each row
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return -R.T @ t, d


def render_view(
    layout: Layout,
    cam: PinholeCamera,
    pose: np.ndarray,
    supersample: int = SynthConfig.supersample,
    sky: tuple[float, float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ray-cast one view (the sky a flat ``sky`` colour when given).

    Returns rgb (H, W, 3) uint8 (box-filtered over supersample^2 rays a pixel), ids (H, W)
    uint8 at pixel centres, z-depth (H, W) float64 at pixel centres (inf for sky), and the
    (H*W, 3) surface points of the centre rays.
    """
    H, W = cam.height, cam.width
    o, d = _rays(cam, pose, 0.5, 0.5)
    hits = trace(layout, o, d)
    points = o + np.where(np.isfinite(hits.t), hits.t, 0.0)[:, None] * d
    depth = (hits.t * (d @ pose[2, :3])).reshape(H, W)
    acc = np.zeros((H * W, 3))
    offsets = (np.arange(supersample) + 0.5) / supersample
    for dv in offsets:
        for du in offsets:
            o, d = _rays(cam, pose, du, dv)
            acc += shade(layout, o, d, trace(layout, o, d), sky)
    rgb = np.clip(np.rint(acc / supersample**2 * 255), 0, 255).astype(np.uint8).reshape(H, W, 3)
    return rgb, object_ids(layout, hits).reshape(H, W).astype(np.uint8), depth, points


def observe(
    points: np.ndarray, cam: PinholeCamera, pose: np.ndarray, depth: np.ndarray, rel_tol: float = 0.01
) -> tuple[np.ndarray, np.ndarray]:
    """Which points a view sees: inside the image and not occluded (depth test).

    Returns (rows (M,) into ``points``, uv (M, 2) pixel coordinates).
    """
    pc = points @ pose[:, :3].T + pose[:, 3]
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = pc[:, :2] / z[:, None] * [cam.fx, cam.fy] + [cam.cx, cam.cy]
    inside = (z > 1e-6) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
    rows = np.flatnonzero(inside)
    px = uv[rows].astype(int)
    seen = np.abs(depth[px[:, 1], px[:, 0]] - z[rows]) <= rel_tol * z[rows]
    return rows[seen], uv[rows[seen]]


def generate_scene(cfg: SynthConfig, out: Path | str, *, overwrite: bool = False, progress: bool = True) -> SynthResult:
    """Ray-cast a synthetic scene and write it as a scene folder at ``out``.

    Writes images/*.png, gt_mask/*.png (exact IDs: 0 background, 1..K objects; its
    manifest.json marks them as ground truth),
    sparse/0 (PINHOLE cameras, points3D sampled on visible surfaces, with the tracks of
    every view that sees them) and scene.json (objects, options, LLFF split).
    """
    cfg.validate()
    out = Path(out)
    if out.exists() and not overwrite:
        raise OutputExists(out)
    rng = np.random.default_rng(cfg.seed)
    layout = make_layout(cfg, rng)
    f = 0.5 * cfg.res / np.tan(np.deg2rad(cfg.fov_deg) / 2)
    cam = PinholeCamera(cfg.res, cfg.res, f, f, cfg.res / 2, cfg.res / 2)
    dist = 2.6 * layout.extent + 0.8
    poses = (camera_paths.orbit if cfg.path == "orbit" else camera_paths.forward)(cfg.views, dist, layout.center)
    names = [f"{k:04d}.png" for k in range(cfg.views)]

    with atomic_directory(out, overwrite=overwrite) as tmp:
        depths, samples, sample_ids, sample_rgb = [], [], [], []
        for name, pose in zip(tqdm(names, desc="ray-casting views", disable=not progress), poses):
            rgb, ids, depth, pts = render_view(layout, cam, pose, cfg.supersample)
            write_bytes_atomic(tmp / "images" / name, encode_png(rgb))
            write_bytes_atomic(tmp / GT_MASKS / name, encode_png(ids))
            depths.append(depth)
            hit = np.flatnonzero(np.isfinite(depth.ravel()))
            pick = np.sort(rng.choice(hit, size=min(cfg.points_per_view, len(hit)), replace=False))
            samples.append(pts[pick])
            sample_ids.append(ids.ravel()[pick])
            sample_rgb.append(rgb.reshape(-1, 3)[pick])
        write_bytes_atomic(tmp / GT_MASKS / MANIFEST, manifest_bytes("dataset_tools synth", truth=True))
        xyz, point_ids, point_rgb = np.concatenate(samples), np.concatenate(sample_ids), np.concatenate(sample_rgb)
        obs = [observe(xyz, cam, pose, depth) for pose, depth in zip(poses, depths)]
        n_obs = np.bincount(np.concatenate([rows for rows, _ in obs]), minlength=len(xyz))
        keep = n_obs >= 2
        new_row = np.cumsum(keep) - 1
        obs = [(new_row[rows[keep[rows]]], uv[keep[rows]]) for rows, uv in obs]
        colmap.write_model(tmp / "sparse" / "0", names, [cam] * cfg.views, poses, obs, xyz[keep], point_rgb[keep])
        meta = {
            "objects": {str(o.id): {"name": f"{o.kind}_{o.id}", "kind": o.kind} for o in layout.objects},
            "provenance": {"generator": "dataset_tools.synth", "config": asdict(cfg)},
            "split": {"test": sorted(llff_test_names(names))},
        }
        write_bytes_atomic(tmp / "scene.json", json.dumps(meta, indent=2, sort_keys=True).encode())
    return SynthResult(out, layout, point_ids[keep].astype(np.int64))
