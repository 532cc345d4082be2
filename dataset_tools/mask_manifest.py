"""How a mask folder was made: ``<mask folder>/manifest.json``.

Every command that writes a mask folder records itself there (``made_by``), with the options
that shaped the masks, the package version and the format version; the synthetic generator
marks its exact masks as ground truth (``"truth": true``). ``python -m dataset_tools inspect``
shows it. Folders written before manifests existed, or by other tools, have none.
"""

from __future__ import annotations

import json
from pathlib import Path

from dataset_tools.infra.cli_support import package_version
from dataset_tools.infra.errors import OptionError

MANIFEST = "manifest.json"
FORMAT = 1


def manifest_bytes(made_by: str, **how) -> bytes:
    """The manifest of a mask folder written by the command ``made_by`` with the options ``how``
    (JSON values)."""
    record = {"format": FORMAT, "made_by": made_by, "version": package_version(), **how}
    return json.dumps(record, indent=2, sort_keys=True).encode()


def read_manifest(mask_dir: Path) -> dict | None:
    """The manifest of ``mask_dir``, or None when it has none (or an unreadable one)."""
    try:
        record = json.loads((Path(mask_dir) / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) and "made_by" in record else None


def describe(record: dict | None) -> str:
    """One line on how the masks were made."""
    if record is None:
        return "no manifest: made before manifests or by another tool"
    if record.get("truth"):
        return f"ground truth ({record['made_by']})"
    shown = {k: v for k, v in record.items() if k not in ("format", "made_by", "version") and v is not None}
    options = ", ".join(f"{k} {v}" for k, v in sorted(shown.items()))
    return f"{record['made_by']} {record.get('version', '')}".strip() + (f": {options}" if options else "")


def refuse_truth(mask_dir: Path, force: str) -> None:
    """Refuse ``mask_dir`` as an output where its manifest marks it as ground truth: truth is
    an input of every command, never an output, whatever the option ``force`` (the keyword
    that replaces outputs) says."""
    record = read_manifest(mask_dir)
    if record is not None and record.get("truth"):
        raise OptionError(
            f"holds ground truth (its {MANIFEST} says so), which no command writes over, with or without "
            f"{{{force}}}; choose another {{out_masks}}.",
            file=mask_dir,
        )
