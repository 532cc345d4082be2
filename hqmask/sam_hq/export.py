"""``hqmask export-onnx``: an official SAM-HQ checkpoint -> encoder.onnx, decoder.onnx, model.json.

The decoder is the package's own ``SamOnnxModel`` (the official SAM-HQ ONNX decoder), exported
with a dynamic prompt dimension so the runtime can decode a batch of prompts per call; the
export checks that a batched call equals one call per prompt and, where the traced graph
does not generalise, falls back to the official one-prompt-per-call export. The encoder
returns the image embeddings and the early ViT features the HQ decoder needs, stacked.

Needs the ``segment-anything-hq`` package (``pip install .[export]``, which brings
torchvision); the runtime does not.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from dataset_tools.infra.atomic import atomic_directory
from dataset_tools.infra.errors import InputError, OptionError, OutputExists
from dataset_tools.infra.overlap import refuse_overlap
from hqmask.sam_hq.model import DECODER, DECODER_OUTPUTS, ENCODER, ENCODER_OUTPUTS, MODEL_JSON, ModelInfo

MODEL_TYPES = ("vit_tiny", "vit_b", "vit_l", "vit_h")


class StackedEncoder(nn.Module):
    """A SAM-HQ image encoder whose list of intermediate features becomes one tensor:
    image (1, 3, S, S) -> image_embeddings (1, 256, S/16, S/16), interm_embeddings (K, 1, S/16, S/16, C)."""

    def __init__(self, image_encoder: nn.Module):
        super().__init__()
        self.image_encoder = image_encoder

    def forward(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        embeddings, interm = self.image_encoder(image)[:2]
        return embeddings, torch.stack(list(interm))


def _export(
    module: nn.Module,
    inputs: dict[str, torch.Tensor],
    outputs: tuple[str, ...],
    path: Path,
    opset: int,
    dynamic_axes: dict[str, dict[int, str]],
) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            module,
            tuple(inputs.values()),
            str(path),
            input_names=list(inputs),
            output_names=list(outputs),
            opset_version=opset,
            do_constant_folding=True,
            dynamic_axes=dynamic_axes,
            dynamo=False,
        )


def _decoder_inputs(
    embeddings: torch.Tensor, interm: torch.Tensor, prompts: int, image_size: int
) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    return {
        "image_embeddings": embeddings,
        "interm_embeddings": interm,
        "point_coords": torch.rand(prompts, 2, 2, generator=g) * image_size,
        "point_labels": torch.tensor([[1.0, -1.0]]).repeat(prompts, 1),
        "mask_input": torch.zeros(1, 1, 4 * embeddings.shape[2], 4 * embeddings.shape[3]),
        "has_mask_input": torch.zeros(1),
        "orig_im_size": torch.tensor([image_size * 0.75, image_size], dtype=torch.float32),
    }


def _batch_matches_single(path: Path, inputs: dict[str, torch.Tensor]) -> bool:
    """Whether the decoder at ``path`` gives, for a batch of prompts, what it gives for each alone."""
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    feed = {k: v.numpy() for k, v in inputs.items()}
    try:
        batched = session.run(list(DECODER_OUTPUTS), feed)
        for i in range(len(feed["point_coords"])):
            one = dict(feed, point_coords=feed["point_coords"][i : i + 1], point_labels=feed["point_labels"][i : i + 1])
            single = session.run(list(DECODER_OUTPUTS), one)
            if not all(np.allclose(b[i : i + 1], s, atol=1e-4) for b, s in zip(batched, single)):
                return False
    except Exception:  # noqa: BLE001 - any runtime failure of the batched graph means "not batchable"
        return False
    return True


def export_modules(
    encoder: nn.Module, decoder: nn.Module, info: ModelInfo, out_dir: Path | str, *, overwrite: bool = False
) -> Path:
    """Export a SAM-HQ-shaped encoder/decoder pair to ``out_dir`` (written atomically).

    Args:
        encoder: image (1, 3, S, S) -> (image_embeddings, interm_embeddings), S = ``info.image_size``.
        decoder: the inputs named in ``DECODER_INPUTS`` -> (masks, iou_predictions, low_res_masks).
        info: written as model.json.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not overwrite:
        raise OutputExists(out_dir)
    encoder, decoder = encoder.eval(), decoder.eval()
    image = torch.zeros(1, 3, info.image_size, info.image_size)
    with torch.no_grad():
        embeddings, interm = encoder(image)
    with atomic_directory(out_dir, overwrite=overwrite) as tmp:
        _export(encoder, {"image": image}, ENCODER_OUTPUTS, tmp / ENCODER, info.opset, {})
        inputs = _decoder_inputs(embeddings, interm, 3, info.image_size)
        dynamic = {"point_coords": {0: "prompts", 1: "num_points"}, "point_labels": {0: "prompts", 1: "num_points"}}
        _export(decoder, inputs, DECODER_OUTPUTS, tmp / DECODER, info.opset, dynamic)
        if not _batch_matches_single(tmp / DECODER, inputs):
            warnings.warn(
                "the decoder does not trace to a batched graph; exported for one prompt per call", stacklevel=2
            )
            single = _decoder_inputs(embeddings, interm, 1, info.image_size)
            _export(
                decoder, single, DECODER_OUTPUTS, tmp / DECODER, info.opset, {k: {1: "num_points"} for k in dynamic}
            )
        info.save(tmp / MODEL_JSON)
    return out_dir


def export_checkpoint(
    checkpoint: Path | str | None,
    model_type: str,
    out_dir: Path | str,
    *,
    opset: int = ModelInfo.opset,
    hq_token_only: bool = False,
    multimask_output: bool = True,
    overwrite: bool = False,
) -> Path:
    """Export an official SAM-HQ checkpoint (``None``: random weights, for tests) of ``model_type``.

    ``multimask_output`` makes the decoder pick, per prompt, the best of SAM's three masks by
    predicted IoU (what the automatic generator wants); ``hq_token_only`` uses the HQ mask
    alone instead of adding it to SAM's.
    """
    if model_type not in MODEL_TYPES:
        raise OptionError(f"{{model_type}}: use one of {', '.join(MODEL_TYPES)}.", model_type=model_type)
    if checkpoint is not None and not Path(checkpoint).is_file():
        raise InputError(f"{checkpoint}: checkpoint not found; download it from https://github.com/SysCV/sam-hq.")
    if checkpoint is not None:
        refuse_overlap(out_dir, [("the checkpoint", Path(checkpoint))])
    try:
        from segment_anything_hq import sam_model_registry
        from segment_anything_hq.utils.onnx import SamOnnxModel
    except ImportError as e:
        raise InputError(
            f"export-onnx needs the segment-anything-hq package ({e}); install it with `pip install .[export]`."
        ) from None
    sam = sam_model_registry[model_type](checkpoint=None if checkpoint is None else str(checkpoint))
    decoder = SamOnnxModel(sam, hq_token_only=hq_token_only, multimask_output=multimask_output)
    info = ModelInfo(
        model_type=model_type,
        image_size=int(sam.image_encoder.img_size),
        pixel_mean=tuple(float(v) for v in sam.pixel_mean.flatten()),
        pixel_std=tuple(float(v) for v in sam.pixel_std.flatten()),
        mask_threshold=float(sam.mask_threshold),
        opset=opset,
        multimask_output=multimask_output,
        hq_token_only=hq_token_only,
    )
    return export_modules(StackedEncoder(sam.image_encoder), decoder, info, out_dir, overwrite=overwrite)
