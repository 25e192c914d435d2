"""Shared checks for every test."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from scenarios import interrupts


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
