"""Stopping long work at a clean point: Ctrl-C and SIGTERM set a flag that the work checks
between its steps, so that what it saves on the way out is a state it really reached."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from dataclasses import dataclass


class Interrupted(Exception):
    """Work stopped on request after saving its state; the message says how to continue.

    Command-line front ends print the message and exit with code 130.
    """


@dataclass
class StopRequest:
    """Set by the first SIGINT or SIGTERM inside :func:`stop_requests`."""

    requested: bool = False
    signal_name: str = ""


@contextlib.contextmanager
def stop_requests() -> Iterator[StopRequest]:
    """While active, the first SIGINT or SIGTERM sets ``requested`` instead of stopping the
    process; a second one raises ``KeyboardInterrupt`` at once. Outside the main thread
    (where Python cannot install handlers) signals behave as usual."""
    flag = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def handler(signum, frame):
        if flag.requested:
            raise KeyboardInterrupt
        flag.requested, flag.signal_name = True, signal.Signals(signum).name

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield flag
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
