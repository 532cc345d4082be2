"""The published 3D-Scene-Segmentation-HQ dataset: download (or take a local copy) and convert
it to scene folders.

The loader accepts the forms such a dataset takes on the Hub, in any nesting:

- scene folders (``images/``, ``sparse/0/``, a mask folder), copied after they load;
- archives of scene folders (``.zip``, ``.tar``, ``.tar.gz``, ``.tgz``), unpacked first;
- ``datasets`` view rows (a ``save_to_disk`` folder or parquet files with the columns of
  :data:`dataset_tools.dataset_rows.COLUMNS`), written out as scene folders.
"""

from __future__ import annotations

import shutil
import tarfile
import tempfile
import zipfile
from pathlib import Path

from tqdm import tqdm

from dataset_tools.dataset_rows import write_scenes_from_rows
from dataset_tools.infra.atomic import atomic_directory
from dataset_tools.infra.errors import InputError, OptionError, OutputExists
from dataset_tools.infra.overlap import refuse_overlap
from dataset_tools.scene import MASKS, load_scene

HQ_REPO = "joshir/3D-Scene-Segmentation-HQ"
ARCHIVE_SUFFIXES = (".zip", ".tar", ".tar.gz", ".tgz")
OFFLINE_HINT = (
    f"download it where the Hub is reachable (`huggingface-cli download {HQ_REPO} --repo-type dataset "
    "--local-dir DIR`) and pass that folder as {local}"
)


def download_hq(*, repo_id: str = HQ_REPO, revision: str | None = None, cache_dir: Path | None = None) -> Path:
    """The dataset's files, fetched through ``huggingface_hub`` (or found in its cache)."""
    from huggingface_hub import snapshot_download
    from huggingface_hub.errors import HfHubHTTPError, LocalEntryNotFoundError

    try:
        return Path(snapshot_download(repo_id, repo_type="dataset", revision=revision, cache_dir=cache_dir))
    except (LocalEntryNotFoundError, HfHubHTTPError, OSError) as e:
        reason = type(e).__name__
        raise OptionError(
            f"cannot download {repo_id} from the Hugging Face Hub ({reason}: offline or not reachable); {OFFLINE_HINT}."
        ) from None


def _is_archive(path: Path) -> bool:
    return path.is_file() and path.name.lower().endswith(ARCHIVE_SUFFIXES)


def _unpack(archive: Path, into: Path) -> None:
    """Extract ``archive`` into ``into``, refusing members that would land outside it."""
    if archive.name.lower().endswith(".zip"):
        with zipfile.ZipFile(archive) as z:
            z.extractall(into)  # zipfile drops absolute paths and ".." components itself
    else:
        with tarfile.open(archive) as t:
            t.extractall(into, filter="data")


def _scene_folders(root: Path) -> list[Path]:
    """Folders under ``root`` (or ``root`` itself) that hold a COLMAP model in sparse/0."""
    return sorted(p.parent.parent for p in root.rglob("0") if p.is_dir() and p.parent.name == "sparse")


def _row_sources(root: Path) -> list[Path]:
    """``save_to_disk`` folders and parquet files under ``root``."""
    saved = sorted(p.parent for p in root.rglob("dataset_info.json") if (p.parent / "state.json").is_file())
    parquet = sorted(p for p in root.rglob("*.parquet") if not any(s in p.parents for s in saved))
    return saved + parquet


def _load_rows(sources: list[Path]):
    import datasets

    parts = [datasets.load_from_disk(str(p)) if p.is_dir() else None for p in sources]
    files = [str(p) for p in sources if p.is_file()]
    if files:
        parts.append(datasets.load_dataset("parquet", data_files=files, split="train"))
    parts = [p for p in parts if p is not None]
    return parts[0] if len(parts) == 1 else datasets.concatenate_datasets(parts)


def convert_hq(
    source: Path | str,
    out: Path | str,
    *,
    scenes: list[str] | None = None,
    masks: str = MASKS,
    overwrite: bool = False,
    progress: bool = True,
) -> list[Path]:
    """Convert a copy of the dataset at ``source`` into scene folders ``out/<scene>/``.

    Args:
        source: a snapshot of the dataset repository, a folder of it, or one archive.
        out: where the scene folders go.
        scenes: keep only the scenes with these names (all when None).
        masks: name of the object-mask folder in the source scenes and in the output.
        overwrite: replace scene folders that exist in ``out``.

    Returns:
        The scene folders written, sorted by name.
    """
    source, out = Path(source), Path(out)
    if not source.exists():
        raise InputError(f"{source}: no such dataset path; pass the folder or archive of a copy of {HQ_REPO}.")
    with tempfile.TemporaryDirectory(prefix="hq_unpack_") as unpacked:
        if source.is_dir():
            roots, archives = [source], sorted(p for p in source.rglob("*") if _is_archive(p))
        else:
            roots, archives = [], [source] if _is_archive(source) else []
        if not roots and not archives:
            raise InputError(
                f"{source}: not a folder or an archive ({', '.join(ARCHIVE_SUFFIXES)}); pass a copy of {HQ_REPO}."
            )
        for k, archive in enumerate(
            tqdm(archives, desc="unpacking", unit="archive", disable=not progress or not archives)
        ):
            target = Path(unpacked) / f"{k:03d}"
            try:
                _unpack(archive, target)
            except (zipfile.BadZipFile, tarfile.TarError, EOFError) as e:
                raise InputError(f"{archive}: damaged archive ({e}); download it again.") from None
            roots.append(target)

        folders = [f for r in roots for f in _scene_folders(r) if scenes is None or f.name in scenes]
        names = [f.name for f in folders]
        duplicated = sorted({n for n in names if names.count(n) > 1})
        if duplicated:
            raise InputError(
                f"{source}: several scene folders are named {duplicated[0]!r}; pass one copy of the dataset."
            )
        written = []
        for folder in tqdm(folders, desc="copying scenes", unit="scene", disable=not progress or not folders):
            load_scene(folder, masks=masks)  # refuses broken scenes with a message naming the file
            dst = out / folder.name
            if dst.exists() and not overwrite:
                raise OutputExists(dst)
            with atomic_directory(dst, overwrite=overwrite) as tmp:
                shutil.copytree(folder, tmp, dirs_exist_ok=True)
            written.append(dst)

        rows = [p for r in roots for p in _row_sources(r)]
        if rows:
            written += write_scenes_from_rows(_load_rows(rows), out, scenes=scenes, masks=masks, overwrite=overwrite)
    if not written:
        wanted = f" named {', '.join(scenes)}" if scenes else ""
        raise InputError(
            f"{source}: found no scenes{wanted} (folders with sparse/0, archives of them, or dataset "
            f"rows); pass a copy of {HQ_REPO}."
        )
    return sorted(written)


def fetch_hq(
    out: Path | str,
    *,
    local: Path | str | None = None,
    scenes: list[str] | None = None,
    masks: str = MASKS,
    revision: str | None = None,
    overwrite: bool = False,
    progress: bool = True,
) -> list[Path]:
    """Scene folders of the HQ dataset in ``out``: from the local copy ``local``, or downloaded
    from the Hub when it is None."""
    if local is not None:
        refuse_overlap(out, [("the local copy", Path(local))])
    source = Path(local) if local is not None else download_hq(revision=revision)
    return convert_hq(source, out, scenes=scenes, masks=masks, overwrite=overwrite, progress=progress)
