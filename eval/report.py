"""``gseval report``: metrics.json, report.md and a self-contained report.html for one run.

The report holds the per-scene summary, tables per object and per view, one image row per
test view (photo | ground truth | predicted labels | removal | extraction | recolour of
one object) and the training curves.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np

from dataset_tools.image_files import colorize_labels, encode_png
from dataset_tools.infra.atomic import atomic_directory, write_bytes_atomic
from dataset_tools.infra.errors import InputError, OutputExists
from dataset_tools.infra.overlap import refuse_overlap, run_inputs, scene_entries
from dataset_tools.scene import GT_MASKS, View
from dataset_tools.synth.edit_truth import read_edit_truth
from eval.edit_scores import edit_rows, summarize_edits
from eval.evaluate import PROTOCOLS, Evaluation, evaluate, load_inputs
from eval.lpips import LPIPS
from eval.renders import ViewRenders
from eval.training_curve import psnr_levels
from gsseg.edits import COMPLETED_OPS, OPS, Selection, apply_edit, edit_background
from gsseg.fill import fill_run_removal
from gsseg.fill_options import FillOptions
from gsseg.model.gaussians import Gaussians
from gsseg.render import Backend, get_backend
from gsseg.run.folder import RunFolder
from gsseg.run.loaded import Run
from gsseg.segment.reassign import Segmentation
from gsseg.segment.served import complete_selection

PANELS = ("photo", "ground truth", "predicted (visible)", "removal", "extraction", "recolour")
TRUTH_PANELS = ("removal", "the view without the object", "extraction", "the object alone")
EDIT_COLUMNS = {  # the edits table's scores: header -> key of eval.edit_scores.summarize_edits
    "removal PSNR (dB)": "removal_psnr",
    "removal PSNR, object's region": "removal_psnr_region",
    "removal PSNR, region seen": "removal_psnr_seen",
    "removal SSIM, object's region": "removal_ssim_region",
    "removal LPIPS, around the region": "removal_lpips_region",
    "extraction IoU": "extraction_iou",
    "extraction IoU, seen part": "extraction_iou_seen",
    "extraction PSNR inside": "extraction_psnr_inside",
    "leak": "leak",
    "ghost share": "ghost_share_after",
}


def _fmt(x: float | None, digits: int = 3) -> str:
    return "n/a" if x is None else f"{x:.{digits}f}"


def default_object(segmentation: Segmentation) -> int:
    """The segmented object with the most Gaussians."""
    if not len(segmentation.objects):
        raise InputError("the run's labels.npz holds no object; segment it with masks that contain objects.")
    return int(segmentation.objects[np.argmax(segmentation.selections.sum(axis=1))])


def edit_panels(
    run: Run,
    selected: np.ndarray,
    completed: np.ndarray,
    views: list[View],
    color: tuple[int, int, int],
    backend: str | Backend,
    *,
    train_views: list[View],
    removal: Gaussians | None = None,
    fill: FillOptions | None = FillOptions(),
    progress: bool = True,
) -> dict[str, list[np.ndarray]]:
    """Renders of ``views`` after removing and extracting (on white) the (N,) bool ``completed``
    Gaussians (the selection with what served it alone, as ``gsseg edit`` takes them) and
    recolouring the ``selected`` ones; the removal filled from the ``train_views`` as ``gsseg
    edit`` fills it, with the options ``fill`` (:mod:`gsseg.fill`; None: the removal alone), or the model
    ``removal`` where it is given (an edit made already)."""
    backend = get_backend(backend)
    out: dict[str, list[np.ndarray]] = {}
    for op in OPS:
        chosen = completed if op in COMPLETED_OPS else selected
        if op == "remove" and removal is not None:
            edited = removal
        elif op == "remove" and fill is not None:
            edited = fill_run_removal(run, chosen, train_views, options=fill, backend=backend, progress=progress)
            edited = edited.gaussians
        else:
            edited = apply_edit(run.gaussians, chosen, op, tuple(c / 255 for c in color))
        edited = edited.to(backend.device)
        background = edit_background([op])
        out[op] = [run.render_rgb(v, gaussians=edited, background=background, backend=backend) for v in views]
    return out


def image_row(r: ViewRenders, id_map: dict[int, int], edits: dict[str, list[np.ndarray]], index: int) -> np.ndarray:
    """The panels of one view side by side, 4 px apart: (H, 6W + 20, 3) uint8 (5 panels
    without ground truth). With ground truth, predicted labels take the colour of the object
    they were matched to (unmatched ones all the same); without, each label its own colour."""
    mapping = np.arange(256, dtype=np.uint8)
    if r.truth is not None:
        mapping[1:] = 255
        for label, gt in id_map.items():
            mapping[label] = gt
    truth = [colorize_labels(r.truth)] if r.truth is not None else []
    panels = [r.image, *truth, colorize_labels(mapping[r.visible])] + [edits[op][index] for op in OPS]
    gap = np.full((r.image.shape[0], 4, 3), 255, np.uint8)
    return np.concatenate([x for p in panels for x in (p, gap)][:-1], axis=1)


def truth_rows(
    scene_dir: Path, views: list[View], gt: int | None, edits: dict[str, list[np.ndarray]]
) -> dict[str, np.ndarray]:
    """Per view with edit truth for ground-truth object ``gt``: removal | the view without the
    object | extraction | the object alone, 4 px apart."""
    out = {}
    for view, removed, extracted in zip(views, edits["remove"], edits["extract"]):
        truth = read_edit_truth(scene_dir, gt, view.stem) if gt is not None else None
        if truth is not None:
            gap = np.full((removed.shape[0], 4, 3), 255, np.uint8)
            out[f"{view.stem}_truth"] = np.concatenate(
                [removed, gap, truth.without, gap, extracted, gap, truth.alone], 1
            )
    return out


def training_plot(history: list[dict], levels: tuple[np.ndarray, np.ndarray] | None = None) -> bytes | None:
    """PNG of the training loss and PSNR against the step (None without a history); ``levels``:
    (W,) steps and (W,) dB of the PSNR with each view's own level taken out
    (:func:`eval.training_curve.psnr_levels`), drawn over it."""
    if not history:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [h["step"] for h in history]
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3), dpi=100)
    a.plot(steps, [h["loss"] for h in history], label="total")
    a.plot(steps, [h["rgb"] for h in history], label="colour")
    a.plot(steps, [h["obj"] for h in history], label="object CE")
    a.set(xlabel="step", ylabel="loss", yscale="log", title="training loss")
    a.legend()
    b.plot(steps, [h["psnr"] for h in history], lw=0.6, alpha=0.6, label="the view of each step")
    if levels is not None:
        b.plot(*levels, lw=2, color="black", label="each view's level taken out")
        b.legend()
    b.set(xlabel="step", ylabel="dB", title="training-view PSNR")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


def _sections(ev: Evaluation) -> list[tuple[str, list[str], list[list[str]]]]:
    """The report's tables as (title, head, rows): the summary (untitled), the objects and
    the views. Without ground truth the segmentation columns and the objects table are left
    out, not drawn empty."""
    s = ev.summary()
    truth = bool(ev.objects)
    lpips = s["lpips"] if isinstance(s["lpips"], str) else _fmt(s["lpips"])
    summary_head = [
        "views",
        *(["mIoU visible", "mAcc visible", "mIoU extracted", "mAcc extracted"] if truth else []),
        "PSNR",
        "SSIM",
        "LPIPS",
    ]
    scores = [_fmt(s[p][m]) for p in PROTOCOLS for m in ("miou", "macc")] if truth else []
    sections = [("", summary_head, [[str(s["views"]), *scores, _fmt(s["psnr"], 2), _fmt(s["ssim"]), lpips]])]
    if truth:
        label_of = {g: p for p, g in ev.id_map.items()}
        sections.append(
            (
                "Objects",
                ["object", "ground-truth match", "IoU visible", "acc visible", "IoU extracted", "acc extracted"],
                [
                    [
                        str(label_of.get(o, "none")),
                        str(o),
                        *(_fmt(v[f"{p}_{m}"]) for p in PROTOCOLS for m in ("iou", "acc")),
                    ]
                    for o, v in ev.per_object().items()
                ],
            )
        )
    views = []
    for v in ev.views:
        rows = {p: [r["iou"] for r in ev.objects if r["view"] == v["view"] and r["protocol"] == p] for p in PROTOCOLS}
        views.append(
            [
                v["view"],
                _fmt(v["psnr"], 2),
                _fmt(v["ssim"]),
                _fmt(v.get("lpips")),
                *((_fmt(float(np.mean(rows[p])) if rows[p] else None) for p in PROTOCOLS) if truth else ()),
            ]
        )
    sections.append(
        ("Views", ["view", "PSNR", "SSIM", "LPIPS", *(["mIoU visible", "mIoU extracted"] if truth else [])], views)
    )
    if ev.edits:
        sections.append(
            (
                "Edits against ground truth",
                ["object", "ground-truth match", *EDIT_COLUMNS],
                [
                    [
                        str(label),
                        str(obj),
                        *(_fmt(scores[k], 2 if "psnr" in k else 3) for k in EDIT_COLUMNS.values()),
                    ]
                    for obj, label in sorted({(r["object"], r["label"]) for r in ev.edits})
                    for scores in [summarize_edits([r for r in ev.edits if r["object"] == obj])]
                ],
            )
        )
    return sections


def markdown_table(head: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def _html_table(head: list[str], rows: list[list[str]]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    trs = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{trs}</table>"


def _data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode()


def write_report(
    ev: Evaluation,
    renders: list[ViewRenders],
    edits: dict[str, list[np.ndarray]],
    history: list[dict],
    out_dir: Path,
    *,
    edited: str,
    matched: int | None,
    title: str,
    truth: dict[str, np.ndarray] | None = None,
    levels: tuple[np.ndarray, np.ndarray] | None = None,
    overwrite: bool = False,
) -> Path:
    """Write ``out_dir`` (atomically) with metrics.json, report.md, report.html and images/;
    ``edited``: what the edits took, in words, and ``matched`` the ground-truth object it was
    matched to (None: none); ``truth``: image rows of the edits beside their ground truth (:func:`truth_rows`);
    ``levels``: the training curve of the model alone (:func:`training_plot`)."""
    sections = _sections(ev)
    rows = {r.stem: encode_png(image_row(r, ev.id_map, edits, i)) for i, r in enumerate(renders)}
    truth_pngs = {stem: encode_png(row) for stem, row in (truth or {}).items()}
    curve = training_plot(history, levels)
    edit_note = f"edits of {edited}" + (f" (ground-truth match: object {matched})" if matched is not None else "")
    panels = " | ".join(p for p in PANELS if p != "ground truth" or ev.objects)
    with atomic_directory(out_dir, overwrite=overwrite) as tmp:
        ev.save(tmp / "metrics.json")
        for stem, png in {**rows, **truth_pngs}.items():
            write_bytes_atomic(tmp / "images" / f"{stem}.png", png)
        if curve is not None:
            write_bytes_atomic(tmp / "images" / "training.png", curve)
        md = [f"# {title}", "", f"Run `{ev.run}` on scene `{ev.scene}`, {ev.split} views.", ""]
        for name, head, table in sections:
            md += ([f"## {name}", ""] if name else []) + [markdown_table(head, table), ""]
        md += [f"## Images: {panels}", "", f"{edit_note}.", ""]
        md += [f"![{stem}](images/{stem}.png)" for stem in rows]
        if truth_pngs:
            md += ["", f"## Edits beside their truth: {' | '.join(TRUTH_PANELS)}", ""]
            md += [f"![{stem}](images/{stem}.png)" for stem in truth_pngs]
        if curve is not None:
            md += ["", "## Training", "", "![training](images/training.png)"]
        write_bytes_atomic(tmp / "report.md", ("\n".join(md) + "\n").encode())

        def figures(pngs: dict[str, bytes]) -> str:
            return "".join(
                f"<figure><img src='{_data_uri(png)}' alt='{html.escape(stem)}'><figcaption>"
                f"{html.escape(stem)}</figcaption></figure>"
                for stem, png in pngs.items()
            )

        images = figures(rows)
        if truth_pngs:
            images += f"<h2>Edits beside their truth</h2><p>{html.escape(' | '.join(TRUTH_PANELS))}.</p>" + figures(
                truth_pngs
            )
        training = f"<h2>Training</h2><img src='{_data_uri(curve)}' alt='training curves'>" if curve is not None else ""
        tables = "".join(
            (f"<h2>{html.escape(name)}</h2>" if name else "") + _html_table(head, table)
            for name, head, table in sections
        )
        page = f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title><style>
body{{font-family:sans-serif;margin:24px;color:#222}} table{{border-collapse:collapse;margin:8px 0 20px}}
td,th{{border:1px solid #ccc;padding:4px 10px;text-align:right}} th{{background:#f0f0f0}}
figure{{margin:0 0 12px}} img{{max-width:100%;image-rendering:pixelated}} figcaption{{font-size:12px;color:#666}}
</style></head><body><h1>{html.escape(title)}</h1>
<p>Run <code>{html.escape(ev.run)}</code> on scene <code>{html.escape(ev.scene)}</code>,
{html.escape(ev.split)} views.</p>
{tables}<h2>Images</h2><p>{html.escape(panels)}; {html.escape(edit_note)}.</p>
{images}{training}</body></html>
"""
        write_bytes_atomic(tmp / "report.html", page.encode())
    return out_dir


