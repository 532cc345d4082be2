"""Names a user gives to outputs inside a folder the command owns (a mask folder in a scene,
an edit in a run): plain folder names, never a path that leaves the folder."""

from __future__ import annotations

from dataset_tools.infra.errors import OptionError


def plain_name(name: str, option: str) -> str:
    """``name`` if it is a plain folder name; else an :class:`OptionError` naming ``option``
    (the keyword that took it, such as ``out_masks``)."""
    if not name or name in (".", "..") or name.startswith(".") or any(c in name for c in "/\\\0"):
        raise OptionError(
            f"{{{option}}}: give a plain folder name (letters, digits, -, _), not a path.", **{option: name}
        )
    return name
