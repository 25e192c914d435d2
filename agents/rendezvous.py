"""Rendezvous verification of a merge hypothesis (docs/design.md §5 step 5, §6).

For a hypothesis ``T = map0_from_map1`` and the robots' current SLAM poses ``p0`` (in map
0) and ``p1`` (in map 1), robot 1 should stand at ``T3 = p0⁻¹ · T · p1`` in robot 0's body
frame (the paper's ``T3 = T1⁻¹ · T · T2``). The robots drive to a meeting point chosen
free and reachable in both maps so that the later of the two arrives as early as
possible; the peer sensor then settles it: the other robot seen where predicted (within
the tolerances) accepts ``T``; a sighting elsewhere, or arriving and waiting without any
sighting, rejects it.

Two more sensors check a hypothesis without a meeting: the peer sensor's silence where the
hypothesis puts the other robot in plain sight (:func:`in_plain_sight`), and the radio
link as a range sensor (:func:`radio_contradiction`, :func:`heading_allowance`).

Pure functions on arrays and poses; the team's verification role
(:mod:`agents.team_verification`) drives them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import compose, inverse, transform_points, wrap_scalar
from mrslam_env.gridmap import GridMap
from mrslam_env.validation import check_fields

__all__ = [
    "SIGHT_BAND",
    "RendezvousConfig",
    "Sighting",
    "choose_meeting_point",
    "field_on_lattice",
    "heading_allowance",
    "in_plain_sight",
    "judge_sighting",
    "predicted_relative_pose",
    "radio_contradiction",
    "sighting_pose",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True, kw_only=True)
class RendezvousConfig:
    """How a rendezvous is judged."""

    position_tolerance: float = 0.6
    """A sighting matches the prediction when the other robot is within this distance (m)
    of where the hypothesis puts it: SLAM drift of both robots since their maps were
    merged, the hypothesis' own error and the peer sensor's noise all fit inside."""
    heading_tolerance: float = math.radians(20.0)
    """... and its heading within this (rad)."""
    wait_steps: int = 40
    """After both robots arrived, wait this many steps for a sighting before rejecting."""
    timeout_steps: int = 900
    """Give up on a rendezvous (reject) after this many steps in all."""
    confirm_motion: float = 1.0
    """One matching sighting is not enough: a wrong hypothesis that differs from the
    truth by a symmetry of the building centred near the robots predicts the other robot
    where it is at one instant. The hypothesis is accepted once the sightings have kept
    matching while the robots moved this far (m, both robots' travel added up) since the
    first match; any contradicting sighting rejects it."""
    confirm_sightings: int = 3
    """... and at least this many matching sightings were made."""
    confirm_steps: int = 150
    """Steps after the first match within which the confirmation must come; otherwise the
    hypothesis is set aside unjudged (not rejected: it is proposed again later)."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=("position_tolerance", "heading_tolerance", "confirm_motion"),
            counts=("wait_steps", "timeout_steps", "confirm_sightings", "confirm_steps"),
        )


@dataclass(frozen=True, slots=True)
class Sighting:
    """A peer-sensor sighting judged against a prediction."""

    matches: bool
    position_error: float
    """m."""
    heading_error: float
    """rad, absolute."""


def predicted_relative_pose(
    pose0_in_map0: ArrayLike, pose1_in_map1: ArrayLike, map0_from_map1: ArrayLike
) -> FloatArray:
    """Where robot 1 should be in robot 0's body frame if ``map0_from_map1`` is right:
    ``T3 = p0⁻¹ · T · p1``, shape (3,)."""
    return compose(inverse(pose0_in_map0), compose(map0_from_map1, pose1_in_map1))


def sighting_pose(range_m: float, bearing: float, relative_heading: float) -> FloatArray:
    """The pose (3,) of a sighted robot in the observer's body frame, from the peer
    sensor's ``(range, bearing, relative heading)``."""
    return np.array(
        [range_m * math.cos(bearing), range_m * math.sin(bearing), wrap_scalar(relative_heading)]
    )


def judge_sighting(measured: ArrayLike, predicted: ArrayLike, config: RendezvousConfig) -> Sighting:
    """Compare a sighting (``sighting_pose``) with the predicted relative pose."""
    m = np.asarray(measured, dtype=np.float64)
    p = np.asarray(predicted, dtype=np.float64)
    position_error = float(np.hypot(*(m[:2] - p[:2])))
    heading_error = abs(wrap_scalar(float(m[2] - p[2])))
    matches = (
        position_error <= config.position_tolerance and heading_error <= config.heading_tolerance
    )
    return Sighting(matches, position_error, heading_error)


def field_on_lattice(
    field1: NDArray[np.floating], grid1: GridMap, grid0: GridMap, map0_from_map1: ArrayLike
) -> FloatArray:
    """Resample a per-cell field of map 1 (e.g. robot 1's travel cost) onto map 0's
    lattice through ``map0_from_map1`` (nearest cell); ``inf`` where map 1 has no cell."""
    rows, cols = grid0.cells.shape
    cells0 = np.indices((rows, cols)).reshape(2, -1).T
    points_in_1 = transform_points(inverse(map0_from_map1), grid0.cell_to_world(cells0))
    cells1 = grid1.world_to_cell(points_in_1)
    inside = grid1.contains(cells1)
    out = np.full(rows * cols, np.inf)
    out[inside] = np.asarray(field1, dtype=np.float64)[cells1[inside, 0], cells1[inside, 1]]
    return out.reshape(rows, cols)


