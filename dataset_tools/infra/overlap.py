"""No command writes over what it reads.

Every command that writes resolves its output path and hands it, with the paths it reads or
must keep, to :func:`refuse_overlap` before it does any work. An output that *is* one of
them, *contains* one (writing it would replace the folder that holds it), or *lies inside*
one is refused in one sentence, whatever ``--force`` says: ``--force`` replaces an earlier
output, never an input.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from dataset_tools.infra.errors import InputError

Protected = tuple[str, Path]  # (what it is, in words; its path)


def _real(path: Path | str) -> Path:
    """The absolute path with every symbolic link of its existing part followed."""
    return Path(os.path.realpath(path))


def overlap(out: Path | str, path: Path | str) -> str | None:
    """How the output ``out`` overlaps ``path``: ``"is"``, ``"contains"``, ``"lies inside"``,
    or None when writing ``out`` cannot touch ``path``."""
    out, path = _real(out), _real(path)
    if out == path:
        return "is"
    if path.is_relative_to(out):
        return "contains"
    if out.is_relative_to(path):
        return "lies inside"
    return None


def refuse_overlap(out: Path | str, protected: Iterable[Protected]) -> None:
    """Raise :class:`InputError` when the output ``out`` is, contains or lies inside any of
    ``protected``: (description, path) pairs of what the command reads or must keep."""
    for what, path in protected:
        relation = overlap(out, path)
        if relation is not None:
            where = "would replace" if relation == "is" else relation
            shown = "" if relation == "is" else f" ({path})"
            raise InputError(
                f"{out}: the output {where} {what}{shown}, which this command reads; an input is never "
                "replaced, so write the output elsewhere."
            )


def scene_inputs(root: Path | str, masks: Iterable[str | None] = ()) -> list[Protected]:
    """What a command that writes a mask folder into a scene must keep: the scene's image
    folders (``images`` and every ``images_N``), its COLMAP model, ``scene.json``, and the
    mask folders ``masks`` it reads. Other mask folders may be rebuilt (with ``--force``)."""
    root = Path(root)
    image_folders = {root / "images", *(p for p in root.glob("images_*") if p.is_dir())}
    return [
        *(("the scene's images", p) for p in sorted(image_folders)),
        ("the scene's COLMAP model", root / "sparse"),
        ("the scene's scene.json", root / "scene.json"),
        *((f"the mask folder {m}", root / m) for m in masks if m),
    ]


def scene_entries(root: Path | str) -> list[Protected]:
    """What a command that only reads a scene must keep: everything in the scene folder
    (images, model, every mask folder, ``scene.json``; hidden work folders aside). A new
    folder inside it may be written."""
    root = Path(root)
    entries = {e for e in root.iterdir() if not e.name.startswith(".")} if root.is_dir() else set()
    return scene_inputs(root) + [
        (f"the scene's {e.name}", e) for e in sorted(entries - {p for _, p in scene_inputs(root)})
    ]


def run_inputs(root: Path | str) -> list[Protected]:
    """A run folder as a whole: nothing but ``gsseg`` itself writes inside it."""
    return [("the run folder", Path(root))]
