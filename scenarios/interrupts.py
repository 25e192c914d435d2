"""SIGINT and SIGTERM for a run: handlers that only note the signal (standard library only).

A handler that raises (Python's own ``KeyboardInterrupt``) can strike anywhere: inside a
numba kernel as it returns (``SystemError: CPUDispatcher(...) returned a result with an
exception set``), inside a C callback, while a module is imported, or in a ``finally`` that
was writing the outputs. The handlers here raise nothing: they note the first signal, and
the run looks at :func:`received` between its steps and between its setup phases
(:func:`raise_if_received` before its run folder exists), then ends the way it chooses.

:func:`noting_signals` installs them for a block (main thread only; a signal the process
ignores, e.g. SIGINT of a background job, stays ignored); nested blocks share one note.
A block that installed them can send the noted signal again as it ends
(``redeliver``), for callers that expect Python's own handling after the run. The
``mrslam`` console script installs them from its first import
(:func:`install_for_console_script`), so a Ctrl-C while the heavy modules load is noted too.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import Any

__all__ = [
    "SIGNALS",
    "RunInterrupted",
    "install",
    "install_for_console_script",
    "noting_signals",
    "raise_if_received",
    "received",
    "restore",
]

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by a signal: ``signal_name`` is e.g. ``"SIGTERM"``."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signal_name = signal.Signals(signum).name
        self.signum = int(signum)


_received: list[int] = []
"""The signals noted since the handlers were installed (the first one counts)."""
_previous: dict[int, Any] = {}
"""The handlers ours replaced, to put back."""


def _note(signum: int, frame: FrameType | None) -> None:
    _received.append(signum)


def received() -> str | None:
    """The name of the first signal noted (``"SIGINT"``, ``"SIGTERM"``), or None."""
    return signal.Signals(_received[0]).name if _received else None


def raise_if_received() -> None:
    """Raise :class:`RunInterrupted` for the first signal noted, if any."""
    if _received:
        raise RunInterrupted(_received[0])


def install() -> bool:
    """Install the noting handlers (main thread only); True when this call installed them
    (and a fresh note begins), False when they were already in place or cannot be."""
    if threading.current_thread() is not threading.main_thread() or _previous:
        return False
    for signum in SIGNALS:
        current = signal.getsignal(signum)
        if current is not signal.SIG_IGN:  # an ignored signal stays ignored
            _previous[signum] = current
            signal.signal(signum, _note)
    if not _previous:
        return False
    _received.clear()
    return True


def restore() -> None:
    """Put back the handlers :func:`install` replaced (the note is kept)."""
    while _previous:
        signum, handler = _previous.popitem()
        signal.signal(signum, handler)


@contextmanager
def noting_signals(*, redeliver: bool = False) -> Iterator[None]:
    """The noting handlers for the block (see the module docstring).

    ``redeliver``: when this block installed the handlers and ends normally with a signal
    noted, the signal is sent again once the earlier handlers are back, so that it takes
    its ordinary effect there (a Python caller's loop of runs gets its
    ``KeyboardInterrupt`` after the run's outputs are written)."""
    installed = install()
    try:
        yield
    except BaseException:
        if installed:
            restore()
        raise
    if installed:
        restore()
        if redeliver and _received:
            signal.raise_signal(_received[0])


def install_for_console_script() -> None:
    """Install the handlers when this process is the ``mrslam`` console script (never in a
    program that merely imports the CLI)."""
    if Path(sys.argv[0]).name == "mrslam":
        install()
