"""A SAM-HQ model folder run with ONNX Runtime: encoder once per image, decoder per prompt batch.

A model folder holds ``encoder.onnx``, ``decoder.onnx`` and ``model.json`` (what
``hqmask export-onnx`` writes). The decoder has the inputs and outputs of the official SAM-HQ
ONNX decoder; when its prompt dimension is dynamic, prompts are decoded in batches,
otherwise one at a time, so official single-prompt exports work too.
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import asdict, dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from dataset_tools.infra.atomic import write_bytes_atomic
from dataset_tools.infra.checked_files import read_checked, write_checked
from dataset_tools.infra.errors import InputError
from hqmask.sam_hq.transforms import preprocess, transform_coords

ENCODER, DECODER, MODEL_JSON = "encoder.onnx", "decoder.onnx", "model.json"
ENCODER_INPUTS = ("image",)
ENCODER_OUTPUTS = ("image_embeddings", "interm_embeddings")
DECODER_INPUTS = (
    "image_embeddings",
    "interm_embeddings",
    "point_coords",
    "point_labels",
    "mask_input",
    "has_mask_input",
    "orig_im_size",
)
DECODER_OUTPUTS = ("masks", "iou_predictions", "low_res_masks")
EXPORT_HINT = (
    "make one with `hqmask export-onnx --checkpoint sam_hq_vit_b.pth --model-type vit_b --out DIR` "
    "(checkpoints: https://github.com/SysCV/sam-hq)"
)
DEVICES = ("auto", "cpu", "cuda")


@dataclass(frozen=True)
class ModelInfo:
    """``model.json``: what the runtime needs to know beyond the ONNX graphs."""

    model_type: str
    image_size: int = 1024
    pixel_mean: tuple[float, float, float] = (123.675, 116.28, 103.53)
    pixel_std: tuple[float, float, float] = (58.395, 57.12, 57.375)
    mask_threshold: float = 0.0
    opset: int = 17
    multimask_output: bool = True
    hq_token_only: bool = False

    def save(self, path: Path) -> None:
        write_bytes_atomic(path, (json.dumps(asdict(self), indent=2) + "\n").encode())

    @classmethod
    def load(cls, path: Path) -> ModelInfo:
        try:
            fields = json.loads(path.read_text())
            info = cls(**fields)
        except (json.JSONDecodeError, TypeError, UnicodeDecodeError) as e:
            raise InputError(f"{path}: not a SAM-HQ model.json ({e}); {EXPORT_HINT}.") from None
        if (
            not isinstance(info.image_size, int)
            or info.image_size < 16
            or len(info.pixel_std) != 3
            or min(info.pixel_std) <= 0
        ):
            raise InputError(
                f"{path}: image_size must be an integer of 16 or more and pixel_std three positive "
                f"numbers (got {info.image_size}, {info.pixel_std}); {EXPORT_HINT}."
            )
        return info


@dataclass
class ImageEmbedding:
    """Encoder outputs of one image: image_embeddings (1, 256, 64, 64) and interm_embeddings
    (K, 1, 64, 64, C), the early ViT features of the HQ decoder; ``original_hw`` is the image's
    (H, W)."""

    image_embeddings: np.ndarray
    interm_embeddings: np.ndarray
    original_hw: tuple[int, int]


@dataclass
class Prediction:
    """Decoder outputs for B prompts: logits (B, H, W) at the image's size, iou (B,) the
    predicted IoU, low_res_logits (B, 256, 256) (the ``mask_input`` of a refining call)."""

    logits: np.ndarray
    iou: np.ndarray
    low_res_logits: np.ndarray


def _check_names(path: Path, kind: str, got: list[str], expected: tuple[str, ...], exact: bool) -> None:
    ok = set(got) == set(expected) if exact else set(expected) <= set(got)
    if not ok:
        raise InputError(
            f"{path}: the {kind} are {', '.join(got)}; a SAM-HQ model needs {', '.join(expected)}; {EXPORT_HINT}."
        )


def _providers(device: str) -> list[str]:
    import onnxruntime as ort

    if device not in DEVICES:
        raise InputError(f"device {device!r}: use one of {', '.join(DEVICES)}.")
    cuda = "CUDAExecutionProvider" in ort.get_available_providers()
    if device == "cuda" and not cuda:
        raise InputError(
            "device cuda: this onnxruntime has no CUDA provider; install onnxruntime-gpu or use device cpu."
        )
    return ["CUDAExecutionProvider", "CPUExecutionProvider"] if cuda and device != "cpu" else ["CPUExecutionProvider"]


def _session(path: Path, options, providers: list[str]):
    import onnxruntime as ort

    try:
        return ort.InferenceSession(str(path), options, providers=providers)
    except Exception as e:  # noqa: BLE001 - ONNX Runtime reports every load failure as its own types
        reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputError(f"{path}: ONNX Runtime cannot load it ({reason}); {EXPORT_HINT}.") from None


class SamHQ:
    """SAM-HQ on ONNX Runtime.

    Args:
        model_dir: folder with encoder.onnx, decoder.onnx and model.json.
        device: ``auto`` (CUDA when onnxruntime-gpu sees a GPU, else CPU), ``cpu`` or ``cuda``.
        threads: intra-op threads of each session; 0 lets ONNX Runtime choose.
        cache_dir: when set, image embeddings are stored there, keyed by the image's pixels and
            the model, and reused.
    """

    def __init__(
        self, model_dir: Path | str, *, device: str = "auto", threads: int = 0, cache_dir: Path | str | None = None
    ):
        import onnxruntime as ort

        self.model_dir = Path(model_dir)
        for name in (ENCODER, DECODER, MODEL_JSON):
            if not (self.model_dir / name).is_file():
                raise InputError(
                    f"{self.model_dir / name}: missing; a SAM-HQ model folder holds {ENCODER}, {DECODER} and "
                    f"{MODEL_JSON}; {EXPORT_HINT}."
                )
        self.info = ModelInfo.load(self.model_dir / MODEL_JSON)
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        options.log_severity_level = 3
        self.providers = _providers(device)
        self.encoder, self.decoder = (
            _session(self.model_dir / name, options, self.providers) for name in (ENCODER, DECODER)
        )
        _check_names(
            self.model_dir / ENCODER,
            "encoder inputs",
            [i.name for i in self.encoder.get_inputs()],
            ENCODER_INPUTS,
            True,
        )
        _check_names(
            self.model_dir / ENCODER,
            "encoder outputs",
            [o.name for o in self.encoder.get_outputs()],
            ENCODER_OUTPUTS,
            False,
        )
        _check_names(
            self.model_dir / DECODER,
            "decoder inputs",
            [i.name for i in self.decoder.get_inputs()],
            DECODER_INPUTS,
            True,
        )
        _check_names(
            self.model_dir / DECODER,
            "decoder outputs",
            [o.name for o in self.decoder.get_outputs()],
            DECODER_OUTPUTS,
            False,
        )
        coords = next(i for i in self.decoder.get_inputs() if i.name == "point_coords")
        self.batched = not isinstance(coords.shape[0], int)
        self.cache_dir = None if cache_dir is None else Path(cache_dir)
        self._mean = np.array(self.info.pixel_mean, np.float32)
        self._std = np.array(self.info.pixel_std, np.float32)

    @cached_property
    def fingerprint(self) -> str:
        """A short hash of model.json and the encoder graph: what the embeddings depend on."""
        h = hashlib.sha1((self.model_dir / MODEL_JSON).read_bytes())
        encoder = self.model_dir / ENCODER
        h.update(str(encoder.stat().st_size).encode())
        with encoder.open("rb") as f:
            h.update(f.read(1 << 20))
        return h.hexdigest()[:16]

    def encode(self, image: np.ndarray) -> ImageEmbedding:
        """Encoder outputs of ``image`` (H, W, 3) uint8 RGB, from the cache when it has them."""
        cached = None
        if self.cache_dir is not None:
            key = hashlib.sha1(np.ascontiguousarray(image).tobytes() + str(image.shape).encode()).hexdigest()
            cached = self.cache_dir / self.fingerprint / f"{key}.npz"
            data = read_checked(cached)
            if data is not None:
                with np.load(io.BytesIO(data)) as z:
                    return ImageEmbedding(z["image_embeddings"], z["interm_embeddings"], image.shape[:2])
        x = preprocess(image, self.info.image_size, self._mean, self._std)
        embeddings, interm = self.encoder.run(list(ENCODER_OUTPUTS), {"image": x})
        out = ImageEmbedding(embeddings, interm, image.shape[:2])
        if cached is not None:
            buffer = io.BytesIO()
            np.savez(buffer, image_embeddings=embeddings, interm_embeddings=interm)
            write_checked(cached, buffer.getvalue())
        return out

    def decode(self, embedding: ImageEmbedding, coords: np.ndarray, labels: np.ndarray) -> Prediction:
        """Masks for B prompts of N points each.

        Args:
            embedding: the image's encoder outputs.
            coords: (B, N, 2) points (x, y) in the image's pixels.
            labels: (B, N): 1 foreground, 0 background, 2/3 box corners, -1 padding.

        B must be at least 1.
        """
        h, w = embedding.original_hw
        coords = transform_coords(coords, (h, w), self.info.image_size)
        fixed = {
            "image_embeddings": embedding.image_embeddings,
            "interm_embeddings": embedding.interm_embeddings,
            "mask_input": np.zeros((1, 1, 256, 256), np.float32),
            "has_mask_input": np.zeros(1, np.float32),
            "orig_im_size": np.array([h, w], np.float32),
        }
        step = max(len(coords), 1) if self.batched else 1
        parts = []
        for i in range(0, len(coords), step):
            feed = dict(
                fixed, point_coords=coords[i : i + step], point_labels=np.asarray(labels[i : i + step], np.float32)
            )
            parts.append(self.decoder.run(list(DECODER_OUTPUTS), feed))
        masks, iou, low = parts[0] if len(parts) == 1 else (np.concatenate([p[k] for p in parts]) for k in range(3))
        return Prediction(masks[:, 0], iou[:, 0], low[:, 0])

    def predict(
        self,
        image: np.ndarray | ImageEmbedding,
        points: np.ndarray | None = None,
        labels: np.ndarray | None = None,
        box: np.ndarray | None = None,
    ) -> tuple[np.ndarray, float]:
        """One object from point and/or box prompts, as SAM's predictor does it.

        Args:
            image: (H, W, 3) uint8 RGB, or its ``encode`` result.
            points: (N, 2) pixels (x, y); labels (N,) 1 foreground / 0 background.
            box: (4,) XYXY pixels.

        Returns:
            The mask (H, W) bool and its predicted IoU.
        """
        if points is None and box is None:
            raise InputError("a SAM-HQ prompt needs points, a box, or both.")
        embedding = image if isinstance(image, ImageEmbedding) else self.encode(image)
        coords = np.zeros((0, 2), np.float32) if points is None else np.asarray(points, np.float32).reshape(-1, 2)
        point_labels = (
            np.ones(len(coords), np.float32) if labels is None else np.asarray(labels, np.float32).reshape(-1)
        )
        if len(point_labels) != len(coords):
            raise InputError(f"{len(coords)} prompt points but {len(point_labels)} labels.")
        if box is not None:
            coords = np.concatenate([coords, np.asarray(box, np.float32).reshape(2, 2)])
            point_labels = np.concatenate([point_labels, [2, 3]])
        else:  # SAM pads point-only prompts with a not-a-point
            coords = np.concatenate([coords, np.zeros((1, 2), np.float32)])
            point_labels = np.concatenate([point_labels, [-1]])
        pred = self.decode(embedding, coords[None], point_labels[None])
        return pred.logits[0] > self.info.mask_threshold, float(pred.iou[0])
