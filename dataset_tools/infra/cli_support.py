"""What every command-line front end shares: user errors and I/O failures become one line
and exit code 2, naming options by their flags; interruptions exit 130 saying how to
continue; and ``--version``."""

from __future__ import annotations

import dataclasses
import errno
import functools
import importlib
import inspect
import signal
import sys
import warnings
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version

import click
from click.core import ParameterSource
from tqdm import tqdm

from dataset_tools.infra.errors import NO_VALUE, InputError, OptionError, RunFailed, Spelling
from dataset_tools.infra.interrupts import Interrupted
from dataset_tools.infra.threads import configure_threads

# What to do about an operating-system error, by errno.
OS_FIXES = {
    errno.ENOSPC: "free some disk space or write elsewhere",
    errno.EDQUOT: "free some disk space or write elsewhere",
    errno.EROFS: "the file system is read-only; write elsewhere",
    errno.EACCES: "check the permissions or write elsewhere",
    errno.EPERM: "check the permissions or write elsewhere",
    errno.ENOTDIR: "a file stands where a folder is needed; choose another path",
    errno.EISDIR: "a folder stands where a file is needed; choose another path",
    errno.EEXIST: "it already exists; choose another path",
    errno.ENOENT: "check the path",
    errno.ENAMETOOLONG: "choose a shorter path",
}


# Library keywords that the command lines take under another name.
KEYWORD_OPTIONS = {"overwrite": "force", "clicks": "click_", "scene_dir": "scene"}


class WordedError(click.ClickException):
    """A library's :class:`InputError`, worded with the flags of the command that ended."""

    exit_code = 2


def flag_spelling(command: click.Command) -> Spelling:
    """How ``command`` names an option of the library: by its flag (``--max-gaussians 0``,
    ``--force``); an option the command does not declare as ``--name-with-dashes``."""
    options = {p.name: p for p in command.params if isinstance(p, click.Option)}

    def spell(name: str, value: object) -> str:
        option = options.get(KEYWORD_OPTIONS.get(name, name))
        flag = option.opts[0] if option is not None else "--" + name.replace("_", "-")
        if value is False and option is not None and option.secondary_opts:
            return option.secondary_opts[0]
        if value is NO_VALUE or isinstance(value, bool):
            return flag
        if value is None:  # the command lines' word for an option turned off
            return f"{flag} none"
        return f"{flag} {' '.join(map(str, value)) if isinstance(value, (tuple, list)) else value}"

    return spell


def word_errors_by_flags(command: click.Command) -> None:
    """Have every command under ``command`` word the library's errors with its own flags."""
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            word_errors_by_flags(sub)
        return
    callback, spelling = command.callback, flag_spelling(command)

    @functools.wraps(callback)
    def worded(*args, **kwargs):
        try:
            return callback(*args, **kwargs)
        except InputError as e:
            raise WordedError(e.worded(spelling)) from e

    command.callback = worded


def package_version() -> str:
    try:
        return version("gsseg")
    except PackageNotFoundError:
        return "unknown"


def _close_progress_bars() -> None:
    """Finish every open progress bar, so that what is printed next starts on a fresh line."""
    for bar in list(getattr(tqdm, "_instances", ())):
        bar.close()


def describe_os_error(e: OSError) -> str:
    """``<file>: <what>; <fix>`` for an operating-system error."""
    where = e.filename if e.filename is not None else "writing the output"
    what = e.strerror or str(e)
    return f"{where}: {what.lower()}; {OS_FIXES.get(e.errno, 'check the path and try again')}."


class Registry(click.Choice):
    """A choice among the names of a registry (a dict or tuple of names), read when the command
    line is parsed: ``where`` is ``module:NAME``, imported then rather than when the commands
    load, so that ``--help`` of the group stays quick; ``extra``: names put before them (such
    as ``auto``). A name added to the registry is a choice of every option that reads it."""

    def __init__(self, where: str, extra: tuple[str, ...] = ()) -> None:
        self.where, self.extra, self.case_sensitive = where, extra, True

    @property
    def choices(self) -> tuple[str, ...]:
        module, name = self.where.split(":")
        return (*self.extra, *getattr(importlib.import_module(module), name))


