"""SIGINT, SIGTERM and SIGHUP for a run: handlers that only note the signal (standard
library only).

A handler that raises (Python's own ``KeyboardInterrupt``) can strike anywhere: inside a
numba kernel as it returns (``SystemError: CPUDispatcher(...) returned a result with an
exception set``), inside a C callback, while a module is imported, or in a ``finally`` that
was writing the outputs. The handlers here raise nothing: they note the first signal, and
the run looks at :func:`received` between its steps and between its setup phases
(:func:`raise_if_received` before its run folder exists), then ends the way it chooses.
SIGHUP (the terminal or the ssh session closed) ends a run as SIGTERM does.

:func:`noting_signals` installs them for a block (main thread only; a signal the process
ignores, e.g. SIGINT of a background job, stays ignored); nested blocks share one note.
The note belongs to the block that installed the handlers: as that block ends (normally or
by an exception) it puts the earlier handlers back, takes the note and clears it, so that
no note outlives its block; with ``redeliver`` it then sends the noted signal again, for
callers that expect Python's own handling after the run (see :func:`noting_signals`).

The ``mrslam`` console script installs the handlers from its first import
(:func:`install_for_console_script`), so a Ctrl-C while the heavy modules load is noted
too; :func:`end_console_script` puts the earlier handlers back and hands over that note.
A program that merely imports the CLI installs nothing and never sees a note it did not
cause.
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
    "end_console_script",
    "install",
    "install_for_console_script",
    "noting_signals",
    "raise_if_received",
    "received",
    "restore",
    "take",
]

SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)
"""The signals noted (SIGHUP where the platform has it)."""


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
_console_script = False
"""Whether :func:`install_for_console_script` installed the handlers (and
:func:`end_console_script` has not yet put the earlier ones back)."""


def _note(signum: int, frame: FrameType | None) -> None:
    _received.append(signum)


def received() -> str | None:
    """The name of the first signal noted (``"SIGINT"``, ``"SIGTERM"``, ``"SIGHUP"``), or
    None."""
    return signal.Signals(_received[0]).name if _received else None


def raise_if_received() -> None:
    """Raise :class:`RunInterrupted` for the first signal noted, if any."""
    if _received:
        raise RunInterrupted(_received[0])


def take() -> int | None:
    """The first signal noted (None when none was), clearing the note."""
    signum = _received[0] if _received else None
    _received.clear()
    return signum


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
    """Put back the handlers :func:`install` replaced (the note is kept; :func:`take` it).
    A handler installed from C (``signal.getsignal`` gave None, it cannot be put back from
    Python) becomes ``SIG_DFL``."""
    while _previous:
        signum, handler = _previous.popitem()
        signal.signal(signum, signal.SIG_DFL if handler is None else handler)


@contextmanager
def noting_signals(*, redeliver: bool = False) -> Iterator[None]:
    """The noting handlers for the block (see the module docstring).

    When this block installed the handlers, its end (normal or by an exception) puts the
    earlier handlers back and takes the note (clearing it). With ``redeliver`` and a
    signal noted, the signal is then sent again (``signal.raise_signal``), so that it
    takes its ordinary effect in the caller, after the block's work:

    - Python's own SIGINT handler raises ``KeyboardInterrupt`` (a Python caller's loop of
      runs stops after the run's outputs are written). When the block ended by an
      exception, that ``KeyboardInterrupt`` replaces it (the block's exception, e.g. an
      ``OSError`` or a :class:`RunInterrupted`, is its ``__context__``).
    - ``SIG_DFL`` (SIGTERM's and SIGHUP's default) ends the process by the signal.
    - A handler of the caller's runs; when it returns, the block's exception (if any)
      propagates as it would have.

    When this block did not install them (nested in another block, or not the main thread)
    it neither clears nor sends anything: the note is the installing block's."""
    installed = install()
    try:
        yield
    except BaseException:
        if installed:
            restore()
            signum = take()
            if redeliver and signum is not None:
                signal.raise_signal(signum)
        raise
    if installed:
        restore()
        signum = take()
        if redeliver and signum is not None:
            signal.raise_signal(signum)


def install_for_console_script() -> None:
    """Install the handlers when this process is the ``mrslam`` console script (never in a
    program that merely imports the CLI)."""
    global _console_script
    if Path(*sys.argv[:1]).name == "mrslam" and install():
        _console_script = True


def end_console_script() -> int | None:
    """When :func:`install_for_console_script` installed the handlers: put the earlier
    ones back and return the signal noted since (clearing the note). Otherwise None, and
    nothing is touched (a note then belongs to a :func:`noting_signals` block)."""
    global _console_script
    if not _console_script:
        return None
    _console_script = False
    restore()
    return take()