def choose_meeting_point(
    cost0: NDArray[np.floating], cost1: NDArray[np.floating], grid0: GridMap
) -> tuple[FloatArray, float] | None:
    """The meeting point minimising the later arrival.

    Parameters
    ----------
    cost0, cost1 : ndarray, shape of ``grid0.cells``
        Travel cost (m, ``inf`` where unreachable or not free) of robot 0 and robot 1 to
        every cell of map 0's lattice (robot 1's through :func:`field_on_lattice`).
    grid0 : GridMap
        Map 0 (the lattice).

    Returns
    -------
    (point, cost) or None
        The point (2,) in map 0's frame and ``max(cost0, cost1)`` there (m); None when no
        cell is reachable by both.
    """
    later = np.maximum(np.asarray(cost0, dtype=np.float64), np.asarray(cost1, dtype=np.float64))
    if not np.isfinite(later).any():
        return None
    # Ties (a plateau of equal later arrivals) go to the smaller total travel.
    total = np.where(np.isfinite(later), later + 1e-3 * (cost0 + cost1), np.inf)
    flat = int(np.argmin(total))
    cell = np.array(np.unravel_index(flat, later.shape))
    return grid0.cell_to_world(cell[None, :])[0], float(later.flat[flat])


# --- the peer sensor and the radio as checks of a hypothesis (design §6) ------------

SIGHT_BAND = (-0.25, 0.0, 0.25)
"""Offsets (m) of the lines of sight checked side by side."""


def in_plain_sight(
    pose: FloatArray, predicted: FloatArray, grid: GridMap, *, sight_range: float
) -> bool:
    """Whether a robot at ``predicted`` (its pose in the observer's body frame) would be
    in the peer sensor's sight from ``pose`` (the observer's pose in ``grid``): closer than
    ``sight_range`` (m, :attr:`agents.team_config.TeamConfig.in_sight_range`) and further
    than 0.5 m, across cells ``grid`` knows to be free all the way, in a band
    :data:`SIGHT_BAND` wide."""
    distance = float(np.hypot(predicted[0], predicted[1]))
    if not 0.5 < distance < sight_range:
        return False
    start = pose[:2]
    end = transform_points(pose, predicted[None, :2])[0]
    # A band, not a line: the prediction is only good to a few decimetres, and a wall
    # corner just beside the line would hide the robot.
    normal = np.array([start[1] - end[1], end[0] - start[0]]) / distance
    line = start + np.linspace(0.0, 1.0, 50)[:, None] * (end - start)
    samples = np.concatenate([line + offset * normal for offset in SIGHT_BAND])
    cells = grid.world_to_cell(samples)
    if not grid.contains(cells).all():
        return False
    return bool(grid.free[cells[:, 0], cells[:, 1]].all())


def radio_contradiction(
    hypothesis: FloatArray,
    track0: FloatArray,
    track1: FloatArray,
    link: NDArray[np.bool_],
    *,
    comm_range: float,
    exact: bool,
    allowance: ArrayLike = 0.0,
) -> float:
    """How far (m) ``hypothesis`` (``side0_from_side1``) puts two robots outside what
    their radio link said, at worst over the steps given: on a step the link was up, the
    amount by which the robots' distance under the hypothesis exceeds ``comm_range``; on
    one it was down (only if the link is up ``exact``-ly within ``comm_range``), the
    amount by which it falls short of it; less the step's ``allowance`` (m, scalar or
    (T,): the error a true hypothesis may have there). ``track0`` (T, 2) and ``track1``
    (T, 2) are the robots' positions in their side's frame on those steps, ``link`` (T,)
    whether the link was up. Negative (or -inf for no step) when the hypothesis agrees
    with the radio."""
    if len(link) == 0:
        return -math.inf
    predicted = transform_points(hypothesis, np.asarray(track1, dtype=np.float64))
    distance = np.hypot(*(predicted - np.asarray(track0, dtype=np.float64)).T)
    down = comm_range - distance if exact else np.full_like(distance, -math.inf)
    return float((np.where(link, distance - comm_range, down) - allowance).max())


def heading_allowance(track: FloatArray, known: FloatArray, tolerance: float) -> FloatArray:
    """(T,) m: how far a heading error of ``tolerance`` (rad) moves each place of
    ``track`` (T, 2) about a pivot anywhere in the box bounding ``known`` (K, 2; the
    robot's whole track, where the maps that pin the hypothesis were made): the tangent
    times the distance to the box's farthest corner."""
    track = np.asarray(track, dtype=np.float64).reshape(-1, 2)
    known = np.asarray(known, dtype=np.float64).reshape(-1, 2)
    if len(known) == 0 or len(track) == 0:
        return np.zeros(len(track))
    low, high = known.min(axis=0), known.max(axis=0)
    reach = np.maximum(np.abs(track - low), np.abs(track - high))
    return math.tan(tolerance) * np.hypot(*reach.T)
