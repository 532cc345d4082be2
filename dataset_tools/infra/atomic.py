"""Outputs that appear whole or not at all: write to a temporary sibling, then rename.

A temporary sibling is locked (an OS lock) by the process writing it. One that no process
holds is what a killed process left: the next write of the same output removes it.
"""

from __future__ import annotations

import contextlib
import glob
import os
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from dataset_tools.infra.errors import InputError
from dataset_tools.infra.locks import try_lock

STALE_AFTER_S = 60  # a temporary sibling younger than this may be one another writer is just creating


def require_folder_path(path: Path) -> None:
    """Refuse an output folder path where a file stands (before any work is done)."""
    if path.exists() and not path.is_dir():
        raise InputError(f"{path}: a file stands there; write the output elsewhere.")


def first_missing(path: Path) -> Path | None:
    """The outermost of ``path`` and its parents that does not exist (what a failed command
    that created ``path`` with its parents removes), None when ``path`` exists."""
    path = Path(path).absolute()
    missing = [p for p in (path, *path.parents) if not p.exists()]
    return missing[-1] if missing else None


def _default_mode(kind: int) -> int:
    """``kind`` (0o666 for files, 0o777 for folders) less the process umask, the mode a plain
    ``open``/``mkdir`` would give; temporary files start private (0o600/0o700)."""
    umask = os.umask(0)
    os.umask(umask)
    return kind & ~umask


def remove_stale_temporaries(path: Path) -> None:
    """Remove the temporary siblings of ``path`` (``.NAME.*.tmp``, ``.NAME.old``) that no
    process holds: the leftovers of a killed write. ``path`` named ``*`` stands for every
    output in its folder (for folders whose every entry the project writes)."""
    now = time.time()
    name = "*" if path.name == "*" else glob.escape(path.name)
    for leftover in path.parent.glob(f".{name}.*"):
        if not (leftover.name.endswith(".tmp") or leftover.name.endswith(".old")):
            continue
        try:
            if now - leftover.lstat().st_mtime < STALE_AFTER_S:
                continue
            fd = os.open(leftover, os.O_RDONLY)
        except OSError:
            continue
        try:
            if try_lock(fd):
                if leftover.is_dir() and not leftover.is_symlink():
                    shutil.rmtree(leftover, ignore_errors=True)
                else:
                    leftover.unlink(missing_ok=True)
        finally:
            os.close(fd)


def _named(error: OSError, temporary: Path | str, final: Path) -> OSError:
    """``error`` naming the output ``final`` where it named its ``temporary`` sibling (or what
    lies inside it) or nothing (a full disk's write): the user's path, not a hidden one."""
    name = error.filename
    if name is None or str(name).startswith(str(temporary)):
        inside = "" if name is None else str(name)[len(str(temporary)) :]
        return OSError(error.errno, error.strerror, str(final) + inside)
    return error


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder; an
    operating-system error names ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as e:  # the folder is read-only or full
        raise OSError(e.errno, e.strerror, str(path)) from None
    try_lock(fd)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, _default_mode(0o666))
        os.replace(tmp, path)
    except BaseException as e:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(e, OSError):
            raise _named(e, tmp, path) from None
        raise


@contextlib.contextmanager
def atomic_directory(path: Path, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary folder that replaces ``path`` only if the block succeeds.

    On any exception the temporary folder is deleted and ``path`` is left as it was; an
    operating-system error names ``path`` (and the file inside it), not the temporary folder.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    except OSError as e:  # the folder is read-only or full
        raise OSError(e.errno, e.strerror, str(path)) from None
    held = os.open(tmp, os.O_RDONLY)
    try_lock(held)
    try:
        yield tmp
        os.chmod(tmp, _default_mode(0o777))
        if path.exists():
            if not overwrite:
                raise FileExistsError(path)
            old = path.with_name(f".{path.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            os.replace(path, old)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException as e:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(e, OSError):
            raise _named(e, tmp, path) from None
        raise
    finally:
        os.close(held)
