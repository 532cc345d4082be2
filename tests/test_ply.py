"""3D-GS PLY files: exact round trip, files of other 3D-GS tools, malformed files."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from helpers import random_gaussians
from plyfile import PlyData, PlyElement

from dataset_tools.infra.errors import InputError
from gsseg.model.ply import read_ply, write_ply


def test_round_trip_is_exact(tmp_path):
    g = random_gaussians(50, 0)
    back = read_ply(write_ply(g, tmp_path / "g.ply"))
    for name, value in g.tensors().items():
        assert torch.equal(getattr(back, name), value), name


def _plain_3dgs_ply(path, n: int, degree: int, drop: str | None = None):
    """A PLY laid out as 3D-GS writes it, without object features."""
    n_rest = 3 * ((degree + 1) ** 2 - 1)
    names = (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(n_rest)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )
    names = [x for x in names if x != drop]
    data = np.zeros(n, dtype=[(x, "f4") for x in names])
    rng = np.random.default_rng(0)
    for x in names:
        data[x] = rng.standard_normal(n)
    PlyData([PlyElement.describe(data, "vertex")]).write(str(path))
    return data


@pytest.mark.parametrize("degree", [0, 1, 3])
def test_a_3dgs_ply_without_object_features_loads(tmp_path, degree):
    data = _plain_3dgs_ply(tmp_path / "p.ply", 7, degree)
    g = read_ply(tmp_path / "p.ply")
    assert len(g) == 7 and torch.equal(g.obj_feat, torch.zeros(7, 16))
    assert torch.equal(g.quats[:, 0], torch.from_numpy(data["rot_0"]))
    if degree:
        # f_rest is channel-major: coefficient k of green is f_rest_{K + k}, K per channel.
        k = (degree + 1) ** 2 - 1
        assert torch.equal(g.sh_rest[:, 0, 1], torch.from_numpy(data[f"f_rest_{k}"]))
        assert torch.equal(g.sh_rest[:, k:], torch.zeros(7, 15 - k, 3))


def test_ply_missing_required_fields_is_refused(tmp_path):
    _plain_3dgs_ply(tmp_path / "p.ply", 3, 0, drop="opacity")
    with pytest.raises(InputError, match=r"p\.ply lacks the 3D-GS vertex properties opacity"):
        read_ply(tmp_path / "p.ply")
    (tmp_path / "junk.ply").write_text("not a ply")
    with pytest.raises(InputError, match="not a readable PLY"):
        read_ply(tmp_path / "junk.ply")


def test_a_ply_with_a_one_byte_property_loads(tmp_path):
    """Packed records (a uchar beside the floats, as the exported ``label`` or other tools'
    colours) are read by value, not through misaligned views."""
    g = random_gaussians(20, 1)
    labels = np.arange(20, dtype=np.uint8)
    back = read_ply(write_ply(g, tmp_path / "g.ply", labels=labels))
    for name, value in g.tensors().items():
        assert torch.equal(getattr(back, name), value), name
    np.testing.assert_array_equal(PlyData.read(str(tmp_path / "g.ply"))["vertex"]["label"], labels)


def test_gaussians_with_a_wrong_shape_or_dtype_are_refused_naming_the_field():
    from gsseg.model.gaussians import Gaussians

    g = random_gaussians(5, 0)
    with pytest.raises(ValueError, match=r"Gaussians\.quats: shape \(5, 3\), expected \('N', 4\), N = 5"):
        Gaussians(**{**g.tensors(), "quats": g.quats[:, :3]})
    with pytest.raises(ValueError, match=r"Gaussians\.sh_dc: shape \(4, 3\)"):
        Gaussians(**{**g.tensors(), "sh_dc": g.sh_dc[:4]})
    with pytest.raises(ValueError, match=r"Gaussians\.opacity_logits: torch\.float64 on cpu, expected"):
        Gaussians(**{**g.tensors(), "opacity_logits": g.opacity_logits.double()})
    assert len(Gaussians(**{**g.tensors(), "obj_feat": g.obj_feat[:, :2]})) == 5  # any feature width
