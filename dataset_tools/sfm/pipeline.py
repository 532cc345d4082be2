"""Structure from motion with pycolmap on the CPU: photos or a video in, a scene folder out.

Steps, each recorded with its options in ``SCENE/.sfm/steps.json`` when it finishes, so that
a second call continues after the last finished one (and redoes a step whose options
changed, with every step after it):

1. ``images``: the photos as they are, or a video's frames (:mod:`dataset_tools.sfm.frames`);
2. ``features``: SIFT on every image into ``.sfm/database.db`` (one shared camera for a video,
   one per folder of photos by default), its peak threshold lowered for small images
   (:func:`sift_peak_threshold`);
3. ``matches``: exhaustive for up to ``EXHAUSTIVE_UP_TO`` photos; past that, each with its
   ``neighbours`` most alike (:mod:`dataset_tools.sfm.retrieval`); for a video, sequential
   (each image with its next ``overlap`` and at powers of two further) plus every pair of
   keyframes spread over the sequence, which closes loops without a vocabulary tree;
4. ``mapping``: incremental (its pixel thresholds scaled to the image size,
   :func:`incremental_options`) or global mapping; the model with the most images is kept and
   the others reported, with a video's frames turned far from the frame before (flips);
5. ``undistort``: the kept model undistorted to PINHOLE cameras.

Then the scene folder is written: ``images/`` (undistorted), ``images_2/``, ``images_4/`` (and
``images_8/`` past 1600 px), ``sparse/0/`` and ``scene.json`` (what was run and how many
images registered), each item renamed into place, ``scene.json`` last.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import multiprocessing
import shutil
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image
from tqdm import tqdm

from dataset_tools.cameras import turned_frames
from dataset_tools.colmap import load_pycolmap
from dataset_tools.image_files import IMAGE_SUFFIXES, write_downsampled
from dataset_tools.infra.atomic import require_folder_path, write_bytes_atomic
from dataset_tools.infra.errors import InputError, OptionError, OutputExists
from dataset_tools.infra.locks import exclusive
from dataset_tools.infra.overlap import refuse_overlap
from dataset_tools.sfm import retrieval
from dataset_tools.sfm.frames import VIDEO_SUFFIXES, sample_frames

if TYPE_CHECKING:
    import pycolmap

STEPS = ("images", "features", "matches", "mapping", "undistort")
EXHAUSTIVE_UP_TO = 80
MIN_REGISTERED_SHARE = 0.5
# An image whose support (share of keypoints with a 3D point, discounted by how far they
# reproject) is under this share of the median image's is posed on too little to trust
# (weakly_posed).
WEAK_POSE_SHARE = 0.2
SIFT_PEAK_THRESHOLD = 0.02 / 3  # COLMAP's default, for photos of about REFERENCE_SIDE pixels
REFERENCE_SIDE = 1000
MATCHERS = ("auto", "exhaustive", "sequential", "retrieval")
MAPPERS = ("incremental", "global")
CAMERA_MODELS = ("SIMPLE_RADIAL", "RADIAL", "OPENCV", "SIMPLE_PINHOLE", "PINHOLE", "OPENCV_FISHEYE")


@dataclass(frozen=True)
class SfmConfig:
    """Options of ``python -m dataset_tools sfm`` (same names as the CLI)."""

    frames: int = 150  # a video's frames to keep
    matcher: str = "auto"  # one of MATCHERS; auto: by the number of photos, sequential for a video
    mapper: str = "incremental"  # one of MAPPERS
    camera_model: str = "SIMPLE_RADIAL"
    single_camera: bool | None = None  # None: one camera for a video, one per folder of photos
    max_image_size: int = 3200  # SIFT runs on images at most this large
    peak_threshold: float | None = None  # SIFT's; None: by the image size (sift_peak_threshold)
    scale_thresholds: bool = True  # the mapper's pixel thresholds scaled to the image size; False: COLMAP's
    overlap: int = 10  # sequential matching: each image with its next ``overlap``
    keyframes: int = 30  # sequential matching: keyframes matched exhaustively among themselves
    neighbours: int = 20  # retrieval matching: each image with this many most alike
    deterministic: bool = True  # SIFT and mapping on one thread: the same photos and seed, the same model
    seed: int = 0  # of the two-view verification's RANSAC and of the mapper

    def check(self) -> None:
        if self.frames < 3:
            raise OptionError("{frames}: keep at least 3 frames.", frames=self.frames)
        if self.matcher not in MATCHERS:
            raise OptionError(f"{{matcher}}: use {', '.join(MATCHERS)}.", matcher=self.matcher)
        if self.neighbours < 1:
            raise OptionError("{neighbours}: match each photo with at least 1 other.", neighbours=self.neighbours)
        if self.mapper not in MAPPERS:
            raise OptionError(f"{{mapper}}: use {' or '.join(MAPPERS)}.", mapper=self.mapper)
        if self.camera_model not in CAMERA_MODELS:
            raise OptionError(
                f"{{camera_model}}: use one of {', '.join(CAMERA_MODELS)}.", camera_model=self.camera_model
            )
        if self.max_image_size < 64:
            raise OptionError("{max_image_size}: give 64 pixels or more.", max_image_size=self.max_image_size)
        if self.peak_threshold is not None and not 0 < self.peak_threshold < 1:
            raise OptionError(
                f"{{peak_threshold}}: give a value between 0 and 1 (COLMAP's default is {SIFT_PEAK_THRESHOLD:.4f}).",
                peak_threshold=self.peak_threshold,
            )


@dataclass
class SfmResult:
    scene: Path
    images: int
    registered: int
    seconds: float
    other_models: list[int]
    flips: list[str]  # a video's frames turned > 45 degrees from the frame before (see turned_frames)
    left_out: list[str]  # images posed on too few points, left out of the model (see weakly_posed)

    def warning(self) -> str | None:
        """One sentence on the frames posed on the far side and the images left out, or None."""
        said = []
        if self.flips:
            said.append(
                f"{', '.join(self.flips)}: turned more than 45 degrees from the frame before, so probably posed on "
                "the far side of the object (the scene looks alike from two sides); check these cameras, or film "
                "with texture off the repeated surface in view (docs/sfm.md)."
            )
        if self.left_out:
            said.append(
                f"{', '.join(self.left_out)}: posed on too few points, or on points that fit them badly, and left "
                "out (an object turned on a turntable in front of a still background gives such photos; docs/sfm.md)."
            )
        return " ".join(said) or None


def _scene_folders(photos: Path) -> set[Path]:
    """Scene folders inside ``photos`` (an earlier output, or a copy of one): never photos."""
    marks = (*photos.rglob("scene.json"), *photos.rglob("sparse"), *photos.rglob(".sfm"))
    return {m.parent for m in marks}


def _input_images(photos: Path) -> list[str]:
    """The image files of a folder (sub-folders too, but no hidden folder or scene folder),
    relative, sorted; each checked whole."""
    scenes = _scene_folders(photos)
    names = sorted(
        str(p.relative_to(photos))
        for p in photos.rglob("*")
        if p.suffix in IMAGE_SUFFIXES
        and not any(part.startswith(".") for part in p.relative_to(photos).parts)
        and not any(p.is_relative_to(s) for s in scenes)
    )
    if not names:
        raise InputError(f"{photos}: holds no JPEG or PNG images; pass a folder of photos or a video file.")
    for name in names:
        try:
            with Image.open(photos / name) as im:
                im.draft("RGB", (im.width // 8, im.height // 8))  # decode small: truncation still shows
                im.load()
        except (OSError, SyntaxError, ValueError) as e:
            raise InputError(f"{photos / name}: not a readable image ({e}); remove or replace it.") from None
    return names


def content_digest(files: list[Path]) -> str:
    """A hash of the names, sizes and bytes of ``files``: the steps of a run are redone when the
    photos change, even under the same names (about 1 s a GB)."""
    h = hashlib.blake2b(digest_size=16)
    for f in files:
        h.update(f"{f.name}\0{f.stat().st_size}\0".encode())
        with open(f, "rb") as stream:
            while chunk := stream.read(1 << 20):
                h.update(chunk)
    return h.hexdigest()


def _image_sizes(folder: Path, names: list[str]) -> list[tuple[int, int]]:
    """The distinct (width, height) of the images, sorted."""
    sizes = set()
    for name in names:
        with Image.open(folder / name) as im:
            sizes.add(im.size)
    return sorted(sizes)


def _check_free_space(photos: Path, out: Path, n_images: int) -> None:
    """Refuse to start on a disk without room for the work: the database (about 2 MB an image),
    the undistorted images and their smaller copies (about 3x the photos)."""
    source = [photos] if photos.is_file() else [p for p in photos.rglob("*") if p.is_file()]
    need = 3 * sum(p.stat().st_size for p in source) + n_images * 2_000_000 + 50_000_000
    existing = next(p for p in (out, *out.parents) if p.exists())
    free = shutil.disk_usage(existing).free
    if free < need:
        raise OptionError(
            f"{free / 1e9:.2f} GB free, structure from motion needs about {need / 1e9:.2f} GB; free some "
            "disk space or write {out} elsewhere.",
            file=existing,
        )


def pixel_scale(side: int) -> float:
    """How COLMAP's defaults, set for photos of about ``REFERENCE_SIDE`` px, scale to images
    whose longest side is ``side`` pixels: 1 at that size and above, in proportion below it,
    a quarter at least."""
    return min(1.0, max(0.25, side / REFERENCE_SIDE))


def sift_peak_threshold(side: int) -> float:
    """SIFT's peak (contrast) threshold for images whose longest side is ``side`` pixels:
    COLMAP's default scaled by :func:`pixel_scale`. A small image holds fewer blobs above a
    fixed contrast: at the default, the beer photos at 320 px give 60-300 keypoints each and
    leave views unregistered."""
    return SIFT_PEAK_THRESHOLD * pixel_scale(side)


def incremental_options(scale: float, seed: int, threads: int) -> pycolmap.IncrementalPipelineOptions:
    """COLMAP's incremental mapper options with its reprojection-error thresholds (the initial
    pair, registering an image, triangulating, filtering points; 4 and 12 px) times ``scale``
    (:func:`pixel_scale` of the image size, by default). They decide which observations the
    bundle adjustment fits: on small images 4 px is a large share of the frame, and the loose
    observations it lets in bend the cameras (the beer photos at 320 px: median rotation error
    0.8-1.3 degrees by seed at 4 px, 0.4 at the scaled thresholds; docs/sfm.md). The two-view
    verification keeps COLMAP's 4 px: it only proposes matches, which the mapper then judges
    at its own thresholds, and a tighter one loses images."""
    pycolmap = load_pycolmap()

    options = pycolmap.IncrementalPipelineOptions(random_seed=seed, num_threads=threads)
    for owner, name in (
        (options.mapper, "init_max_error"),
        (options.mapper, "abs_pose_max_error"),
        (options.mapper, "filter_max_reproj_error"),
        (options.triangulation, "complete_max_reproj_error"),
        (options.triangulation, "merge_max_reproj_error"),
    ):
        setattr(owner, name, getattr(owner, name) * scale)
    return options


def weakly_posed(names: list[str], keypoints: np.ndarray, triangulated: np.ndarray, residuals: np.ndarray) -> list[str]:
    """Those of the registered images ``names`` whose support is under :data:`WEAK_POSE_SHARE`
    of the median image's: the share of its ``keypoints`` (N,) that hold a 3D point
    (``triangulated`` (N,)), over the median share, divided by the mean distance in pixels at
    which those points reproject (``residuals`` (N,)), over the median distance, where that
    is above one.
    Such a pose rests on a few matches that may belong to something else: an object turned on
    a turntable in front of a still background gives photos the mapper poses from the
    background, on top of other photos' places (nerd_ethiopian_head: 7 of 66 photos at 10-17%
    of the median share; in another mapping of the same photos 6 at 21-27%, whose points
    reproject 1.5-1.8 times as far as the median photo's, support 11-18%), rendering the back
    of the head where the photo shows its face; the photos posed right on four other captures
    have a support of at least 23% (docs/sfm.md)."""
    shares = np.asarray(triangulated, float) / np.maximum(np.asarray(keypoints, float), 1)
    median_share = float(np.median(shares)) if len(shares) else 0.0
    if median_share <= 0:
        return []
    residuals = np.asarray(residuals, float)
    spread = np.maximum(residuals / max(float(np.median(residuals)), 1e-12), 1.0)  # a better fit earns nothing
    support = shares / median_share / spread
    return sorted(name for name, held in zip(names, support) if held < WEAK_POSE_SHARE)


def mean_residuals(model: pycolmap.Reconstruction) -> np.ndarray:
    """(N,) each registered image of the pycolmap ``model`` (in ``model.images`` order): the
    mean distance in pixels between its keypoints that hold a 3D point and where that point
    projects (0 where none does)."""
    out = []
    for image in model.images.values():
        residuals = [
            np.linalg.norm(image.project_point(model.points3D[p.point3D_id].xyz) - p.xy)
            for p in image.points2D
            if p.has_point3D()
        ]
        out.append(float(np.mean(residuals)) if residuals else 0.0)
    return np.array(out)


def sequential_pairs(n: int, cfg: SfmConfig) -> list[tuple[int, int]]:
    """Pairs (i < j) of n images in order: each with its next ``overlap`` and at powers of two
    further, and every pair of ``keyframes`` spread over the sequence (loop closure)."""
    pairs = set()
    for i in range(n):
        for j in range(i + 1, min(n, i + cfg.overlap + 1)):
            pairs.add((i, j))
        step = 1
        while i + step < n:
            pairs.add((i, i + step))
            step *= 2
    keys = sorted({round(k) for k in (i * (n - 1) / max(1, cfg.keyframes - 1) for i in range(min(n, cfg.keyframes)))})
    pairs |= set(itertools.combinations(keys, 2))
    return sorted(pairs)


def retrieval_pairs(pycolmap, database: Path, names: list[str], cfg: SfmConfig) -> list[tuple[int, int]]:
    """Pairs (i < j) of the images ``names``: each with its ``neighbours`` most alike by the
    VLAD vectors of their SIFT descriptors in ``database``
    (:mod:`dataset_tools.sfm.retrieval`)."""
    db = pycolmap.Database.open(str(database))
    try:
        ids = {image.name: image.image_id for image in db.read_all_images()}
        descriptors = [np.asarray(db.read_descriptors(ids[name]).data) for name in names]
    finally:
        db.close()
    centres = retrieval.vocabulary(descriptors, seed=cfg.seed)
    return retrieval.similar_pairs(retrieval.vlad(descriptors, centres, seed=cfg.seed), cfg.neighbours)


def _write_pairs(names: list[str], pairs: list[tuple[int, int]], path: Path) -> None:
    path.write_text("".join(f"{names[i]} {names[j]}\n" for i, j in pairs))


class _Steps:
    """The record of finished steps in ``work/steps.json``."""

    def __init__(self, work: Path):
        self.path = work / "steps.json"
        self.done: dict = json.loads(self.path.read_text()) if self.path.is_file() else {}
        self.started = time.perf_counter()

    def finished(self, step: str, options: dict) -> bool:
        """Whether ``step`` finished with these options; if not, it and every later step are forgotten."""
        if self.done.get(step, {}).get("options") == options:
            return True
        for later in STEPS[STEPS.index(step) :]:
            self.done.pop(later, None)
        self.started = time.perf_counter()
        return False

    def record(self, step: str, options: dict, **facts) -> None:
        """Record ``step`` as finished with ``options``, its ``facts`` and the seconds it took."""
        self.done[step] = {"options": options, **facts, "seconds": round(time.perf_counter() - self.started, 2)}
        write_bytes_atomic(self.path, (json.dumps(self.done, indent=2) + "\n").encode())


def run_sfm(
    photos: Path | str, out: Path | str, cfg: SfmConfig = SfmConfig(), *, overwrite: bool = False, progress: bool = True
) -> SfmResult:
    """Make a scene folder at ``out`` from a folder of photos or a video file ``photos``.

    The steps run in a fresh process (started with ``spawn``): a model made in a process that
    had made others has come out different (docs/sfm.md), most likely from state COLMAP keeps
    from one model to the next. A script that calls this needs the ``if __name__ == "__main__":``
    guard that ``multiprocessing`` asks of every spawning script."""
    cfg.check()
    photos, out = Path(photos), Path(out)
    if not photos.exists():
        raise InputError(f"{photos}: not found; pass a folder of photos or a video file.")
    video = photos.is_file()
    if video and photos.suffix not in VIDEO_SUFFIXES:
        raise InputError(f"{photos}: not a folder of photos nor a video ({', '.join(VIDEO_SUFFIXES[:5])}).")
    require_folder_path(out)
    refuse_overlap(out, [("the photos", photos)])
    if (out / "scene.json").exists() and not overwrite:
        raise OptionError(
            "already holds a scene; pass {overwrite} to make it again or choose another {out}.",
            file=out,
            overwrite=True,
        )
    found = None if video else _input_images(photos)
    _check_free_space(photos, out, cfg.frames if video else len(found))
    work = out / ".sfm"
    new_out, new_work = not out.exists(), not work.exists()
    try:
        with exclusive(work / "lock", out, "this scene"):
            with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as fresh:
                return fresh.submit(_run_job, photos, out, work, video, found, cfg, progress, overwrite).result()
    except InputError:  # a refusal leaves nothing behind; an interruption keeps the finished steps
        if new_work:
            shutil.rmtree(work, ignore_errors=True)
        if new_out and out.is_dir() and not any(out.iterdir()):
            out.rmdir()
        raise


def _run_job(
    photos: Path,
    out: Path,
    work: Path,
    video: bool,
    found: list[str] | None,
    cfg: SfmConfig,
    progress: bool,
    overwrite: bool,
) -> SfmResult:
    """:func:`run_sfm`'s steps, in the fresh process; the caller holds the lock on ``work``."""
    pycolmap = load_pycolmap()  # after the image libraries: importing it first breaks PNG writes
    return _SfmJob(pycolmap, photos, out, work, video, found, cfg, _Steps(work), progress).run(overwrite)