def _names(owner: type | Callable) -> dict[str, object]:
    """The fields of the dataclass ``owner``, or the parameters of the function ``owner``,
    with their defaults."""
    if dataclasses.is_dataclass(owner):
        return {
            f.name: f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
            for f in dataclasses.fields(owner)
        }
    return {name: p.default for name, p in inspect.signature(owner).parameters.items()}


def field_default(owner: type | Callable, name: str) -> object:
    """The default of the field ``name`` of the dataclass ``owner`` (or of the parameter
    ``name`` of the function ``owner``)."""
    return _names(owner)[name]


def field_option(config: type | Callable, name: str, *decls: str, spell: Callable | None = None, **kwargs) -> Callable:
    """A click option for the field ``name`` of the options dataclass ``config`` (or the
    keyword ``name`` of the library function ``config``), whose default
    (shown in the help) is the field's, written for the command line by ``spell`` where the
    option's values are words. A field that defaults to None shows no default (its help says
    what None means); a bool field without a ``--x/--no-x`` pair is a flag. ``decls``: the
    flags (default ``--name-with-dashes``); the keyword arguments are click's. The command
    hands on only the options the user gave (:func:`given_fields`), so that the dataclass
    alone decides the rest."""
    default = field_default(config, name)
    if isinstance(default, bool) and not any("/" in d for d in decls):
        kwargs.setdefault("is_flag", True)
    if spell is not None:
        default = spell(default)
    return click.option(
        *(decls or ("--" + name.replace("_", "-"),)),
        name,
        default=default,
        show_default=default is not None and not kwargs.get("is_flag"),
        **kwargs,
    )


def given_fields(ctx: click.Context, config: type | Callable) -> dict:
    """The options of ``ctx`` that the user gave and that are fields of the dataclass ``config``
    (or keywords of the function ``config``), by name: what the command hands to ``config``,
    whose defaults fill in the rest."""
    names = _names(config)
    defaults = (ParameterSource.DEFAULT, ParameterSource.DEFAULT_MAP)
    return {
        name: value
        for name, value in ctx.params.items()
        if name in names and ctx.get_parameter_source(name) not in defaults
    }


def switched_fields(ctx: click.Context, config: type, switch: str) -> dict:
    """The keyword ``switch`` of a library function that takes options of the dataclass
    ``config``, or None for the feature off, from the command line's ``--switch/--no-switch``
    (the parameter ``switch`` of ``ctx``, None where not given) and the fields of ``config``
    the user gave (:func:`given_fields`): {} where neither was given, so that the function's
    default decides.

    Raises:
        OptionError: a field given with the feature turned off.
    """
    given = given_fields(ctx, config)
    if ctx.params[switch] is not False:
        return {switch: config(**given)} if given else {}
    if given:
        named = " ".join(f"{{{name}}}" for name in given)
        raise OptionError(f"{named} with {{{switch}}}: give the one or the other.", **given, **{switch: False})
    return {switch: None}


