"""The exploration-policy protocol: how any policy (scripted or learned) drives one robot
inside the team (design §6).

The team keeps everything that is not exploring: it exchanges maps, merges them, verifies a
hypothesis by rendezvous, shares frontiers once the robots are in one frame. While a robot
explores, the team asks its policy for an action::

    action = policy.act(observation, context)

``observation`` is the env's observation of that robot (the ``Dict`` form: ``pose``,
``odom``, ``scan``, ``peer``, ``comm``, ``local_map``; :class:`mrslam_env.wrappers.
ObservationFlattener` turns it into the flat vector a learned policy was trained on) and
``context`` (:class:`PolicyContext`) is what the team knows at that step. The action is the
env's normalised ``(v, omega)`` in [-1, 1], float32 (2,).

A policy is built by a factory ``factory(env, rng) -> ExplorationPolicy``, one per robot:
``env`` is the :class:`~mrslam_env.config.EnvConfig` (the robot and its sensors) and ``rng``
the robot's own generator. ``mrslam run --policy module:factory`` and ``mrslam bench
explore --policy module:factory`` load one with :func:`load_policy_factory`; built in are
``agents.explorer:frontier_policy`` (the default) and ``agents.wander:wander_policy``.

**What the team does itself.** The team drives a robot to a given goal (a rendezvous
meeting point) with its own planner and path follower, not with the policy: verification
works whatever the policy does. The policy acts whenever the robot explores.

**Optional capabilities.** The team uses these when a policy has them, and does without
otherwise (the frontier explorer, :class:`agents.explorer.ExplorerPolicy`, has them all):

==========================  ============================================================
``target``                  (2,) or None: where the policy is heading, in
                            ``context.map``'s frame; shared with the teammates (their
                            ``teammate_targets``). A policy without it is assigned a
                            frontier as ``context.goal``
``request_replan()``        choose again (two robots chose one target; the later yields)
``shared_target_radius``    m: targets this close count as one (default: a quarter of
                            the explorer's separation)
``change_frame(T)``         the map frame changes by the SE(2) ``T = new_from_old`` (the
                            robot joined the common frame): carry what is remembered in
                            map coordinates over
``done``                    True when nothing is left to explore (the run may stop early)
``plan``, ``frontiers``     (P, 2) / (F, 2) points in ``context.map``'s frame, drawn in
                            the recording
==========================  ============================================================
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from mrslam_env.config import EnvConfig
from mrslam_env.gridmap import GridMap

__all__ = [
    "ExplorationPolicy",
    "PolicyContext",
    "PolicyFactory",
    "build_policy",
    "load_policy_factory",
    "policy_label",
]

FloatArray = NDArray[np.float64]


def _no_points() -> FloatArray:
    return np.empty((0, 2))


@dataclass
class PolicyContext:
    """What the team knows when robot ``robot`` acts.

    Attributes
    ----------
    robot : int
        The robot's index (``robot_<i>``).
    step : int
        Team steps so far.
    map : GridMap
        The map to explore: the robot's own map, or, once the robot is in the team's common
        frame, the merged map in that frame.
    pose : ndarray, shape (3,)
        The robot's pose in ``map``'s frame.
    own_map : GridMap
        The robot's own SLAM map (its own frame), whatever ``map`` is.
    in_common_frame : bool
        True once a verified transform puts this robot in the team's common frame; ``map``
        is then the merged map.
    teammates : ndarray, shape (K, 2)
        Positions of the teammates known in ``map``'s frame (as last received over the
        link); empty before a merge.
    teammate_targets : ndarray, shape (K, 2)
        Where those teammates are heading, where known; empty otherwise.
    goal : ndarray, shape (2,) or None
        A point the team assigns this robot in ``map``'s frame (a frontier it owns after
        coordination), or None: the policy is free to choose.
    common_from_own : ndarray, shape (3,) or None
        The SE(2) transform from the robot's own map frame into the common frame once the
        robot is in it (``map``'s frame then), else None.
    """

    robot: int
    step: int
    map: GridMap
    pose: FloatArray
    own_map: GridMap
    in_common_frame: bool = False
    teammates: FloatArray = field(default_factory=_no_points)
    teammate_targets: FloatArray = field(default_factory=_no_points)
    goal: FloatArray | None = None
    common_from_own: FloatArray | None = None


@runtime_checkable
class ExplorationPolicy(Protocol):
    """Drives one robot while it explores (module notes)."""

    def reset(self) -> None:
        """Forget everything of the last episode."""
        ...

    def act(self, observation: dict[str, Any], context: PolicyContext) -> NDArray[np.float32]:
        """One normalised action ``(v, omega)`` in [-1, 1], float32 (2,)."""
        ...


PolicyFactory = Callable[[EnvConfig, np.random.Generator], ExplorationPolicy]


def load_policy_factory(spec: str) -> PolicyFactory:
    """The factory named by ``spec`` = ``"module:attribute"`` (``module`` importable, or a
    path to a ``.py`` file); ``ValueError`` with one line naming the problem otherwise."""
    module_name, sep, attribute = spec.partition(":")
    if not sep or not module_name or not attribute:
        raise ValueError(f"policy {spec!r}: expected 'module:factory'")
    try:
        if module_name.endswith(".py"):
            module = _module_from_path(module_name)
        else:
            module = importlib.import_module(module_name)
    except (ImportError, OSError, SyntaxError) as error:
        raise ValueError(f"policy {spec!r}: cannot import {module_name!r} ({error})") from error
    factory = getattr(module, attribute, None)
    if factory is None or not callable(factory):
        raise ValueError(f"policy {spec!r}: {module_name!r} has no callable {attribute!r}")
    return factory


def _module_from_path(path: str) -> Any:
    import importlib.util
    from pathlib import Path

    file = Path(path)
    if not file.is_file():
        raise ImportError(f"no file {path}")
    spec = importlib.util.spec_from_file_location(f"mrslam_user_policy_{file.stem}", file)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def build_policy(
    factory: PolicyFactory, env: EnvConfig, rng: np.random.Generator, name: str = ""
) -> ExplorationPolicy:
    """``factory(env, rng)``, checked: ``ValueError`` with one line when the factory fails
    to be called so or returns something without ``reset()`` and ``act(observation,
    context)``. ``name`` (the spec) names the policy in the message."""
    label = name or getattr(factory, "__name__", repr(factory))
    try:
        policy = factory(env, rng)
    except TypeError as error:
        raise ValueError(f"policy {label!r}: calling factory(env, rng) failed ({error})") from error
    if not isinstance(policy, ExplorationPolicy):
        raise ValueError(
            f"policy {label!r}: the factory returned {type(policy).__name__}, which has no "
            "reset() and act(observation, context) (agents.policy.ExplorationPolicy)"
        )
    return policy


def policy_label(spec: str | None) -> str:
    """A short name for a policy spec in tables and reports: ``"frontier"`` for None (the
    default), ``module:factory`` with a file path shortened to its stem."""
    if spec is None:
        return "frontier"
    module_name, _, attribute = spec.partition(":")
    if module_name.endswith(".py"):
        from pathlib import Path

        module_name = Path(module_name).stem
    return f"{module_name}:{attribute}"
