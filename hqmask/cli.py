"""The ``hqmask`` command."""

from __future__ import annotations

import click

from dataset_tools.cli_support import add_planned_command, run_cli


@click.group(name="hqmask", context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """High-quality, multi-view consistent 2D object masks."""


add_planned_command(cli, "build", "Propose, associate and clean object masks for every view of a scene")
add_planned_command(cli, "clean", "Noise removal alone: closing and small-component reassignment")
add_planned_command(cli, "export-onnx", "Export an official SAM-HQ checkpoint to ONNX")

main = run_cli(cli, "hqmask")
