"""Cache files that know when they are damaged: the payload followed by its hash, written
atomically. A truncated, altered or foreign file reads as missing, so the cache recomputes
that entry instead of failing every later run."""

from __future__ import annotations

import hashlib
from pathlib import Path

from dataset_tools.infra.atomic import write_bytes_atomic

DIGEST_SIZE = 16


def _digest(data: bytes) -> bytes:
    return hashlib.blake2b(data, digest_size=DIGEST_SIZE).digest()


def write_checked(path: Path, data: bytes) -> None:
    """Write ``data`` and its hash to ``path``, atomically."""
    write_bytes_atomic(path, data + _digest(data))


def read_checked(path: Path) -> bytes | None:
    """The payload of a file written by :func:`write_checked`, or None when it is missing or
    its hash does not match (damaged, or written by something else)."""
    try:
        raw = Path(path).read_bytes()
    except (FileNotFoundError, IsADirectoryError):
        return None
    data, digest = raw[:-DIGEST_SIZE], raw[-DIGEST_SIZE:]
    return data if len(raw) >= DIGEST_SIZE and _digest(data) == digest else None
