"""Outputs never replace inputs, appear whole, and leave nothing behind: the overlap rule,
stale temporaries of killed writes, checksummed cache files, locks."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

from dataset_tools.infra.atomic import STALE_AFTER_S, atomic_directory, remove_stale_temporaries, write_bytes_atomic
from dataset_tools.infra.checked_files import read_checked, write_checked
from dataset_tools.infra.errors import InputError
from dataset_tools.infra.locks import exclusive, exclusive_folder, try_lock
from dataset_tools.infra.overlap import overlap, refuse_overlap, scene_entries, scene_inputs


@pytest.mark.parametrize(
    "out, relation",
    [
        ("a/b", "is"),
        ("a/b/", "is"),
        ("a/./b", "is"),
        ("a", "contains"),
        (".", "contains"),
        ("a/b/c", "lies inside"),
        ("a/b/c/d", "lies inside"),
        ("a/bc", None),
        ("a/c", None),
        ("b", None),
    ],
)
def test_overlap_is_is_contains_or_lies_inside(tmp_path, monkeypatch, out, relation):
    monkeypatch.chdir(tmp_path)
    assert overlap(out, "a/b") == relation


def test_overlap_follows_symbolic_links(tmp_path):
    (tmp_path / "photos").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "photos")
    assert overlap(tmp_path / "link" / "scene", tmp_path / "photos") == "lies inside"
    with pytest.raises(InputError, match=r"link: the output would replace the photos, which this command reads"):
        refuse_overlap(tmp_path / "link", [("the photos", tmp_path / "photos")])


def test_a_scene_keeps_its_images_model_and_read_masks_and_a_reader_keeps_everything(scene_copy):
    (scene_copy / "images_2").mkdir()
    kept = {p.name for _, p in scene_inputs(scene_copy, ["object_mask"])}
    assert kept == {"images", "images_2", "sparse", "scene.json", "object_mask"}
    (scene_copy / "hqmask").mkdir()
    (scene_copy / ".hqmask_cache").mkdir()
    assert {p.name for _, p in scene_entries(scene_copy)} == kept | {"hqmask", "gt_mask"}
    refuse_overlap(scene_copy / "renders", scene_entries(scene_copy))  # a new folder inside: allowed
    refuse_overlap(scene_copy / "hqmask", scene_inputs(scene_copy, ["object_mask"]))  # a mask folder rebuilt


def _age(path: Path) -> None:
    old = time.time() - 2 * STALE_AFTER_S
    os.utime(path, (old, old))


def test_the_next_write_removes_what_a_killed_write_left_but_not_a_live_one(tmp_path):
    out = tmp_path / "renders"
    killed, live, young = (tmp_path / f".renders.{k}.tmp" for k in ("killed", "live", "young"))
    for folder in (killed, live, young):
        folder.mkdir()
        (folder / "0000.png").write_bytes(b"partial")
    for folder in (killed, live):
        _age(folder)
    held = os.open(live, os.O_RDONLY)
    try:
        assert try_lock(held)
        with atomic_directory(out) as tmp:
            (tmp / "done").write_text("ok")
        assert not killed.exists() and live.exists() and young.exists()
    finally:
        os.close(held)
    assert (out / "done").read_text() == "ok"
    stale_file = tmp_path / ".labels.npz.x1.tmp"
    stale_file.write_bytes(b"half")
    _age(stale_file)
    write_bytes_atomic(tmp_path / "labels.npz", b"whole")
    assert not stale_file.exists() and (tmp_path / "labels.npz").read_bytes() == b"whole"
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        ".renders.live.tmp",
        ".renders.young.tmp",
        "labels.npz",
        "renders",
    ]


@pytest.mark.parametrize(
    "damage",
    [
        lambda b: b[: len(b) // 2],
        lambda b: b[:-1],
        lambda b: b"",
        lambda b: bytes([b[0] ^ 1]) + b[1:],
    ],
)
def test_a_damaged_cache_file_reads_as_missing(tmp_path, damage):
    path = tmp_path / "entry"
    payload = np.arange(1000, dtype=np.int32).tobytes()
    write_checked(path, payload)
    assert read_checked(path) == payload
    path.write_bytes(damage(path.read_bytes()))
    assert read_checked(path) is None
    assert read_checked(tmp_path / "missing") is None


def test_a_second_writer_is_refused_and_the_lock_leaves_no_file(tmp_path):
    with exclusive(tmp_path / "work" / "lock", tmp_path, "this scene"):
        with pytest.raises(InputError, match=rf"another command \(pid {os.getpid()}\) is writing this scene"):
            with exclusive(tmp_path / "work" / "lock", tmp_path, "this scene"):
                pass
    with exclusive(tmp_path / "work" / "lock", tmp_path, "this scene"):  # released
        pass
    before = sorted(tmp_path.rglob("*"))
    with exclusive_folder(tmp_path, "masks"):
        with pytest.raises(InputError, match="another command is writing or training on masks here"):
            with exclusive_folder(tmp_path, "masks"):
                pass
    assert sorted(tmp_path.rglob("*")) == before


def test_a_folder_the_project_owns_is_swept_of_every_killed_write(tmp_path):
    edits = tmp_path / "edits"
    (edits / "remove_1").mkdir(parents=True)
    for name in (".remove_2.k3j2.tmp", ".extract_1.old", ".recolor_1.zz.tmp"):
        (edits / name).mkdir()
        _age(edits / name)
    (edits / ".notes").write_text("a user's file")
    _age(edits / ".notes")
    remove_stale_temporaries(edits / "*")
    assert sorted(p.name for p in edits.iterdir()) == [".notes", "remove_1"]


def test_a_full_or_read_only_disk_is_named_by_the_output_not_its_temporary(tmp_path, monkeypatch):
    """A write that fails names the output the user asked for: a full disk's error names no
    file at all, a read-only folder's names the hidden temporary sibling."""
    import errno
    import tempfile

    from dataset_tools.infra.cli_support import describe_os_error

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(OSError) as failed:
        write_bytes_atomic(tmp_path / "out.png", b"data")
    assert failed.value.filename == str(tmp_path / "out.png") and "no space left" in describe_os_error(failed.value)
    with pytest.raises(OSError) as failed:
        with atomic_directory(tmp_path / "masks") as tmp:
            write_bytes_atomic(tmp / "0001.png", b"data")
    assert failed.value.filename == str(tmp_path / "masks" / "0001.png")
    monkeypatch.undo()

    def read_only(prefix, suffix, dir):
        raise PermissionError(errno.EACCES, "Permission denied", str(Path(dir) / f"{prefix}abc{suffix}"))

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    with pytest.raises(OSError) as failed:
        write_bytes_atomic(tmp_path / "out.png", b"data")
    assert failed.value.filename == str(tmp_path / "out.png") and not list(tmp_path.glob(".*"))
