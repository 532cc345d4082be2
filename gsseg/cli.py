"""The ``gsseg`` command."""

from __future__ import annotations

import click

from dataset_tools.cli_support import add_planned_command, run_cli


@click.group(name="gsseg", context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """Segment-aware 3D Gaussian Splatting: train, segment, edit, render."""


add_planned_command(cli, "train", "Train 3D-GS jointly with 16-d object features on a scene")
add_planned_command(cli, "render", "Render RGB, labels or segments of a run")
add_planned_command(cli, "segment", "Prior-guided label reassignment of every Gaussian")
add_planned_command(cli, "edit", "Select an object by a 3D point or click; remove, extract or recolour it")
add_planned_command(cli, "demo", "The whole pipeline on a synthetic scene, with a report")

main = run_cli(cli, "gsseg")
