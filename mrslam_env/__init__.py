"""mrslam_env: multi-robot SLAM simulation, onboard SLAM, map merging and recording.

This package is kept light on import: heavy modules (pymunk, pettingzoo, rerun) load only
when used. ``parallel_env`` and ``env`` are resolved lazily from :mod:`mrslam_env.env`;
importing that module also registers ``"mrslam/MultiRobotSlam-v0"`` with PettingZoo and
``"mrslam/SingleRobot-v0"`` with Gymnasium (:mod:`mrslam_env.wrappers`).

``mrslam_env.env`` is the module :mod:`mrslam_env.env`, made callable: ``mrslam_env.env(...)``
builds the AEC environment, as PettingZoo's tests expect of an environment package.
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
        module = importlib.import_module("mrslam_env.env")
        # ``env`` is the callable module itself, the same object the import system binds
        # to this package's attribute once the submodule is loaded.
        return module if name == "env" else getattr(module, name)
    raise AttributeError(f"module 'mrslam_env' has no attribute {name!r}")