@dataclass
class _SfmJob:
    """One call of :func:`run_sfm`: a method per step, each skipped when ``steps`` records it
    finished with the same options."""

    pycolmap: ModuleType
    photos: Path
    out: Path
    work: Path
    video: bool
    found: list[str] | None  # the photos (None for a video)
    cfg: SfmConfig
    steps: _Steps
    progress: bool

    @property
    def threads(self) -> int:
        # On several threads COLMAP's CPU SIFT gives slightly different keypoints from run to run
        # and its bundle adjustment (Ceres) rounds differently: one thread gives the same model
        # again. Matching runs on every core: each pair is matched and verified on its own, with
        # the RANSAC seeded, into tables keyed by the pair (docs/sfm.md).
        return 1 if self.cfg.deterministic else -1

    @property
    def image_dir(self) -> Path:
        return self.work / "frames" if self.video else self.photos

    @property
    def database(self) -> Path:
        return self.work / "database.db"

    def images(self) -> tuple[list[str], list[tuple[int, int]]]:
        """The photos as they are, or a video's frames: their names and distinct sizes."""
        options = {
            "source": str(self.photos.resolve()),
            "frames": self.cfg.frames if self.video else None,
            "content": content_digest([self.photos] if self.video else [self.photos / n for n in self.found]),
        }
        if not self.steps.finished("images", options):
            shutil.rmtree(self.work / "frames", ignore_errors=True)
            names = (
                sample_frames(self.photos, self.image_dir, self.cfg.frames, progress=self.progress)
                if self.video
                else self.found
            )
            self.steps.record("images", options, names=names, sizes=_image_sizes(self.image_dir, names))
        done = self.steps.done["images"]
        return done["names"], [tuple(s) for s in done.get("sizes", [])]

    def features(self, names: list[str], sizes: list[tuple[int, int]]) -> int:
        """SIFT on every image into the database; returns the longest side SIFT saw."""
        single = self.video if self.cfg.single_camera is None else self.cfg.single_camera
        mixed = len(sizes) > 1
        if mixed and single:
            raise InputError(
                f"{self.photos}: the images have {len(sizes)} sizes ({', '.join(f'{w}x{h}' for w, h in sizes)}) "
                "and one camera cannot fit them; resize them to one size or let each size have its camera."
            )
        with Image.open(self.image_dir / names[0]) as im:
            side = min(max(im.size), self.cfg.max_image_size)
        peak = self.cfg.peak_threshold or sift_peak_threshold(side)
        options = {
            "camera_model": self.cfg.camera_model,
            "single_camera": single,
            "max_image_size": self.cfg.max_image_size,
            "peak_threshold": peak,
            "deterministic": self.cfg.deterministic,
            "camera_per_image": mixed,
        }
        if not self.steps.finished("features", options):
            self.database.unlink(missing_ok=True)
            extraction = self.pycolmap.FeatureExtractionOptions(
                max_image_size=self.cfg.max_image_size, use_gpu=False, num_threads=self.threads
            )
            extraction.sift.peak_threshold = peak
            self.pycolmap.extract_features(
                self.database,
                self.image_dir,
                image_names=names,
                camera_mode=_camera_mode(self.pycolmap, single, mixed),
                reader_options=self.pycolmap.ImageReaderOptions(camera_model=self.cfg.camera_model),
                extraction_options=extraction,
                device=self.pycolmap.Device.cpu,
            )
            self.steps.record("features", options)
        return side

    def matches(self, names: list[str]) -> str:
        """Matched and verified image pairs in the database; returns the matcher used."""
        cfg, pycolmap = self.cfg, self.pycolmap
        if cfg.matcher != "auto":
            matcher = cfg.matcher
        elif self.video:
            matcher = "sequential"
        else:
            matcher = "retrieval" if len(names) > EXHAUSTIVE_UP_TO else "exhaustive"
        options = {
            "matcher": matcher,
            "overlap": cfg.overlap,
            "keyframes": cfg.keyframes,
            "neighbours": cfg.neighbours,
            "seed": cfg.seed,
        }
        if self.steps.finished("matches", options):
            return matcher
        _rebuild_database_without_matches(pycolmap, self.database)
        matching = pycolmap.FeatureMatchingOptions(use_gpu=False, num_threads=-1)  # the same matches on any count
        verification = pycolmap.TwoViewGeometryOptions()
        verification.ransac.random_seed = cfg.seed
        if matcher == "exhaustive":
            pycolmap.match_exhaustive(
                self.database,
                matching_options=matching,
                verification_options=verification,
                device=pycolmap.Device.cpu,
            )
        else:
            pairs = (
                sequential_pairs(len(names), cfg)
                if matcher == "sequential"
                else retrieval_pairs(pycolmap, self.database, names, cfg)
            )
            _write_pairs(names, pairs, self.work / "pairs.txt")
            pycolmap.match_image_pairs(
                self.database,
                matching_options=matching,
                pairing_options=pycolmap.ImportedPairingOptions(match_list_path=str(self.work / "pairs.txt")),
                verification_options=verification,
                device=pycolmap.Device.cpu,
            )
        self.steps.record("matches", options)
        return matcher

    def mapping(self, names: list[str], side: int) -> dict:
        """Cameras and points; the model with the most images is kept. Returns its record."""
        cfg, pycolmap, sparse = self.cfg, self.pycolmap, self.work / "sparse"
        scale = pixel_scale(side) if cfg.scale_thresholds else 1.0
        options = {"mapper": cfg.mapper, "seed": cfg.seed, "threshold_scale": scale}
        if not self.steps.finished("mapping", options):
            shutil.rmtree(sparse, ignore_errors=True)
            sparse.mkdir()
            if cfg.mapper == "incremental":
                mapper = incremental_options(scale, cfg.seed, self.threads)
                models = pycolmap.incremental_mapping(self.database, self.image_dir, sparse, mapper)
            else:
                mapper = pycolmap.GlobalPipelineOptions(random_seed=cfg.seed, num_threads=self.threads)
                models = pycolmap.global_mapping(self.database, self.image_dir, sparse, mapper)
            sizes = {int(k): m.num_reg_images() for k, m in models.items()}
            if not sizes:
                raise InputError(
                    f"{self.photos}: no two images could be matched into a model; the photos need more "
                    "overlap (take them 10-20 degrees apart around the object, with texture in view)."
                )
            best = max(sizes, key=lambda k: (sizes[k], -k))
            model = models[best]
            images = list(model.images.values())
            left_out = weakly_posed(
                [im.name for im in images],
                [len(im.points2D) for im in images],
                [im.num_points3D for im in images],
                mean_residuals(model),
            )
            for image in images:
                if image.name in left_out:
                    model.deregister_frame(image.frame_id)
            model.write(sparse / str(best))
            registered = sizes[best] - len(left_out)
            if registered < max(3, MIN_REGISTERED_SHARE * len(names)):
                raise InputError(
                    f"{self.photos}: {registered} of {len(names)} images registered; the photos need more "
                    "overlap (take them 10-20 degrees apart around the object, with texture in view)."
                )
            poses = {im.name: im.cam_from_world().matrix() for im in model.images.values() if im.has_pose}
            self.steps.record(
                "mapping",
                options,
                model=str(best),
                registered=registered,
                other_models=sorted((s for k, s in sizes.items() if k != best), reverse=True),
                points=model.num_points3D(),
                mean_reprojection_error=model.compute_mean_reprojection_error(),
                flips=turned_frames(poses, names) if self.video else [],
                left_out=left_out,
            )
        return self.steps.done["mapping"]

    def undistort(self, mapped: dict) -> None:
        """The kept model undistorted to PINHOLE cameras."""
        options = {"model": mapped["model"]}
        if not self.steps.finished("undistort", options):
            shutil.rmtree(self.work / "undistorted", ignore_errors=True)
            self.pycolmap.undistort_images(
                self.work / "undistorted", self.work / "sparse" / mapped["model"], self.image_dir, output_type="COLMAP"
            )
            self.steps.record("undistort", options)

    def run(self, overwrite: bool) -> SfmResult:
        """Every step, then the scene folder."""
        start = time.perf_counter()
        self.pycolmap.logging.minloglevel = 2  # warnings and errors only; progress is shown here
        with tqdm(total=len(STEPS) + 1, desc="sfm", unit="step", disable=not self.progress) as bar:
            names, sizes = self.images()
            bar.set_postfix_str(f"{len(names)} images")
            bar.update(1)
            side = self.features(names, sizes)
            bar.update(1)
            matcher = self.matches(names)
            bar.update(1)
            mapped = self.mapping(names, side)
            bar.update(1)
            self.undistort(mapped)
            bar.update(1)
            provenance = {
                **asdict(self.cfg),
                "matcher_used": matcher,
                "source": str(self.photos.resolve()),
                "images": len(names),
                **{k: v for k, v in mapped.items() if k != "options"},
            }
            _write_scene(self.work, self.out, {"sfm": provenance}, overwrite)
            bar.update(1)
        return SfmResult(
            self.out,
            len(names),
            mapped["registered"],
            time.perf_counter() - start,
            mapped["other_models"],
            mapped.get("flips", []),
            mapped.get("left_out", []),
        )


