"""mrslam_env: multi-robot SLAM simulation, onboard SLAM, map merging and recording.

This package is kept light on import: heavy modules (pymunk, pettingzoo, rerun) load only
when used. ``parallel_env`` and ``env`` are resolved lazily from :mod:`mrslam_env.env`;
importing that module also registers ``"mrslam/MultiRobotSlam-v0"`` with PettingZoo.
"""

from __future__ import annotations

from typing import Any

__all__ = ["ENV_ID", "env", "parallel_env"]
__version__ = "0.1.0"

ENV_ID = "mrslam/MultiRobotSlam-v0"


def __getattr__(name: str) -> Any:
    if name in ("parallel_env", "env", "MultiRobotSlamEnv"):
        import importlib

        # Not ``from mrslam_env import env``: that looks the name up on this package
        # first, which would call this function again.
        return getattr(importlib.import_module("mrslam_env.env"), name)
    raise AttributeError(f"module 'mrslam_env' has no attribute {name!r}")