def none_means_off(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """A click callback: the option value ``none`` becomes None (the feature turned off)."""
    return None if value == "none" else value


def _failure(e: BaseException, prog_name: str) -> tuple[str, int]:
    """The one line to print for an exception that ends a command, and the exit code."""
    if isinstance(e, InputError):
        return f"error: {e}", 2
    if isinstance(e, RunFailed):
        return f"error: {e}", 1
    if isinstance(e, OSError):
        return f"error: {describe_os_error(e)}", 2
    if isinstance(e, Interrupted):
        return f"interrupted: {e}", 130
    if isinstance(e, (click.exceptions.Abort, KeyboardInterrupt)):
        return "interrupted; nothing half-written was left behind", 130
    if isinstance(e, click.UsageError):
        command = e.ctx.command_path if e.ctx is not None else prog_name
        return f"error: {e.format_message().replace(chr(10), ' ')}; see `{command} --help`.", 2
    return f"error: {e.format_message()}", e.exit_code  # any other click.ClickException


def other_scene_option(command: Callable) -> Callable:
    """``--allow-other-scene``, handed to ``command`` as ``other_scene``: use a run with a scene
    other than the one it was trained on (refused by default)."""
    return click.option(
        "--allow-other-scene",
        "other_scene",
        is_flag=True,
        help="Use the run with another scene than the one it was trained on (its views, cameras, "
        "poses or images differ).",
    )(command)


def engine_options(command: Callable) -> Callable:
    """``--engine local|ray`` and ``--address``, handed to ``command`` as one ``engine``
    (:class:`dataset_tools.infra.engine.Engine`)."""

    @functools.wraps(command)
    def with_engine(*args, engine_name: str, address: str | None, **kwargs):
        from dataset_tools.infra.engine import Engine

        return command(*args, engine=Engine(engine_name, address), **kwargs)

    with_engine = click.option(
        "--address", default=None, help="A Ray cluster's address (default: start a local one); with --engine ray."
    )(with_engine)
    return click.option(
        "--engine",
        "engine_name",
        type=Registry("dataset_tools.infra.engine:ENGINES"),
        default="local",
        show_default=True,
        help="Run the independent tasks here one by one, or as tasks on Ray (pip install -e .[ray]).",
    )(with_engine)


def _show_warning(show: Callable, message, category: type[Warning], *args, **kwargs) -> None:
    """A ``UserWarning`` as one ``warning: ...`` line on stderr (above any progress bar), without
    Python's file, line and source; any other category as ``show`` (Python's own) prints it."""
    if issubclass(category, UserWarning):
        tqdm.write(f"warning: {message}", file=sys.stderr)
    else:
        show(message, category, *args, **kwargs)


def _terminate(signum, frame) -> None:
    """SIGTERM as Ctrl-C: long work stops at a clean point where it listens for it
    (:func:`dataset_tools.infra.interrupts.stop_requests`), anything else unwinds."""
    raise KeyboardInterrupt


def run_cli(group: click.Group, prog_name: str) -> Callable[[], None]:
    """An entry point that runs ``group`` and turns an ``InputError`` (worded with the flags of
    the command, :func:`word_errors_by_flags`) or an ``OSError`` into ``error: ...`` on stderr
    and exit code 2, without a traceback; interrupted work exits 130
    with its own message (a checkpoint written, how to continue). Threads are configured
    first (:func:`dataset_tools.infra.threads.configure_threads`); the library's notes
    (``UserWarning``) print as ``warning: ...`` lines."""
    group = click.version_option(package_version(), "--version", prog_name=prog_name)(group)
    word_errors_by_flags(group)

    def main() -> None:
        configure_threads()
        signal.signal(signal.SIGTERM, _terminate)  # as Ctrl-C: one line, exit code 130
        try:
            with warnings.catch_warnings():
                warnings.showwarning = functools.partial(_show_warning, warnings.showwarning)
                group.main(prog_name=prog_name, standalone_mode=False)
        except (
            InputError,
            RunFailed,
            OSError,
            Interrupted,
            click.exceptions.Abort,
            KeyboardInterrupt,
            click.ClickException,
        ) as e:
            _close_progress_bars()
            message, code = _failure(e, prog_name)
            click.echo(message, err=True)
            sys.exit(code)
        except SystemError as e:  # Ctrl-C inside a numba kernel surfaces as the kernel's SystemError
            if not isinstance(e.__cause__ or e.__context__, KeyboardInterrupt):
                raise
            _close_progress_bars()
            click.echo(_failure(KeyboardInterrupt(), prog_name)[0], err=True)
            sys.exit(130)

    return main
