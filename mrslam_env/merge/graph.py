"""Joint refinement of N map frames: pairwise alignments solved as one pose graph.

A team of robots holds its maps in one common frame through a graph of verified
transforms. Chained along the graph, each transform carries the errors of the ones before
it; a cycle (robots 0, 1 and 2 whose maps all overlap) is not closed, and each join is
refined against one map only. Here every pair of maps that overlaps under the current
estimate is aligned on its own (:func:`~mrslam_env.merge.pipeline.refine_transform`, the
merge's random walk, started from the estimate), giving a relative transform
``mapi_from_mapj`` with a weight; then a small pose-graph least squares (one frame held
fixed) gives every map's transform into the common frame that agrees best with all the
edges at once (Lu & Milios, "Globally consistent range scan alignment", 1997, on maps
instead of scans).

The residual of an edge is measured where it matters, at a point of the overlap (its
``pivot``, in map j): how far that point moves and how much map j turns between where
map i's edge and the solution put it. About the pivot, rotation and translation are
nearly independent (as in the random walk, :mod:`.refine`). Each edge is weighted by its
information (:func:`wall_information`): the walls the two maps share pin the alignment
across them and not along them, so an overlap that is one corridor, which the random walk
can slide along, does not pull the solution along the corridor.

:func:`solve_pose_graph` is the pure least squares (no maps); :func:`pairwise_edges`
aligns the overlapping pairs; :func:`alignment_edge` makes an edge of an alignment done
elsewhere (the team's verified joins, refined on the groups' merged maps);
:func:`refine_jointly` solves them together.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.geometry import compose, inverse, transform_points, wrap_angle, wrap_scalar
from mrslam_env.gridmap import GridMap
from mrslam_env.merge.fuse import at_resolution
from mrslam_env.merge.pipeline import MergeConfig, refine_transform
from mrslam_env.validation import check_fields

__all__ = [
    "GraphEdge",
    "JointRefineConfig",
    "JointRefinement",
    "alignment_edge",
    "pairwise_edges",
    "refine_jointly",
    "solve_pose_graph",
    "wall_information",
]

FloatArray = NDArray[np.float64]

ROTATION_LENGTH = 5.0
"""Metres a turn's residual is measured at (a turn of ``a`` rad counts as ``a * 5`` m of
displacement): about the size of a room, the lever over which a turn of the frames shows
up as misplaced walls."""


@dataclass(frozen=True, slots=True)
class GraphEdge:
    """One relative transform between two maps of the graph.

    Attributes
    ----------
    i, j : int
        The maps (nodes) it relates, ``i != j``.
    mapi_from_mapj : ndarray (3,)
        Map j's frame in map i's frame.
    weight : float
        How much the solution trusts it (> 0; e.g. the overlap's agreeing cells).
    pivot : ndarray (2,)
        A point of the overlap, in map j's frame, where the residual is measured.
    information : ndarray (3, 3) or None
        Directional trust, in map j's frame about the pivot (``(dx, dy, dtheta)``): the
        alignment's wall-normal information (:func:`wall_information`), so that a
        corridor's overlap constrains across the corridor and not along it. None: the
        same trust in every direction, ``weight * diag(1, 1, ROTATION_LENGTH**2)``.
    """

    i: int
    j: int
    mapi_from_mapj: FloatArray
    weight: float
    pivot: FloatArray
    information: FloatArray | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class JointRefineConfig:
    """Which pairwise alignments become edges, and how they may move the estimate."""

    merge: MergeConfig = field(default_factory=lambda: MergeConfig(correlation_candidates=0))
    """The pairwise refinement (its random walks and resolution)."""
    min_overlap_area: float = 3.0
    """A pair is aligned only when its maps overlap on at least this much (m²) under the
    refined transform (the merge's own ``min_overlap_area``)."""
    min_acceptance_index: float = 0.9
    """... and agree on at least this fraction of the overlapping cells (the acceptance
    index; the merge's own decision no longer uses it, but a pose-graph edge between two
    maps already merged must fit this well)."""
    max_shift: float = 0.3
    """An alignment that moves the pair's relation further than this at the pivot (m) is
    not an edge: it has left the estimate for another fit (the rendezvous tolerance)."""
    max_turn: float = math.radians(3.0)
    """... or that turns it by more than this (rad)."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=("min_overlap_area", "max_shift", "max_turn"),
        )
        index = self.min_acceptance_index
        if not (isinstance(index, int | float) and 0.0 <= index <= 1.0):
            raise ValueError(
                f"JointRefineConfig.min_acceptance_index must be in [0, 1], got {index!r}"
            )


@dataclass(frozen=True, slots=True)
class JointRefinement:
    """The outcome of :func:`refine_jointly`.

    Attributes
    ----------
    transforms : list of ndarray (3,)
        ``common_from_map_k`` per map, the fixed one unchanged.
    edges : list of GraphEdge
        The pairwise alignments the solution used.
    """

    transforms: list[FloatArray]
    edges: list[GraphEdge]


def _edge_misfit(edge: GraphEdge, poses: FloatArray) -> FloatArray:
    """(3,) misfit of ``edge`` given ``poses`` (N, 3), ``common_from_map_k``, in map j's
    frame: how far the pivot moves (m, x and y) and how much map j turns (rad) between
    where the solution puts map j and where map i's edge does."""
    through_i = compose(poses[edge.i], edge.mapi_from_mapj)
    difference = compose(inverse(poses[edge.j]), through_i)
    moved = transform_points(difference, edge.pivot[None, :])[0] - edge.pivot
    return np.array([moved[0], moved[1], wrap_scalar(float(difference[2]))])


def graph_residuals(edges: Sequence[GraphEdge], poses: ArrayLike) -> FloatArray:
    """(E, 3) misfits of ``edges`` given ``poses`` (N, 3), unweighted: the pivot's
    displacement (m, in map j's frame) and the turn times :data:`ROTATION_LENGTH` (m)."""
    poses = np.asarray(poses, dtype=np.float64)
    if not edges:
        return np.empty((0, 3))
    misfits = np.array([_edge_misfit(edge, poses) for edge in edges])
    return misfits * np.array([1.0, 1.0, ROTATION_LENGTH])


def _square_root(edge: GraphEdge) -> FloatArray:
    """(3, 3) ``L.T`` with ``L @ L.T`` the edge's information: ``L.T @ misfit`` is its
    weighted residual."""
    if edge.information is None:
        return np.sqrt(edge.weight) * np.diag([1.0, 1.0, ROTATION_LENGTH])
    information = np.asarray(edge.information, dtype=np.float64)
    # A small isotropic floor keeps the factorisation defined (a wall seen from one side
    # only leaves a direction unconstrained).
    floor = 1e-6 * max(float(np.trace(information)), 1e-12)
    lower = np.linalg.cholesky(information + floor * np.eye(3))
    return np.asarray(lower.T, dtype=np.float64)


def solve_pose_graph(
    initial: ArrayLike, edges: Sequence[GraphEdge], *, fixed: int = 0
) -> list[FloatArray]:
    """The poses that agree best with all ``edges`` (weighted least squares).

    Parameters
    ----------
    initial : array_like (N, 3)
        ``common_from_map_k`` per node: the starting estimate (e.g. the chained edges).
    edges : sequence of GraphEdge
        Relative transforms between nodes (``0 <= i, j < N``).
    fixed : int
        The node held where it is (the group's root, robot 0 for the common frame).

    Returns
    -------
    list of ndarray (3,)
        The solved ``common_from_map_k`` (theta wrapped). A node the edges do not connect
        to ``fixed`` keeps its initial pose.
    """
    from scipy.optimize import least_squares

    poses = np.asarray(initial, dtype=np.float64).reshape(-1, 3).copy()
    n = len(poses)
    if not 0 <= fixed < n:
        raise ValueError(f"fixed must be a node index in [0, {n}), got {fixed!r}")
    for edge in edges:
        if not (0 <= edge.i < n and 0 <= edge.j < n and edge.i != edge.j):
            raise ValueError(f"edge ({edge.i}, {edge.j}) is not between two of {n} nodes")
        if not (math.isfinite(edge.weight) and edge.weight > 0):
            raise ValueError(f"edge ({edge.i}, {edge.j}) needs a weight > 0, got {edge.weight}")
        information = edge.information
        if information is not None and (
            np.shape(information) != (3, 3) or not np.all(np.isfinite(information))
        ):
            raise ValueError(f"edge ({edge.i}, {edge.j}) needs a finite (3, 3) information")
    free = sorted(_component(fixed, edges) - {fixed})
    if not edges or not free:
        return [p.copy() for p in poses]
    roots = [_square_root(edge) for edge in edges]
    scale = max(float(np.abs(root).max()) for root in roots)
    roots = [root / scale for root in roots]

    def residuals(x: FloatArray) -> FloatArray:
        current = poses.copy()
        current[free] = x.reshape(-1, 3)
        return np.concatenate(
            [root @ _edge_misfit(edge, current) for edge, root in zip(edges, roots, strict=True)]
        )

    solution = least_squares(residuals, poses[free].ravel(), method="trf")
    solved = poses.copy()
    solved[free] = solution.x.reshape(-1, 3)
    solved[:, 2] = wrap_angle(solved[:, 2])
    return [p.copy() for p in solved]


def _component(node: int, edges: Sequence[GraphEdge]) -> set[int]:
    """The nodes the edges connect to ``node`` (itself included)."""
    reached = {node}
    grown = True
    while grown:
        grown = False
        for edge in edges:
            if (edge.i in reached) != (edge.j in reached):
                reached |= {edge.i, edge.j}
                grown = True
    return reached


def wall_information(
    mi: GridMap, mj: GridMap, mapi_from_mapj: ArrayLike, pivot: ArrayLike
) -> FloatArray:
    """(3, 3) information of an alignment of map j on map i, from the walls they share.

    Each occupied cell of map j that lands within one cell of an occupied cell of map i
    (a wall both maps hold) pins map j along that wall's normal ``n`` (from the structure
    tensor of map j's smoothed occupancy) and no other way: it adds ``J.T @ J`` with
    ``J = [n_x, n_y, n x (p - pivot)]`` for a move ``(dx, dy, dtheta)`` of map j about the
    pivot (``p``: the cell, map j's frame). Walls of one direction (a corridor) leave the
    move along them unconstrained, as the alignment leaves it unknown; this is the
    Hessian of point-to-line ICP (Censi, "An accurate closed-form estimate of ICP's
    covariance", 2007). Units: cells of wall times m² / m / 1.
    """
    from scipy import ndimage

    transform = np.asarray(mapi_from_mapj, dtype=np.float64)
    pivot = np.asarray(pivot, dtype=np.float64)
    walls_j = mj.occupied
    cells = np.argwhere(walls_j)
    if len(cells) == 0:
        return np.zeros((3, 3))
    points = mj.cell_to_world(cells)
    near_i = ndimage.binary_dilation(mi.occupied, iterations=1)
    in_i = mi.world_to_cell(transform_points(transform, points))
    inside = mi.contains(in_i)
    shared = np.zeros(len(cells), dtype=bool)
    shared[inside] = near_i[in_i[inside, 0], in_i[inside, 1]]
    if not shared.any():
        return np.zeros((3, 3))
    # The wall's normal at each cell: the structure tensor of map j's smoothed occupancy
    # (the gradient is zero on a one-cell wall's own line; its outer product around the
    # line is not), normalised to trace 1: ``n n^T`` on a straight wall, half the identity
    # at a corner.
    smooth = ndimage.gaussian_filter(walls_j.astype(np.float64), sigma=1.0)
    # Rows are y (cell index 0), columns x.
    d_row, d_col = np.gradient(smooth)
    tensor_xx = ndimage.gaussian_filter(d_col * d_col, sigma=2.0)
    tensor_xy = ndimage.gaussian_filter(d_col * d_row, sigma=2.0)
    tensor_yy = ndimage.gaussian_filter(d_row * d_row, sigma=2.0)
    rows, cols = cells[shared, 0], cells[shared, 1]
    xx, xy, yy = tensor_xx[rows, cols], tensor_xy[rows, cols], tensor_yy[rows, cols]
    trace = xx + yy
    keep = trace > 1e-12
    xx, xy, yy = xx[keep] / trace[keep], xy[keep] / trace[keep], yy[keep] / trace[keep]
    lever = points[shared][keep] - pivot
    # A turn dtheta about the pivot moves a point by dtheta * (-lever_y, lever_x).
    across_x, across_y = -lever[:, 1], lever[:, 0]
    turn_x = xx * across_x + xy * across_y
    turn_y = xy * across_x + yy * across_y
    turn_turn = across_x * turn_x + across_y * turn_y
    return np.array(
        [
            [xx.sum(), xy.sum(), turn_x.sum()],
            [xy.sum(), yy.sum(), turn_y.sum()],
            [turn_x.sum(), turn_y.sum(), turn_turn.sum()],
        ]
    )


def _overlap_pivot(mi: GridMap, mj: GridMap, mapi_from_mapj: FloatArray) -> FloatArray | None:
    """The centroid (map j's frame) of map j's known cells that land on known cells of
    map i under ``mapi_from_mapj``; None when none do."""
    known_j = ~mj.unknown
    cells = np.argwhere(known_j)
    if len(cells) == 0:
        return None
    points_j = mj.cell_to_world(cells)
    in_i = mi.world_to_cell(transform_points(mapi_from_mapj, points_j))
    inside = mi.contains(in_i)
    hit = np.zeros(len(cells), dtype=bool)
    hit[inside] = ~mi.unknown[in_i[inside, 0], in_i[inside, 1]]
    if not hit.any():
        return None
    return points_j[hit].mean(axis=0)


def pairwise_edges(
    maps: Sequence[GridMap],
    estimate: Sequence[ArrayLike],
    config: JointRefineConfig | None = None,
    *,
    rng: np.random.Generator,
) -> list[GraphEdge]:
    """Align every pair of ``maps`` that overlaps under ``estimate`` (``common_from_map_k``).

    Each pair ``i < j`` whose known cells meet under the estimate is refined by the
    merge's random walk from ``inverse(estimate[i]) ∘ estimate[j]``; it becomes an edge
    when the refined maps overlap on ``config.min_overlap_area`` m² or more, agree on
    ``config.min_acceptance_index`` of it, and the refinement stayed within
    ``config.max_shift`` / ``config.max_turn`` of the estimate at the overlap. Its trust
    is the shared walls' information (:func:`wall_information`); its ``weight`` the
    overlap's agreeing area (m², for reports).
    """
    config = config if config is not None else JointRefineConfig()
    estimate = [np.asarray(e, dtype=np.float64) for e in estimate]
    if len(estimate) != len(maps):
        raise ValueError(f"{len(maps)} maps need as many transforms, got {len(estimate)}")
    resolution = min(m.resolution for m in maps)
    grids = [at_resolution(m, resolution) for m in maps]
    edges = []
    for i in range(len(grids)):
        for j in range(i + 1, len(grids)):
            guess = compose(inverse(estimate[i]), estimate[j])
            pivot = _overlap_pivot(grids[i], grids[j], guess)
            if pivot is None:
                continue
            try:
                refined, _, agreement = refine_transform(
                    grids[i], grids[j], guess, config.merge, rng=rng
                )
            except ValueError:  # too little known to refine
                continue
            cell_area = resolution**2
            if agreement.overlap * cell_area < config.min_overlap_area:
                continue
            if agreement.index < config.min_acceptance_index:
                continue
            moved = transform_points(refined, pivot[None, :]) - transform_points(
                guess, pivot[None, :]
            )
            turned = abs(wrap_scalar(float(refined[2] - guess[2])))
            if float(np.hypot(*moved[0])) > config.max_shift or turned > config.max_turn:
                continue
            edge = _wall_edge(i, j, grids[i], grids[j], refined, pivot, agreement.agree * cell_area)
            if edge is not None:
                edges.append(edge)
    return edges


def _wall_edge(
    i: int,
    j: int,
    mi: GridMap,
    mj: GridMap,
    mapi_from_mapj: FloatArray,
    pivot: FloatArray,
    weight: float,
) -> GraphEdge | None:
    """The edge ``i``-``j`` trusted by the walls ``mi`` and ``mj`` (same resolution) share
    about ``pivot`` under ``mapi_from_mapj``; None when they share none."""
    walls = wall_information(mi, mj, mapi_from_mapj, pivot)
    if not np.any(walls):
        return None
    # Each shared wall cell pins its normal to about a cell.
    return GraphEdge(
        i=i,
        j=j,
        mapi_from_mapj=mapi_from_mapj,
        weight=weight,
        pivot=pivot,
        information=walls / mi.resolution**2,
    )


def refine_jointly(
    maps: Sequence[GridMap],
    estimate: Sequence[ArrayLike],
    config: JointRefineConfig | None = None,
    *,
    rng: np.random.Generator,
    fixed: int = 0,
    known_edges: Sequence[GraphEdge] = (),
) -> JointRefinement:
    """Every map's ``common_from_map_k`` refined jointly: :func:`pairwise_edges` on the
    overlapping pairs and the ``known_edges`` (e.g. the alignments that joined the maps,
    :func:`alignment_edge`), then :func:`solve_pose_graph` with map ``fixed`` held."""
    initial = np.array([np.asarray(e, dtype=np.float64) for e in estimate]).reshape(-1, 3)
    edges = pairwise_edges(maps, list(initial), config, rng=rng) + list(known_edges)
    return JointRefinement(transforms=solve_pose_graph(initial, edges, fixed=fixed), edges=edges)


def alignment_edge(
    i: int, j: int, mi: GridMap, mj: GridMap, mapi_from_mapj: ArrayLike, weight: float = 1.0
) -> GraphEdge | None:
    """The edge ``i``-``j`` of an alignment of map ``mj`` on ``mi`` made elsewhere (e.g.
    a verified, refined join of two groups' maps): its trust from the walls the maps
    share there (:func:`wall_information`); None when they share none."""
    transform = np.asarray(mapi_from_mapj, dtype=np.float64)
    mj = at_resolution(mj, mi.resolution)
    pivot = _overlap_pivot(mi, mj, transform)
    if pivot is None:
        return None
    return _wall_edge(i, j, mi, mj, transform, pivot, weight)
