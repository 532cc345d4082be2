"""The one exception type for mistakes a user can make (paths, formats, sizes, options)."""


class InputError(Exception):
    """Bad user input. The message is one sentence naming the file and the fix.

    Command-line front ends print the message (no traceback) and exit with code 2.
    """
