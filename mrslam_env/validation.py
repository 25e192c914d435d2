"""Checks shared by the configuration dataclasses' ``__post_init__``: each names the
class, the field and the offending value in a one-line ValueError."""

from __future__ import annotations

import math

__all__ = ["check_fields", "require"]


def require(cls_name: str, name: str, value: object, ok: bool, wanted: str) -> None:
    """Raise ``ValueError("<cls_name>.<name> must be <wanted>, got <value>")`` unless ok."""
    if not ok:
        raise ValueError(f"{cls_name}.{name} must be {wanted}, got {value!r}")


def check_fields(
    config: object,
    *,
    positive: tuple[str, ...] = (),
    non_negative: tuple[str, ...] = (),
    counts: tuple[str, ...] = (),
    whole: tuple[str, ...] = (),
) -> None:
    """Validate fields of ``config``: ``positive`` finite numbers > 0, ``non_negative``
    finite numbers >= 0, ``counts`` ints >= 1 and ``whole`` ints >= 0 (not bools)."""
    name = type(config).__name__
    for attr in positive + non_negative:
        value = getattr(config, attr)
        number = isinstance(value, int | float) and math.isfinite(value)
        if attr in positive:
            require(name, attr, value, number and value > 0, "a finite number > 0")
        else:
            require(name, attr, value, number and value >= 0, "a finite number >= 0")
    for attr, least in [(a, 1) for a in counts] + [(a, 0) for a in whole]:
        value = getattr(config, attr)
        ok = isinstance(value, int) and not isinstance(value, bool) and value >= least
        require(name, attr, value, ok, f"an int >= {least}")
