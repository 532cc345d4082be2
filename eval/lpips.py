"""LPIPS through ONNX Runtime, from a network file on disk.

LPIPS needs trained network weights (a backbone and its linear calibration layers) that are
not shipped and never downloaded at run time. ``gseval export-lpips`` writes them as one ONNX
file where the ``lpips`` package is installed (``pip install lpips``, which needs torchvision);
``gseval report --lpips FILE`` then scores with it. Without a file, the reports say
:data:`eval.evaluate.LPIPS_NA` instead of a number.

The graph takes two images ``image0`` and ``image1``, (1, 3, H, W) float32 scaled to [-1, 1],
and returns their distance (any shape with one element).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.errors import InputError, OutputExists

INPUTS = ("image0", "image1")
NETS = ("alex", "vgg", "squeeze")


class LPIPS:
    """An LPIPS network loaded from an ONNX file; call it on two (H, W, 3) uint8 images."""

    def __init__(self, path: Path | str, threads: int = 0):
        import onnxruntime as ort

        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: no LPIPS network here; write one with `gseval export-lpips --out {path}`.")
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        try:
            self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own exception types for unreadable graphs
            raise InputError(
                f"{path}: ONNX Runtime cannot load it ({type(e).__name__}); write it again with `gseval export-lpips`."
            ) from None
        names = tuple(i.name for i in self.session.get_inputs())
        if sorted(names) != sorted(INPUTS) or len(self.session.get_outputs()) != 1:
            raise InputError(
                f"{path}: an LPIPS graph takes inputs {', '.join(INPUTS)} and returns one distance "
                f"(this one takes {', '.join(names)}); write it with `gseval export-lpips`."
            )
        self.path = path

    @staticmethod
    def _to_input(image: np.ndarray) -> np.ndarray:
        return (image.astype(np.float32).transpose(2, 0, 1)[None] / 127.5 - 1.0).copy()

    def __call__(self, pred: np.ndarray, target: np.ndarray) -> float:
        """LPIPS distance of two (H, W, 3) uint8 images of the same size (lower is closer)."""
        (out,) = self.session.run(None, {"image0": self._to_input(pred), "image1": self._to_input(target)})
        return float(np.asarray(out).reshape(-1)[0])


def export_lpips(out: Path | str, net: str = "alex", *, overwrite: bool = False) -> Path:
    """Write the ``lpips`` package's network ``net`` (with its pretrained weights, which it
    loads from its own files and torchvision's cache) as an ONNX graph for :class:`LPIPS`."""
    import io

    import torch

    out = Path(out)
    if net not in NETS:
        raise InputError(f"unknown LPIPS network {net!r}; choose {', '.join(NETS)}.")
    if out.exists() and not overwrite:
        raise OutputExists(out)
    try:
        import lpips
    except ImportError:
        raise InputError(
            "exporting LPIPS needs the lpips package and torchvision: "
            "`pip install lpips` where torchvision is available."
        ) from None
    model = lpips.LPIPS(net=net, verbose=False).eval()
    x = torch.zeros(1, 3, 64, 64)
    buf = io.BytesIO()
    dynamic = {"image0": {2: "height", 3: "width"}, "image1": {2: "height", 3: "width"}}
    torch.onnx.export(
        model,
        (x, x),
        buf,
        input_names=list(INPUTS),
        output_names=["distance"],
        dynamic_axes=dynamic,
        opset_version=17,
        dynamo=False,
    )
    write_bytes_atomic(out, buf.getvalue())
    return out
