"""Shared checks for every test."""

from __future__ import annotations

import signal
from collections.abc import Iterator
from pathlib import Path

import pytest

from mrslam_env.mapio import save_map
from mrslam_env.registry import build_world
from mrslam_env.sim.world import ground_truth_map
from scenarios import interrupts

# A test run started in the background of a script (``pytest &``) inherits SIGINT ignored,
# and every command a test starts inherits that: an ignored signal stays ignored
# (scenarios/interrupts.py), so the tests of Ctrl-C would see no Ctrl-C. The tests are of
# a terminal's Ctrl-C: the commands they start get SIGINT as a terminal would.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(autouse=True)
def no_signal_note_outlives_a_test() -> Iterator[None]:
    """A signal noted by :mod:`scenarios.interrupts` belongs to the block that installed
    the handlers: none may be left when a test ends (it would end a later command or run
    in the same process). A note left is cleared, so that one failure does not spread."""
    yield
    left = interrupts.received()
    interrupts.restore()
    interrupts.take()
    assert left is None, f"a {left} note outlived the test"


@pytest.fixture()
def maps(tmp_path: Path) -> Path:
    """Two small map files, a.yaml/a.pgm and b.yaml/b.pgm (the maze at 0.1 m), in
    tmp_path."""
    grid = ground_truth_map(build_world("maze"), 0.1, margin=0.5)
    save_map(tmp_path / "a.yaml", grid)
    save_map(tmp_path / "b.yaml", grid)
    return tmp_path
