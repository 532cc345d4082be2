"""The ``gseval`` command."""

from __future__ import annotations

import click

from dataset_tools.cli_support import add_planned_command, run_cli


@click.group(name="gseval", context_settings={"help_option_names": ["-h", "--help"]})
def cli() -> None:
    """Metrics, reports and paper-table benchmarks."""


add_planned_command(cli, "report", "Metrics and an HTML/markdown report of a run")
add_planned_command(cli, "compare", "Put several runs side by side")
add_planned_command(cli, "paper-tables", "The analogs of the paper's tables on synthetic scenes")

main = run_cli(cli, "gseval")
