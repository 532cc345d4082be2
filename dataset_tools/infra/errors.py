"""The exceptions a command ends with: a mistake a user can make (paths, formats, sizes,
options), and work that failed on good input."""


class InputError(Exception):
    """Bad user input. The message is one sentence naming the file and the fix.

    Command-line front ends print the message (no traceback) and exit with code 2.
    """


class RunFailed(Exception):
    """Work that failed on good input (training that diverged). The message says what was
    kept and how to go on; command-line front ends print it (no traceback) and exit with
    code 1."""
