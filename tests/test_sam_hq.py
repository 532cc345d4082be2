"""SAM-HQ on ONNX Runtime: pre/post-processing against hand-computed values, the runtime and
the automatic generator through a stand-in model (plumbing tests), the model-folder errors,
and the export of the real architecture where segment-anything-hq is installed."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dataset_tools import InputError, load_scene
from hqmask.build import BuildConfig, build_masks
from hqmask.sam_hq import AutomaticMaskGenerator, GeneratorConfig, SamHQ
from hqmask.sam_hq.mask_ops import (
    box_nms,
    crop_boxes,
    masks_to_boxes,
    near_crop_edge,
    point_grid,
    remove_small_regions,
    stability_score,
)
from hqmask.sam_hq.standin import export_standin_model
from hqmask.sam_hq.transforms import preprocess, resized_shape, transform_coords

MEAN = np.array([123.675, 116.28, 103.53], np.float32)
STD = np.array([58.395, 57.12, 57.375], np.float32)


@pytest.fixture(scope="module")
def plumbing_model(tmp_path_factory) -> Path:
    return export_standin_model(tmp_path_factory.mktemp("sam") / "plumbing")


def squares_image(h: int = 200, w: int = 320) -> tuple[np.ndarray, list[tuple[int, int, int, int]]]:
    """Flat grey with three flat-coloured rectangles; returns the image and their XYXY boxes
    (last covered column/row, SAM's box convention)."""
    image = np.full((h, w, 3), 128, np.uint8)
    boxes = [(20, 30, 99, 109), (150, 20, 229, 79), (200, 120, 299, 179)]
    for (x0, y0, x1, y1), colour in zip(boxes, [(230, 40, 40), (40, 200, 60), (40, 60, 230)]):
        image[y0 : y1 + 1, x0 : x1 + 1] = colour
    return image, boxes


# --- pre/post-processing against hand-computed values ---------------------------------------


def test_resize_keeps_aspect_and_rounds_to_nearest():
    assert resized_shape(300, 600, 1024) == (512, 1024)
    assert resized_shape(333, 500, 1024) == (682, 1024)  # 333 * 2.048 = 681.98
    assert resized_shape(1500, 2250, 1024) == (683, 1024)  # 682.67


def test_preprocess_normalises_and_pads_bottom_right():
    image = np.zeros((300, 600, 3), np.uint8)
    image[..., 0] = 255
    x = preprocess(image, 1024, MEAN, STD)
    assert x.shape == (1, 3, 1024, 1024) and x.dtype == np.float32
    np.testing.assert_allclose(x[0, 0, :512], (255 - 123.675) / 58.395, rtol=1e-6)
    np.testing.assert_allclose(x[0, 1, :512], -116.28 / 57.12, rtol=1e-6)
    assert not x[0, :, 512:].any() and np.all(x[0, 0, :512] != 0)


def test_prompt_coordinates_scale_per_axis():
    got = transform_coords(np.array([[250.0, 100.0], [0.0, 333.0]]), (333, 500), 1024)
    np.testing.assert_allclose(got, [[512.0, 100 * 682 / 333], [0.0, 682.0]], rtol=1e-6)


def test_stability_score_is_iou_of_the_two_thresholds():
    logits = np.array([[[-2.0, -0.5, 0.5, 2.0, 3.0]], [[-3.0, -2.0, -1.5, -4.0, -5.0]]], np.float32)
    np.testing.assert_allclose(stability_score(logits, 0.0, 1.0), [2 / 4, 0.0])


def test_boxes_of_masks_use_first_and_last_covered_pixel():
    masks = np.zeros((2, 6, 8), bool)
    masks[0, 1:4, 2:7] = True
    np.testing.assert_array_equal(masks_to_boxes(masks), [[2, 1, 6, 3], [0, 0, 0, 0]])


def test_nms_on_known_boxes():
    boxes = np.array([[0, 0, 10, 10], [1, 1, 11, 11], [0, 0, 10, 9], [50, 50, 60, 60]], np.float32)
    scores = np.array([0.9, 0.8, 0.95, 0.1])
    # C (0.95) suppresses A (IoU 0.9); B overlaps A by 81/119 = 0.68 and C by 72/118 = 0.61: kept.
    np.testing.assert_array_equal(box_nms(boxes, scores, 0.7), [2, 1, 3])
    np.testing.assert_array_equal(box_nms(boxes, scores, 0.6), [2, 3])


def test_point_grid_and_crop_pyramid():
    np.testing.assert_allclose(point_grid(2), [[0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [0.75, 0.75]])
    boxes, layers = crop_boxes(100, 200, 1, 512 / 1500)
    # overlap int(0.341 * 100) = 34; crops ceil((34 + 200) / 2) = 117 wide, ceil(134 / 2) = 67 high
    np.testing.assert_array_equal(
        boxes, [[0, 0, 200, 100], [0, 0, 117, 67], [0, 33, 117, 100], [83, 0, 200, 67], [83, 33, 200, 100]]
    )
    np.testing.assert_array_equal(layers, [0, 1, 1, 1, 1])


def test_masks_cut_by_an_inner_crop_edge_are_flagged():
    crop, image = np.array([0, 0, 117, 67.0]), np.array([0, 0, 200, 100.0])
    boxes = np.array([[5, 5, 60, 40], [50, 10, 110, 40], [0, 0, 30, 30]], np.float32)
    np.testing.assert_array_equal(near_crop_edge(boxes, crop, image), [False, True, False])


def test_small_holes_filled_small_islands_dropped():
    mask = np.zeros((20, 20), bool)
    mask[2:12, 2:12] = True
    mask[5, 5] = False  # a 1-px hole
    mask[16:18, 16:18] = True  # a 4-px island
    filled, changed = remove_small_regions(mask, 10, "holes")
    assert changed and filled[5, 5] and filled.sum() == mask.sum() + 1
    cleaned, changed = remove_small_regions(filled, 10, "islands")
    assert changed and cleaned.sum() == 100 and not cleaned[16:18, 16:18].any()
    tiny = np.zeros((20, 20), bool)
    tiny[0:2, 0:2] = tiny[10:13, 10:13] = True
    kept, _ = remove_small_regions(tiny, 50, "islands")
    assert kept.sum() == 9  # every island is small: the largest stays


# --- runtime and generator through the stand-in model (plumbing) ----------------------------


def test_plumbing_model_folder_loads_with_batched_decoder(plumbing_model):
    model = SamHQ(plumbing_model, device="cpu", threads=1)
    assert model.batched and model.providers == ["CPUExecutionProvider"]
    assert json.loads((plumbing_model / "model.json").read_text())["image_size"] == 1024


def test_plumbing_point_and_box_prompts_land_on_the_right_pixels(plumbing_model):
    """The stand-in selects the flat region under the prompt, so this checks the coordinate
    transforms and the in-graph crop/resize of a non-square image end to end."""
    model = SamHQ(plumbing_model)
    image, boxes = squares_image()
    embedding = model.encode(image)
    for x0, y0, x1, y1 in boxes:
        truth = np.zeros(image.shape[:2], bool)
        truth[y0 : y1 + 1, x0 : x1 + 1] = True
        for mask, _ in (
            model.predict(embedding, np.array([[(x0 + x1) / 2, (y0 + y1) / 2]])),
            model.predict(embedding, box=np.array([x0, y0, x1, y1])),
        ):
            assert mask.shape == image.shape[:2]
            assert (mask & truth).sum() / (mask | truth).sum() > 0.9


def test_plumbing_batched_decoding_equals_one_prompt_at_a_time(plumbing_model):
    model = SamHQ(plumbing_model)
    image, _ = squares_image()
    embedding = model.encode(image)
    coords = np.array([[[60, 70], [0, 0]], [[190, 50], [0, 0]], [[250, 150], [0, 0]]], np.float32)
    labels = np.tile(np.array([[1, -1]], np.float32), (3, 1))
    batch = model.decode(embedding, coords, labels)
    assert (
        batch.logits.shape == (3, 200, 320) and batch.iou.shape == (3,) and batch.low_res_logits.shape == (3, 256, 256)
    )
    for i in range(3):
        one = model.decode(embedding, coords[i : i + 1], labels[i : i + 1])
        np.testing.assert_allclose(one.logits[0], batch.logits[i], atol=1e-4)


@pytest.mark.slow
def test_plumbing_generator_thresholds_nms_and_painting(plumbing_model):
    """The 16x16 grid hits every region many times; NMS leaves one mask per region, with the
    region's exact box. The stand-in rates the grey background (merged with the zero padding)
    at a predicted IoU of 0.18, under the 0.88 default; prompts on edges give empty masks,
    whose stability is 0."""
    image, boxes = squares_image()
    model = SamHQ(plumbing_model)

    def generate(**options):
        return AutomaticMaskGenerator(model, GeneratorConfig(points_per_side=16, **options)).generate(image)

    out = generate()
    assert out.masks.shape == (3, 200, 320) and {tuple(int(v) for v in b) for b in out.boxes} == set(boxes)
    assert np.all(out.predicted_iou > 0.88) and np.all(out.stability >= 0.95)
    loose = generate(pred_iou_thresh=0.1)
    assert {tuple(int(v) for v in b) for b in loose.boxes} == set(boxes) | {(0, 0, 319, 199)}
    unstable = generate(pred_iou_thresh=0.1, stability_score_thresh=0.0)
    empty = ~unstable.masks.any(axis=(1, 2))
    assert empty.sum() > 0 and len(unstable) == 4 + empty.sum()  # empty boxes overlap nothing, as in SAM
    assert len(generate(pred_iou_thresh=1.0)) == 0
    seg = loose.proposals().paint()
    for x0, y0, x1, y1 in boxes:  # painted by score: the squares win over the background
        inside = seg[y0 + 3 : y1 - 2, x0 + 3 : x1 - 2]  # corners are rounded by the bilinear upsampling
        assert np.all(inside == inside[0, 0]) and inside[0, 0] != seg[0, 0]
    assert np.all(seg[:15] == seg[0, 0]) and seg[0, 0] > 0


@pytest.mark.slow
def test_plumbing_generator_with_crop_layers_and_small_region_removal(plumbing_model):
    image, boxes = squares_image()
    # squares fill more of a crop's frame, which the stand-in rates lower: a looser IoU threshold
    cfg = GeneratorConfig(points_per_side=8, pred_iou_thresh=0.5, crop_n_layers=1, min_mask_region_area=50)
    out = AutomaticMaskGenerator(SamHQ(plumbing_model), cfg).generate(image)
    for x0, y0, x1, y1 in boxes:
        truth = np.zeros(image.shape[:2], bool)
        truth[y0 : y1 + 1, x0 : x1 + 1] = True
        assert max((m & truth).sum() / (m | truth).sum() for m in out.masks) > 0.9
    assert len({tuple(c) for c in out.crop_boxes.tolist()}) > 1  # masks came from several crops


def test_embedding_cache_returns_the_stored_embedding(plumbing_model, tmp_path):
    image, _ = squares_image()
    model = SamHQ(plumbing_model, cache_dir=tmp_path / "cache")
    first = model.encode(image)
    files = list((tmp_path / "cache").rglob("*.npz"))
    assert len(files) == 1
    model.encoder = None  # a second call must not need the encoder
    second = model.encode(image)
    np.testing.assert_array_equal(first.image_embeddings, second.image_embeddings)
    np.testing.assert_array_equal(first.interm_embeddings, second.interm_embeddings)


@pytest.mark.slow
def test_plumbing_hqmask_build_with_sam_hq(plumbing_model, scene_copy):
    result = build_masks(
        scene_copy,
        BuildConfig(
            proposer="sam-hq", model=str(plumbing_model), points_per_side=8, out_masks="sam_masks", min_area=20
        ),
        progress=False,
    )
    scene = load_scene(scene_copy, masks="sam_masks")
    assert result.views == len(scene.views) and result.n_objects >= 1
    assert all(v.load_mask().shape == v.load_image().shape[:2] for v in scene.views)
    caches = [p.name for p in (scene_copy / ".hqmask_cache").iterdir()]
    assert len(caches) == 1 and caches[0].startswith("sam-hq-") and caches[0].endswith("-p8")


# --- model-folder errors ------------------------------------------------------------------------


def test_missing_file_names_the_folder_contents_and_the_export(plumbing_model, tmp_path):
    broken = tmp_path / "model"
    broken.mkdir()
    (broken / "encoder.onnx").write_bytes((plumbing_model / "encoder.onnx").read_bytes())
    with pytest.raises(
        InputError, match=r"decoder.onnx: missing.*encoder.onnx, decoder.onnx and model.json.*export-onnx"
    ):
        SamHQ(broken)


def test_decoder_with_other_inputs_lists_the_expected_ones(plumbing_model, tmp_path):
    import onnx
    from onnx import TensorProto, helper

    broken = tmp_path / "model"
    broken.mkdir()
    for name in ("encoder.onnx", "model.json"):
        (broken / name).write_bytes((plumbing_model / name).read_bytes())
    x = helper.make_tensor_value_info("embeddings", TensorProto.FLOAT, [1, 256, 64, 64])
    y = helper.make_tensor_value_info("masks", TensorProto.FLOAT, [1, 256, 64, 64])
    graph = helper.make_graph([helper.make_node("Identity", ["embeddings"], ["masks"])], "sam", [x], [y])
    onnx.save(
        helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8),
        str(broken / "decoder.onnx"),
    )
    with pytest.raises(InputError) as e:
        SamHQ(broken)
    message = str(e.value)
    assert "decoder.onnx: the decoder inputs are embeddings" in message
    assert (
        "image_embeddings, interm_embeddings, point_coords, point_labels, mask_input, has_mask_input, orig_im_size"
        in message
    )
    assert "hqmask export-onnx" in message


def test_cli_sam_hq_without_model_exits_2(scene_copy):
    hqmask = str(Path(sys.executable).parent / "hqmask")
    args = [hqmask, "build", str(scene_copy), "--proposer", "sam-hq", "--out-masks", "sam"]
    r = subprocess.run(args, capture_output=True, text=True)
    assert r.returncode == 2 and "--proposer sam-hq needs --model," in r.stderr and "Traceback" not in r.stderr
    assert not (scene_copy / "sam").exists()


# --- the real architecture ------------------------------------------------------------------------


def test_export_of_the_real_vit_tiny_runs_in_the_runtime(tmp_path):
    pytest.importorskip("torchvision", reason="the SAM-HQ export needs torchvision (pip install .[export])")
    pytest.importorskip(
        "segment_anything_hq", reason="the SAM-HQ export needs segment-anything-hq (pip install .[export])"
    )
    from hqmask.sam_hq.export import export_checkpoint

    out = export_checkpoint(None, "vit_tiny", tmp_path / "vit_tiny")
    model = SamHQ(out, device="cpu")
    image, boxes = squares_image()
    mask, score = model.predict(image, np.array([[60, 70]]))
    assert mask.shape == image.shape[:2] and np.isfinite(score)
    out = AutomaticMaskGenerator(model, GeneratorConfig(points_per_side=4, pred_iou_thresh=0, stability_score_thresh=0))
    masks = out.generate(image)
    assert masks.masks.shape[1:] == image.shape[:2]