def report_run(
    run_dir: Path | str,
    scene_dir: Path | str,
    out_dir: Path | str,
    *,
    gt_masks: str | None = GT_MASKS,
    split: str = "test",
    object_id: int | None = None,
    selection: Selection | None = None,
    color: tuple[int, int, int] = (255, 40, 200),
    removal: Gaussians | None = None,
    fill: FillOptions | None = FillOptions(),
    backend: str = "auto",
    lpips: Path | str | None = None,
    overwrite: bool = False,
    other_scene: bool = False,
    progress: bool = True,
) -> Evaluation:
    """Evaluate a segmented run and write its report to ``out_dir`` and ``RUN/evaluation.json``
    (LPIPS with the network file ``lpips``, else reported as not available). The edits shown
    are of ``object_id``, or of a ``selection`` made by clicks (:func:`gsseg.edits.select`), or
    of the largest object; ``removal``: the model after that object's removal where it was
    made already (``gsseg edit``'s, filled), else it is made here (filled with the options ``fill``,
    unless None)."""
    run_dir, scene_dir, out_dir = Path(run_dir), Path(scene_dir), Path(out_dir)
    refuse_overlap(
        out_dir,
        [*run_inputs(run_dir), *scene_entries(scene_dir)]
        + ([("the LPIPS network", Path(lpips))] if lpips is not None else []),
    )
    if out_dir.exists() and not overwrite:
        raise OutputExists(out_dir)
    backend = get_backend(backend)
    lpips_net = LPIPS(lpips) if lpips is not None else None  # a bad file fails before any rendering
    run, segmentation, views = load_inputs(run_dir, scene_dir, gt_masks, split, other_scene)
    ev, renders = evaluate(
        run,
        segmentation,
        views,
        with_truth=gt_masks is not None,
        scene=str(scene_dir),
        split=split,
        backend=backend,
        lpips=lpips_net,
        progress=progress,
    )
    if selection is None:
        k = default_object(segmentation) if object_id is None else int(object_id)
        selection = Selection(segmentation.selection(k), k, str(k))
    label = selection.object_id if selection.object_id is not None else selection.main_label(segmentation.labels)
    if gt_masks is not None:
        ev.edits = edit_rows(run, segmentation, views, scene_dir, ev.id_map, lpips=lpips_net, backend=backend)
    train_views = run.scene(scene_dir).split("train")
    completed = complete_selection(run.gaussians, selection.mask, train_views, backend=backend)
    edits = edit_panels(
        run,
        selection.mask,
        completed.mask,
        views,
        color,
        backend,
        train_views=train_views,
        removal=removal,
        fill=fill,
        progress=progress,
    )
    truth = truth_rows(scene_dir, views, ev.id_map.get(label), edits) if ev.edits else None
    history = run.folder.read_history()
    trained = len(run.record.train_views)
    levels = psnr_levels(history, trained, run.config.seed, max(10, history[-1]["step"] // 30)) if history else None
    write_report(
        ev,
        renders,
        edits,
        history,
        out_dir,
        edited=selection.name if selection.object_id is None else f"object {selection.object_id}",
        matched=ev.id_map.get(label),
        title=f"gsseg report: {run_dir.name}",
        truth=truth,
        levels=levels,
        overwrite=overwrite,
    )
    with run.folder.lock():
        run.folder.write_evaluation(ev.to_json())
    return ev


def compare_runs(run_dirs: list[Path]) -> str:
    """A markdown table of the evaluation summaries of several runs, side by side."""
    head = ["run", "scene", "mIoU visible", "mAcc visible", "mIoU extracted", "mAcc extracted", "PSNR", "SSIM"]
    rows = []
    for run in run_dirs:
        folder = RunFolder(run)
        try:
            ev = Evaluation.from_json(folder.read_evaluation())
            s = ev.summary()
        except (TypeError, KeyError, ValueError, AttributeError) as e:
            raise InputError(
                f"{folder.evaluation}: does not hold a report's scores ({type(e).__name__}); run `gseval report` "
                "on the run again."
            ) from None
        rows.append(
            [
                str(run),
                Path(ev.scene).name,
                _fmt(s["visible"]["miou"]),
                _fmt(s["visible"]["macc"]),
                _fmt(s["extracted"]["miou"]),
                _fmt(s["extracted"]["macc"]),
                _fmt(s["psnr"], 2),
                _fmt(s["ssim"]),
            ]
        )
    return markdown_table(head, rows)
