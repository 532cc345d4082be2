"""The exceptions a command ends with: a mistake a user can make (paths, formats, sizes,
options), and work that failed on good input.

A library error names options the way its caller calls them: ``str(error)`` writes the
Python keyword (``max_gaussians=0``), the command-line front ends write their flags
(``--max-gaussians 0``) through :meth:`InputError.worded`.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

# An option named in an :class:`OptionError` message: ``{max_gaussians}``.
_OPTION = re.compile(r"\{([a-z][a-z0-9_]*)\}")

# How a front end names an option: (keyword, value or NO_VALUE) -> the words.
Spelling = Callable[[str, object], str]


class _NoValue:
    def __repr__(self) -> str:
        return "NO_VALUE"


NO_VALUE = _NoValue()


def python_spelling(name: str, value: object) -> str:
    """An option as a Python caller passes it: ``max_gaussians=0``, or ``model`` alone."""
    return name if value is NO_VALUE else f"{name}={value!r}"


class InputError(Exception):
    """Bad user input. The message is one sentence naming the file and the fix.

    Command-line front ends print the message (no traceback) and exit with code 2.
    """

    def worded(self, spelling: Spelling = python_spelling) -> str:
        """The message with its options named by ``spelling``."""
        return str(self)


class OptionError(InputError):
    """An option given a value it cannot take, options that do not go together, or an output
    that only an option may replace.

    Args:
        message: what is wrong and the fix, naming options as ``{keyword}``: the keyword or
            dataclass field that takes it (``{max_gaussians}``, ``{overwrite}``).
        file: the file or folder at fault, written first; None when the options alone are.
        **values: the values of the options the message names, written beside them
            (``max_gaussians=0`` in Python, ``--max-gaussians 0`` on the command line).

    Attributes:
        message, file, values: as given; ``options``: every option the message names.
    """

    def __init__(self, message: str, *, file: Path | str | None = None, **values: object):
        self.message, self.file, self.values = message, file, values
        self.options = tuple(_OPTION.findall(message))
        unknown = set(values) - set(self.options)
        if unknown:
            raise ValueError(f"values for options the message does not name: {sorted(unknown)}")
        super().__init__(self.worded())

    def __reduce__(self):  # pickled with its data (a Ray task's error crosses processes)
        return _restore, (type(self), self.__dict__)

    def worded(self, spelling: Spelling = python_spelling) -> str:
        text = _OPTION.sub(lambda m: spelling(m[1], self.values.get(m[1], NO_VALUE)), self.message)
        return text if self.file is None else f"{self.file}: {text}"


def _restore(cls: type[OptionError], state: dict) -> OptionError:
    error = Exception.__new__(cls)
    error.__dict__.update(state)
    error.args = (error.worded(),)
    return error


class OutputExists(OptionError):
    """An output that exists already, which the keyword ``option`` replaces (``--force`` on the
    command line). ``fix`` is the rest of the advice, such as " or choose another {name}"."""

    def __init__(self, path: Path | str, fix: str = "", option: str = "overwrite"):
        super().__init__(f"already exists; pass {{{option}}} to replace it{fix}.", file=path, **{option: True})


class RunFailed(Exception):
    """Work that failed on good input (training that diverged). The message says what was
    kept and how to go on; command-line front ends print it (no traceback) and exit with
    code 1."""


def check_seed(seed: int) -> None:
    """Refuse a seed that numpy's and torch's generators cannot take (a negative one)."""
    if seed < 0:
        raise OptionError("{seed}: give a seed of 0 or more.", seed=seed)
