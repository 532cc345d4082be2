"""A stand-in for SAM-HQ with the official input/output names, shapes and dtypes: a model
folder that exercises the whole ONNX runtime (``SamHQ``, the automatic generator,
``hqmask build --proposer sam-hq``) where the real checkpoints are not at hand, for the
plumbing tests and the runtime benchmark. It is not a segmentation model.

Encoder: the mean normalised colour of each 16x16 patch, mapped isometrically to 256
channels (image_embeddings), and four linear maps of it as the "early ViT features"
(interm_embeddings, K=4, C=32). Decoder: a prompt's anchor is the mean of its foreground
points (box corners count half); the mask logits fall with the embedding distance from the
anchor's embedding (symmetrically about 0), so a point on a uniformly coloured object selects
that object; its "predicted IoU" is 1 minus the mask's share of the padded input frame (large masks are rated low). It
follows the official decoder's structure where it matters to the export: the image
embedding is repeated per prompt, and masks are upscaled to 1024, cropped to the resized
image and resized to ``orig_im_size`` inside the graph.
"""

from __future__ import annotations

from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from hqmask.sam_hq.export import export_modules
from hqmask.sam_hq.model import ModelInfo

IMAGE_SIZE, GRID, K, C = 1024, 64, 4, 32


class StandinEncoder(nn.Module):
    def __init__(self):
        super().__init__()
        g = torch.Generator().manual_seed(0)
        self.patch = nn.Conv2d(3, 3, 16, stride=16, bias=False)
        self.patch.weight.data = torch.eye(3)[:, :, None, None].expand(3, 3, 16, 16) / 256
        q, _ = torch.linalg.qr(torch.randn(256, 3, generator=g))
        self.register_buffer("lift", q)  # (256, 3), orthonormal columns: distances are kept
        self.register_buffer("interm_maps", torch.randn(K, 3, C, generator=g))

    def forward(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        colour = self.patch(image)  # (1, 3, 64, 64)
        embeddings = torch.einsum("kc,bchw->bkhw", self.lift, colour)
        interm = torch.einsum("bchw,kcd->kbhwd", colour, self.interm_maps)
        return embeddings, interm


class StandinDecoder(nn.Module):
    def __init__(self, radius: float = 0.5, sharpness: float = 100.0):
        super().__init__()
        self.radius, self.sharpness = radius, sharpness

    def forward(
        self, image_embeddings, interm_embeddings, point_coords, point_labels, mask_input, has_mask_input, orig_im_size
    ):
        weight = (point_labels == 1).float() + 0.5 * ((point_labels == 2) | (point_labels == 3)).float()
        anchor = (point_coords * weight[..., None]).sum(1) / weight.sum(1, keepdim=True).clamp(min=1e-6)
        src = torch.repeat_interleave(image_embeddings, point_coords.shape[0], dim=0)
        grid = (anchor / IMAGE_SIZE * 2 - 1)[:, None, None, :]
        anchor_embedding = F.grid_sample(src, grid, align_corners=False)
        # clamped so that logits are symmetric about 0 and edges fall midway between patches
        distance = (src - anchor_embedding).square().sum(1, keepdim=True).sqrt().clamp(max=2 * self.radius)
        early = 1e-3 * interm_embeddings[0].permute(0, 3, 1, 2).mean(1, keepdim=True)
        prior = has_mask_input * F.interpolate(mask_input, size=(GRID, GRID), mode="bilinear", align_corners=False)
        logits = self.sharpness * (self.radius - distance) + early + prior
        low_res = F.interpolate(logits, size=(4 * GRID, 4 * GRID), mode="bilinear", align_corners=False)
        iou = 1 - (low_res > 0).float().mean((2, 3))
        masks = F.interpolate(low_res, size=(IMAGE_SIZE, IMAGE_SIZE), mode="bilinear", align_corners=False)
        scale = IMAGE_SIZE / orig_im_size.max()
        resized = torch.floor(orig_im_size * scale + 0.5).to(torch.int64)
        masks = masks[..., : resized[0], : resized[1]]
        size = orig_im_size.to(torch.int64)
        masks = F.interpolate(masks, size=(size[0], size[1]), mode="bilinear", align_corners=False)
        return masks, iou, low_res


def export_standin_model(out_dir: Path) -> Path:
    """Write the stand-in model folder (encoder.onnx, decoder.onnx, model.json) to ``out_dir``."""
    info = ModelInfo(model_type="standin", image_size=IMAGE_SIZE)
    return export_modules(StandinEncoder(), StandinDecoder(), info, out_dir)
