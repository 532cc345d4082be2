"""OS file locks: one writer of a folder at a time, released when the process ends however it
ends (so a lock can never go stale)."""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

from dataset_tools.infra.errors import InputError


def try_lock(fd: int) -> bool:
    """Take an exclusive lock on the open file (or folder) ``fd`` without waiting; False when
    another process holds it."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


@contextlib.contextmanager
def exclusive(lock_file: Path, owner: Path, what: str) -> Iterator[None]:
    """Hold an exclusive lock on ``lock_file`` while the block runs; a second holder is refused
    in one sentence naming ``owner`` (the folder written) and ``what`` is being written."""
    lock_file.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(lock_file, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        if not try_lock(fd):
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "another process"
            raise InputError(
                f"{owner}: another command ({holder}) is writing {what}; wait for it to finish or "
                "choose another folder."
            )
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()}".encode(), 0)
        yield
    finally:
        os.close(fd)


@contextlib.contextmanager
def exclusive_folder(folder: Path, what: str) -> Iterator[None]:
    """Hold an exclusive lock on the existing ``folder`` itself (no lock file is left in it)
    while the block runs, to write ``what`` there; another writer, or a reader holding
    :func:`shared_folder`, refuses it in one sentence."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        if not try_lock(fd):
            raise InputError(f"{folder}: another command is writing or training on {what} here; wait for it to finish.")
        yield
    finally:
        os.close(fd)


@contextlib.contextmanager
def shared_folder(folder: Path, what: str) -> Iterator[None]:
    """Hold a shared lock on the existing ``folder`` while the block reads ``what`` there: any
    number of readers together, no writer (:func:`exclusive_folder`) meanwhile; a writer
    holding it refuses the reader in one sentence."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"{folder}: another command is writing {what} here; wait for it to finish.") from None
        yield
    finally:
        os.close(fd)
