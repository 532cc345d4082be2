"""3D-GS PLY files, plus ``obj_feat_0..15``.

The vertex layout is the one 3D-GS writes and its viewers read:
``x y z nx ny nz f_dc_0..2 f_rest_0..(3K-1) opacity scale_0..2 rot_0..3``, where f_rest
holds the higher SH bands channel-major (all red coefficients, then green, then blue),
opacity is a logit, scales are logs and rot is an unnormalised (w, x, y, z) quaternion.
Object features are extra float properties, and an exported model's per-Gaussian object
``label`` an extra uchar property, that other viewers ignore.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import torch
from plyfile import PlyData, PlyElement

from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.errors import InputError
from gsseg.model.gaussians import OBJ_FEAT_DIM, Gaussians
from gsseg.model.sh import MAX_DEGREE, num_coeffs

REQUIRED = (
    "x",
    "y",
    "z",
    "f_dc_0",
    "f_dc_1",
    "f_dc_2",
    "opacity",
    "scale_0",
    "scale_1",
    "scale_2",
    "rot_0",
    "rot_1",
    "rot_2",
    "rot_3",
)


def _vertex_array(g: Gaussians, labels: np.ndarray | None = None) -> np.ndarray:
    n = len(g)
    rest = g.sh_rest.detach().cpu().numpy().transpose(0, 2, 1).reshape(n, -1)  # channel-major
    columns = {
        **{c: g.means[:, i] for i, c in enumerate("xyz")},
        **{f"n{c}": torch.zeros(n) for c in "xyz"},
        **{f"f_dc_{i}": g.sh_dc[:, i] for i in range(3)},
        **{f"f_rest_{i}": torch.from_numpy(rest[:, i]) for i in range(rest.shape[1])},
        "opacity": g.opacity_logits,
        **{f"scale_{i}": g.log_scales[:, i] for i in range(3)},
        **{f"rot_{i}": g.quats[:, i] for i in range(4)},
        **{f"obj_feat_{i}": g.obj_feat[:, i] for i in range(g.obj_feat.shape[1])},
    }
    dtype = [(name, "f4") for name in columns] + ([("label", "u1")] if labels is not None else [])
    out = np.empty(n, dtype=dtype)
    for name, values in columns.items():
        out[name] = values.detach().cpu().numpy()
    if labels is not None:
        out["label"] = labels
    return out


def write_ply(g: Gaussians, path: Path | str, labels: np.ndarray | None = None) -> Path:
    """Write ``g`` as a binary little-endian 3D-GS PLY, atomically; ``labels`` (N,) uint8, when
    given, become a ``label`` property after the object features."""
    buf = io.BytesIO()
    PlyData([PlyElement.describe(_vertex_array(g, labels), "vertex")], byte_order="<").write(buf)
    write_bytes_atomic(Path(path), buf.getvalue())
    return Path(path)


def read_ply(path: Path | str) -> Gaussians:
    """Read a 3D-GS PLY (ours or any 3D-GS tool's). Missing object features become zeros;
    missing higher SH bands become zeros."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path} does not exist; pass the gaussians.ply of a run.")
    try:
        vertex = PlyData.read(str(path))["vertex"].data
    except Exception as e:  # plyfile raises several unrelated types on malformed files
        raise InputError(f"{path} is not a readable PLY file ({e}); write it with `gsseg train` or a 3D-GS tool.")
    names = set(vertex.dtype.names)
    missing = [name for name in REQUIRED if name not in names]
    if missing:
        raise InputError(
            f"{path} lacks the 3D-GS vertex properties {', '.join(missing)}; "
            "it must hold x y z f_dc_* opacity scale_* rot_* as 3D-GS writes them."
        )

    def stack(prefix: str, count: int) -> torch.Tensor:
        return torch.from_numpy(np.stack([vertex[f"{prefix}{i}"].astype(np.float32) for i in range(count)], 1))

    n = len(vertex)
    n_rest = sum(1 for name in names if name.startswith("f_rest_"))
    k_max = num_coeffs(MAX_DEGREE) - 1
    if n_rest % 3 or n_rest // 3 > k_max:
        raise InputError(f"{path} has {n_rest} f_rest_* properties; 3D-GS writes 3 x 0, 3, 8 or 15.")
    sh_rest = torch.zeros(n, k_max, 3)
    if n_rest:
        sh_rest[:, : n_rest // 3] = stack("f_rest_", n_rest).reshape(n, 3, n_rest // 3).transpose(1, 2)
    n_feat = sum(1 for name in names if name.startswith("obj_feat_"))
    obj_feat = stack("obj_feat_", n_feat) if n_feat else torch.zeros(n, OBJ_FEAT_DIM)
    if obj_feat.shape[1] != OBJ_FEAT_DIM:
        raise InputError(f"{path} has {n_feat} obj_feat_* properties; this version uses {OBJ_FEAT_DIM}.")
    for name in vertex.dtype.names:
        if not np.isfinite(np.asarray(vertex[name], np.float64)).all():
            raise InputError(
                f"{path}: property {name} holds NaN or infinite values; the model is damaged, train it again."
            )
    return Gaussians(
        means=torch.from_numpy(np.stack([vertex[c].astype(np.float32) for c in "xyz"], 1)),
        log_scales=stack("scale_", 3),
        quats=stack("rot_", 4),
        opacity_logits=torch.from_numpy(vertex["opacity"].astype(np.float32)),  # a copy: records may be packed
        sh_dc=stack("f_dc_", 3),
        sh_rest=sh_rest,
        obj_feat=obj_feat,
    )
