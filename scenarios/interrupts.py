"""SIGINT, SIGTERM and SIGHUP: noted during ``mrslam run``, ending any other command at
once (standard library only).

The rule. ``mrslam run`` notes the signal and stops between two steps (below). A signal
ends any other command (``merge``, ``scenarios``, ``bench ...``) at once: its handler
(:func:`end_on_signals`, :func:`end_by`) prints one line ``mrslam: interrupted by SIGINT``
to stderr (``os.write``, no Python I/O buffering), restores the signal's default action
and sends the signal again, so the process ends by it (shells report 130 / 143 / 129;
Python's ``subprocess`` a returncode of -2 / -15 / -1). No Python exception is ever raised
inside C code, so nothing swallows it (a ``KeyboardInterrupt`` raised in a pymunk cffi
callback is printed as "Exception ignored" and the command runs on) and nothing crashes
(one raised inside numba / llvmlite code can end in a segfault). Outputs are written under
temporary names and renamed (mrslam_env/atomic.py), so an interrupted command never
leaves a half-written output; a hidden temporary file (``.NAME.XXXX.part.EXT``) may
remain, as after a kill. This is the ``mrslam`` console script's behaviour only:
``scenarios.cli.main()`` called from Python (tests, notebooks) installs no handler that
ends the process; there a Ctrl-C stays Python's ``KeyboardInterrupt`` (the CLI prints one
line and returns 130).

Why ``run`` only notes. A handler that raises (Python's own ``KeyboardInterrupt``) can
strike anywhere: inside a numba kernel as it returns (``SystemError:
CPUDispatcher(...) returned a result with an exception set``), inside a C callback, while
a module is imported, or in a ``finally`` that was writing the outputs. The noting
handlers raise nothing: they note the first signal, and the run looks at
:func:`received` between its steps and between its setup phases (:func:`raise_if_received`
before its run folder exists), then writes its outputs (its report marked incomplete) and
ends. SIGHUP (the terminal or the ssh session closed) ends a run as SIGTERM does.

:func:`noting_signals` installs them for a block (main thread only; a signal the process
ignores, e.g. SIGINT of a background job, stays ignored); nested blocks share one note.
The note belongs to the block that installed the handlers: as that block ends (normally or
by an exception) it puts the earlier handlers back, takes the note and clears it, so that
no note outlives its block; with ``redeliver`` it then sends the noted signal again, for
callers that expect Python's own handling after the run (see :func:`noting_signals`).

Startup. The ``mrslam`` console script (``os.path.basename(sys.argv[0]) == "mrslam"``)
installs the noting handlers from its first import (:func:`install_for_console_script`,
the first line of scenarios/cli.py; this module imports only what Python's startup has
loaded already, about 1.5 ms), so a signal while the heavy modules load is noted: ``run``
then stops before its run folder exists, any other command ends by the signal as soon as
its arguments are read. :func:`end_console_script` puts the earlier handlers back and
hands over that note. A program that merely imports the CLI installs nothing and never
sees a note it did not cause. The window: a signal before the handlers are in place, i.e.
during Python's own startup (the interpreter, ``site`` and the editable install's import
finder) and the import of the ``scenarios`` package, gets Python's default behaviour
(SIGINT: a ``KeyboardInterrupt`` traceback, status 1 or 130; SIGTERM / SIGHUP: the process
ends by the signal, no line). Measured on a 2-core Linux container (Python 3.11): a SIGINT
sent 10-20 ms after ``Popen`` of ``mrslam scenarios`` gave the traceback every time (36 of
36), at 25 ms 8 of 12, from 30 ms on never (48 of 48): the handlers are in place about
25-30 ms after the process starts, about the cost of ``python -c pass`` (25 ms) itself.
"""

from __future__ import annotations

# Only modules Python's startup has loaded already (contextlib: by site): the console script
# installs the handlers as its first import, so the less it loads first the shorter the
# window in which a signal still takes Python's own effect (see the module docstring).
import os
import signal
import sys
from contextlib import contextmanager, suppress

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Iterator
    from types import FrameType
    from typing import Any, NoReturn

__all__ = [
    "SIGNALS",
    "RunInterrupted",
    "end_console_script",
    "end_on_signals",
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
    if _previous:
        return False
    for signum in SIGNALS:
        current = signal.getsignal(signum)
        if current is not signal.SIG_IGN:  # an ignored signal stays ignored
            try:
                signal.signal(signum, _note)
            except ValueError:  # not the main thread (the first signal.signal says so)
                return False
            _previous[signum] = current
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
    """Install the handlers when this process is the ``mrslam`` console script (``argv[0]``
    is named ``mrslam``). Never in a program that merely imports the CLI, nor in a sweep's
    spawned worker, which imports the console script as its parent's main module with the
    parent's ``sys.argv`` (its own command line, ``sys.orig_argv``, ends in
    multiprocessing's ``--multiprocessing-fork``)."""
    global _console_script
    script = os.path.basename(sys.argv[0]) if sys.argv[:1] else ""
    worker = "--multiprocessing-fork" in getattr(sys, "orig_argv", ())
    if script == "mrslam" and not worker and install():
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


def _end_now(signum: int, frame: FrameType | None) -> NoReturn:
    """The handler of a command other than ``run`` (console script only): one line, then
    the process ends by the signal itself."""
    end_by(signum)


def end_by(signum: int) -> NoReturn:
    """End the process by the signal ``signum`` at once: one line ``mrslam: interrupted by
    SIGINT`` on stderr (``os.write``: no Python buffer to flush), the signal's default
    action back, and the signal sent again, so the process ends by it (a shell reports
    128 + its number). Never returns (should the signal be blocked, the process exits with
    that status)."""
    name = signal.Signals(signum).name
    with suppress(OSError):  # stderr closed: the status still says it
        os.write(2, f"mrslam: interrupted by {name}\n".encode())
    _end_children()
    signal.signal(signum, signal.SIG_DFL)
    signal.raise_signal(signum)
    os._exit(128 + signum)


def _end_children() -> None:
    """SIGTERM to this process's multiprocessing children (a sweep's pool workers), which
    would otherwise wait forever on a parent that is gone, holding the caller's stdout
    and stderr open. Only when multiprocessing was ever imported (never imported here)."""
    multiprocessing = sys.modules.get("multiprocessing")
    if multiprocessing is None:
        return
    for child in multiprocessing.active_children():
        with suppress(Exception):  # gone already, or not ours to end
            child.terminate()


def end_on_signals() -> None:
    """As the ``mrslam`` console script, for a command other than ``run``: a signal noted
    while the modules loaded ends the process now (:func:`end_by`), and from here on
    SIGINT, SIGTERM and SIGHUP end it at once (an ignored one stays ignored). A program
    that merely calls :func:`scenarios.cli.main` is left as it is (nothing installed,
    nothing ended)."""
    if not _console_script:
        return
    signum = end_console_script()
    if signum is not None:
        end_by(signum)
    for signum in SIGNALS:
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, _end_now)
