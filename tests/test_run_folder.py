"""The run folder's files (:mod:`gsseg.run.folder`): each round-trips through its reader and
writer with its format version; files from before versions were recorded still read; a file
from a newer version, or a damaged one, is refused in one sentence naming it."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from dataset_tools.infra.errors import InputError
from gsseg.render.contributions import Contributions
from gsseg.run.folder import FORMAT_VERSIONS, RunFolder, read_edit_record, write_edit_record
from gsseg.segment.reassign import Segmentation


def _segmentation() -> Segmentation:
    labels = np.array([0, 2, 2, 5], np.int64)
    objects = np.array([2, 5])
    return Segmentation(labels, objects, labels[None] == objects[:, None], "argmax", "mode", 0.2, "abc", 16, True)


def test_labels_and_contributions_round_trip_with_their_format_version(tmp_path):
    folder = RunFolder(tmp_path)
    seg = _segmentation()
    folder.write_labels(seg)
    back = folder.read_labels()
    np.testing.assert_array_equal(back.labels, seg.labels)
    np.testing.assert_array_equal(back.selections, seg.selections)
    assert back.settings() == seg.settings() and back.model == "abc"
    with np.load(folder.labels) as f:
        assert int(f["format_version"]) == FORMAT_VERSIONS["labels.npz"]
    folder.write_contributions(Contributions(np.array([0, 3], np.uint8), torch.eye(2, 4), "abc", "hqmask"))
    c = folder.read_contributions()
    assert c.masks == "hqmask" and torch.equal(c.weights, torch.eye(2, 4))


def test_a_run_file_from_before_versions_reads_and_one_from_a_newer_version_is_refused(tmp_path):
    folder = RunFolder(tmp_path)
    folder.evaluation.write_text(json.dumps({"scene": "old"}))  # written before versions were recorded
    assert folder.read_evaluation() == {"scene": "old"}
    folder.write_evaluation({"scene": "now"})
    assert json.loads(folder.evaluation.read_text())["format_version"] == FORMAT_VERSIONS["evaluation.json"]
    folder.evaluation.write_text(json.dumps({"format_version": 99, "scene": "future"}))
    with pytest.raises(InputError, match=r"evaluation\.json: format version 99, newer"):
        folder.read_evaluation()
    np.savez(folder.labels, format_version=99, labels=np.zeros(1))
    with pytest.raises(InputError, match=r"labels\.npz: format version 99"):
        folder.read_labels()


def test_damaged_or_missing_run_files_are_one_sentence_naming_the_file(tmp_path):
    folder = RunFolder(tmp_path)
    with pytest.raises(InputError, match=r"labels\.npz does not exist; run `gsseg segment`"):
        folder.read_labels()
    assert folder.read_contributions() is None and folder.read_history() == []
    folder.labels.write_bytes(b"not a zip")
    with pytest.raises(InputError, match=r"labels\.npz: damaged labels"):
        folder.read_labels()
    folder.config.write_text("{")
    with pytest.raises(InputError, match=r"config\.json: damaged run file"):
        folder.read_config()
    (tmp_path / "edit").mkdir()
    write_edit_record(tmp_path / "edit", {"object_id": 3})
    assert read_edit_record(tmp_path / "edit") == {"object_id": 3}
