"""What every command-line front end shares: user errors become one line and exit code 2."""

from __future__ import annotations

import sys
from collections.abc import Callable

import click

from dataset_tools.errors import InputError


def run_cli(group: click.Group, prog_name: str) -> Callable[[], None]:
    """An entry point that runs ``group`` and turns an ``InputError`` into ``error: ...``
    on stderr and exit code 2, without a traceback."""

    def main() -> None:
        try:
            group.main(prog_name=prog_name, standalone_mode=False)
        except InputError as e:
            click.echo(f"error: {e}", err=True)
            sys.exit(2)
        except click.exceptions.Abort:
            click.echo("aborted", err=True)
            sys.exit(130)
        except click.ClickException as e:
            e.show()
            sys.exit(e.exit_code)

    return main