def _camera_mode(pycolmap, single: bool, mixed: bool) -> pycolmap.CameraMode:
    """One camera for all images, one per image where they have several sizes (phones mix
    portrait and landscape), else one per folder of photos."""
    if single:
        return pycolmap.CameraMode.SINGLE
    return pycolmap.CameraMode.PER_IMAGE if mixed else pycolmap.CameraMode.PER_FOLDER


def _rebuild_database_without_matches(pycolmap, database: Path) -> None:
    """Remove the matches an interrupted or earlier matching step left in the database."""
    db = pycolmap.Database.open(str(database))
    try:
        db.clear_matches()
        db.clear_two_view_geometries()
    finally:
        db.close()


def _write_scene(work: Path, out: Path, provenance: dict, overwrite: bool) -> None:
    """``images/``, ``images_N/``, ``sparse/0/`` and ``scene.json`` of ``out`` from the undistorted
    model, each built in ``work`` and renamed into place, ``scene.json`` last."""
    built = work / "scene"
    shutil.rmtree(built, ignore_errors=True)
    built.mkdir()
    shutil.copytree(work / "undistorted" / "images", built / "images")
    (built / "sparse").mkdir()
    shutil.copytree(work / "undistorted" / "sparse", built / "sparse" / "0")
    with Image.open(next(p for p in (built / "images").rglob("*") if p.is_file())) as im:
        side = max(im.size)
    for factor in (2, 4, 8):
        if factor < 8 or side > 1600:
            write_downsampled(built / "images", built / f"images_{factor}", factor)
    for name in ("images", "images_2", "images_4", "images_8", "sparse"):
        if (built / name).exists():
            target = out / name
            if target.exists():
                if not overwrite:
                    raise OutputExists(target)
                shutil.rmtree(target)
            (built / name).rename(target)
    write_bytes_atomic(out / "scene.json", json.dumps({"provenance": provenance}, indent=2).encode())
    shutil.rmtree(built)
