"""Skeleton of a map's free space and its graph (docs/design.md §5 step 1; paper §3.1).

The free space of a partial map is cleaned (unknown is not free; specks and small holes
that noisy SLAM maps leave behind would otherwise become skeleton spurs and loops), then
thinned to a one-pixel skeleton with the Zhang–Suen algorithm exactly as the paper states
it. Spurs shorter than a threshold are pruned, and the skeleton is turned into a graph of
junction and end nodes joined by edges (ordered cell paths) — the "topological edges" the
virtual robot drives along and near which MCL samples its particles.

Neighbour convention of the thinning (paper, Figure 2), with row 0 at the lowest y so
that "north" is ``row + 1``::

    p9 p2 p3        NW N NE
    p8 p1 p4   =    W  .  E
    p7 p6 p5        SW S SE

A set pixel ``p1`` is removed in the first sub-iteration when ``2 <= N(p1) <= 6``,
``S(p1) = 1``, ``p2·p4·p6 = 0`` and ``p4·p6·p8 = 0``; in the second when the first two hold
and ``p2·p4·p8 = 0``, ``p2·p6·p8 = 0``. ``N`` counts set neighbours, ``S`` the 0→1
transitions in the ring ``p2, p3, ..., p9, p2``. The two sub-iterations alternate until
neither removes a pixel, so the result is a fixed point of both.

Reference: T. Y. Zhang and C. Y. Suen, "A fast parallel algorithm for thinning digital
patterns", Comm. ACM 27(3), 1984.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from mrslam_env.gridmap import GridMap
from mrslam_env.validation import check_fields

BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

__all__ = [
    "NODE_END",
    "NODE_ISOLATED",
    "NODE_JUNCTION",
    "NODE_LOOP",
    "SkeletonConfig",
    "SkeletonEdge",
    "SkeletonGraph",
    "clean_free_space",
    "free_space_graph",
    "prune_spurs",
    "skeleton_graph",
    "skeletonize_free_space",
    "thin_to_eight_connected",
    "zhang_suen_thinning",
]

NODE_END = 1
"""Node kind: an end of the skeleton (one neighbour)."""
NODE_JUNCTION = 3
"""Node kind: a junction (three or more branches), possibly several adjacent pixels."""
NODE_ISOLATED = 0
"""Node kind: a skeleton pixel with no neighbour."""
NODE_LOOP = 2
"""Node kind: an arbitrary pixel chosen to open a closed loop that has no other node."""

# (drow, dcol) of p2..p9, clockwise from north (row + 1 is north).
_RING = np.array(
    [[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1]], dtype=np.int64
)
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True, slots=True, kw_only=True)
class SkeletonConfig:
    """How a map's free space is cleaned, thinned and pruned."""

    clearance: float = 0.0
    """Free cells closer than this to a non-free cell are dropped before thinning, m
    (0 keeps all free space). Keeps the skeleton away from walls in wide areas, but a
    passage narrower than twice this disappears."""
    min_hole_area: float = 0.1
    """Non-free blobs enclosed by free space and smaller than this become free, m²: lone
    unknown or noisy occupied cells would otherwise each put a loop in the skeleton."""
    smoothing_radius: float = 0.1
    """Radius of the morphological opening of the free space, m: removes the thin fingers
    that single lidar rays leave in unknown space (0 turns it off)."""
    min_component_area: float = 0.25
    """Free components smaller than this are dropped, m²."""
    min_spur_length: float = 0.6
    """Branches from an end to a junction shorter than this are pruned, m."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            non_negative=(
                "clearance",
                "min_hole_area",
                "smoothing_radius",
                "min_component_area",
                "min_spur_length",
            ),
        )


@dataclass(frozen=True, slots=True)
class SkeletonEdge:
    """One branch of the skeleton between two nodes.

    Attributes
    ----------
    start, end : int
        Node indices into :attr:`SkeletonGraph.nodes` (equal for a closed loop).
    cells : ndarray of int64, shape (L, 2)
        Ordered ``(row, col)`` cells from the start node's pixel to the end node's pixel,
        8-connected, both node pixels included.
    """

    start: int
    end: int
    cells: IntArray

    @property
    def length(self) -> float:
        """Path length in cells (diagonal steps count sqrt(2))."""
        if len(self.cells) < 2:
            return 0.0
        return float(np.hypot(*np.diff(self.cells, axis=0).T).sum())


@dataclass(frozen=True, slots=True)
class SkeletonGraph:
    """A skeleton as a graph.

    Attributes
    ----------
    skeleton : ndarray of bool, shape (rows, cols)
        The (8-connected, one pixel thin) skeleton the graph was built from.
    nodes : ndarray of int64, shape (K, 2)
        A representative ``(row, col)`` cell per node (for a junction made of several
        adjacent pixels, the one nearest their mean).
    node_kinds : ndarray of int64, shape (K,)
        :data:`NODE_END`, :data:`NODE_JUNCTION`, :data:`NODE_ISOLATED` or :data:`NODE_LOOP`.
    edges : list of SkeletonEdge
        Branches between nodes.
    """

    skeleton: BoolArray
    nodes: IntArray
    node_kinds: IntArray
    edges: list[SkeletonEdge] = field(default_factory=list)

    @property
    def total_length(self) -> float:
        """Summed edge length in cells."""
        return float(sum(edge.length for edge in self.edges))


def clean_free_space(
    grid: GridMap,
    *,
    clearance: float = 0.0,
    min_hole_area: float = 0.1,
    smoothing_radius: float = 0.1,
    min_component_area: float = 0.25,
) -> BoolArray:
    """The free space worth thinning: FREE cells, with small holes filled, thin fingers
    opened away, tiny components dropped and an optional clearance from non-free cells.

    Parameters
    ----------
    grid : GridMap
        The map; UNKNOWN and OCCUPIED cells are not free.
    clearance, min_hole_area, smoothing_radius, min_component_area : float
        See :class:`SkeletonConfig` (metres, square metres).

    Returns
    -------
    ndarray of bool, shape grid.shape
        A new mask; ``grid`` is not modified.
    """
    cell_area = grid.resolution**2
    free = grid.free.copy()
    if not free.any():
        return free
    # Holes: background components (4-connected, dual of 8-connected foreground) that do
    # not touch the border and are small.
    holes, n_holes = ndimage.label(~free)
    if n_holes:
        sizes = np.bincount(holes.ravel(), minlength=n_holes + 1)
        border = np.unique(np.concatenate([holes[0], holes[-1], holes[:, 0], holes[:, -1]]))
        fill = sizes * cell_area < min_hole_area
        fill[0] = False
        fill[border] = False
        free |= fill[holes]
    radius_cells = round(smoothing_radius / grid.resolution)
    if radius_cells > 0:
        yy, xx = np.mgrid[-radius_cells : radius_cells + 1, -radius_cells : radius_cells + 1]
        disc = yy**2 + xx**2 <= radius_cells**2
        free = ndimage.binary_opening(free, structure=disc)
    if clearance > 0:
        free &= ndimage.distance_transform_edt(free) * grid.resolution >= clearance
    components, n_components = ndimage.label(free, structure=_EIGHT)
    if n_components:
        sizes = np.bincount(components.ravel(), minlength=n_components + 1)
        keep = sizes * cell_area >= min_component_area
        keep[0] = False
        free = keep[components]
    return free


@numba.njit(cache=True)
def _zhang_suen_pass(image: NDArray[np.uint8], first: bool, marks: NDArray[np.uint8]) -> int:
    """One parallel sub-iteration: mark on the unchanged image, then delete. Returns the
    number of deleted pixels. ``image`` is padded by one zero pixel on every side."""
    rows, cols = image.shape
    count = 0
    for r in range(1, rows - 1):
        for c in range(1, cols - 1):
            marks[r, c] = 0
            if image[r, c] == 0:
                continue
            p2 = image[r + 1, c]
            p3 = image[r + 1, c + 1]
            p4 = image[r, c + 1]
            p5 = image[r - 1, c + 1]
            p6 = image[r - 1, c]
            p7 = image[r - 1, c - 1]
            p8 = image[r, c - 1]
            p9 = image[r + 1, c - 1]
            n = p2 + p3 + p4 + p5 + p6 + p7 + p8 + p9
            if n < 2 or n > 6:
                continue
            s = (
                (p2 == 0 and p3 == 1)
                + (p3 == 0 and p4 == 1)
                + (p4 == 0 and p5 == 1)
                + (p5 == 0 and p6 == 1)
                + (p6 == 0 and p7 == 1)
                + (p7 == 0 and p8 == 1)
                + (p8 == 0 and p9 == 1)
                + (p9 == 0 and p2 == 1)
            )
            if s != 1:
                continue
            if first:
                if p2 * p4 * p6 == 0 and p4 * p6 * p8 == 0:
                    marks[r, c] = 1
                    count += 1
            elif p2 * p4 * p8 == 0 and p2 * p6 * p8 == 0:
                marks[r, c] = 1
                count += 1
    if count:
        for r in range(1, rows - 1):
            for c in range(1, cols - 1):
                if marks[r, c]:
                    image[r, c] = 0
    return count


@numba.njit(cache=True)
def _zhang_suen(image: NDArray[np.uint8]) -> None:
    marks = np.zeros_like(image)
    while True:
        removed = _zhang_suen_pass(image, True, marks)
        removed += _zhang_suen_pass(image, False, marks)
        if removed == 0:
            return


def zhang_suen_thinning(mask: BoolArray) -> BoolArray:
    """Zhang–Suen thinning of a binary image, the paper's two sub-iterations (module doc).

    Parameters
    ----------
    mask : ndarray of bool, shape (rows, cols)
        Foreground pixels; not modified.

    Returns
    -------
    ndarray of bool, shape (rows, cols)
        A fixed point of both sub-iterations: no pixel satisfies either removal condition.
    """
    mask = np.asarray(mask, dtype=bool)
    if mask.ndim != 2:
        raise ValueError(f"thinning needs a 2-D mask, got shape {mask.shape}")
    out = np.zeros(mask.shape, dtype=bool)
    if not mask.any():
        return out
    rows, cols = np.nonzero(mask)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    image = np.zeros((r1 - r0 + 2, c1 - c0 + 2), dtype=np.uint8)
    image[1:-1, 1:-1] = mask[r0:r1, c0:c1]
    _zhang_suen(image)
    out[r0:r1, c0:c1] = image[1:-1, 1:-1].astype(bool)
    return out


def skeletonize_free_space(
    grid: GridMap,
    *,
    clearance: float = 0.0,
    min_hole_area: float = 0.1,
    smoothing_radius: float = 0.1,
    min_component_area: float = 0.25,
) -> BoolArray:
    """Zhang–Suen skeleton of a map's cleaned free space (paper §3.1, docs/design.md §5 step 1).

    Parameters
    ----------
    grid : GridMap
        The map; it is not modified.
    clearance, min_hole_area, smoothing_radius, min_component_area : float
        Cleaning of the free space, see :class:`SkeletonConfig` and
        :func:`clean_free_space`.

    Returns
    -------
    ndarray of bool, shape grid.shape
        Skeleton pixels, a subset of the cleaned free space (:func:`clean_free_space`:
        the FREE cells plus the small enclosed holes and specks it fills, so a skeleton
        may cross a noise speck of OCCUPIED cells); empty when nothing is free. Not yet
        pruned: see :func:`prune_spurs`.
    """
    free = clean_free_space(
        grid,
        clearance=clearance,
        min_hole_area=min_hole_area,
        smoothing_radius=smoothing_radius,
        min_component_area=min_component_area,
    )
    return zhang_suen_thinning(free)


@numba.njit(cache=True)
def _neighbour_groups(image: NDArray[np.uint8], r: int, c: int, ring: IntArray) -> int:
    """Number of 8-connected groups the set neighbours of (r, c) form among themselves."""
    # Ring positions are 8-adjacent to their ring neighbours; a 4-neighbour (even index)
    # is also 8-adjacent to the next-but-one 4-neighbour (e.g. N and E).
    present = np.zeros(8, dtype=np.uint8)
    for k in range(8):
        present[k] = image[r + ring[k, 0], c + ring[k, 1]]
    label = np.full(8, -1, dtype=np.int64)
    groups = 0
    stack = np.empty(8, dtype=np.int64)
    for k in range(8):
        if present[k] == 0 or label[k] >= 0:
            continue
        label[k] = groups
        top = 0
        stack[top] = k
        top += 1
        while top > 0:
            top -= 1
            j = stack[top]
            for m in range(8):
                if present[m] == 0 or label[m] >= 0:
                    continue
                dr = abs(ring[j, 0] - ring[m, 0])
                dc = abs(ring[j, 1] - ring[m, 1])
                if dr <= 1 and dc <= 1:
                    label[m] = groups
                    stack[top] = m
                    top += 1
        groups += 1
    return groups


@numba.njit(cache=True)
def _thin_eight(image: NDArray[np.uint8], ring: IntArray) -> None:
    """Sequentially delete corner pixels (two perpendicular 4-neighbours, 2 or 3
    neighbours in all) whose neighbours stay one 8-connected group without them."""
    rows, cols = image.shape
    changed = True
    while changed:
        changed = False
        for r in range(1, rows - 1):
            for c in range(1, cols - 1):
                if image[r, c] == 0:
                    continue
                n = 0
                for k in range(8):
                    n += image[r + ring[k, 0], c + ring[k, 1]]
                if n < 2 or n > 3:
                    continue
                north, south = image[r + 1, c], image[r - 1, c]
                east, west = image[r, c + 1], image[r, c - 1]
                corner = (north or south) and (east or west)
                if corner and _neighbour_groups(image, r, c, ring) == 1:
                    image[r, c] = 0
                    changed = True


def thin_to_eight_connected(skeleton: BoolArray) -> BoolArray:
    """Remove the staircase corners a 4-connected thinning leaves, keeping 8-connectivity.

    A corner pixel (a 4-neighbour on one axis and one on the other, two or three
    neighbours in all) whose neighbours form one 8-connected group without it is
    redundant: deleting it changes no connection, and ends (one neighbour) and crossings
    (four or more) are never touched. After this, a path pixel has two neighbours, which
    is what :func:`skeleton_graph` traces.
    """
    skeleton = np.asarray(skeleton, dtype=bool)
    out = np.zeros(skeleton.shape, dtype=bool)
    if not skeleton.any():
        return out
    image = np.zeros((skeleton.shape[0] + 2, skeleton.shape[1] + 2), dtype=np.uint8)
    image[1:-1, 1:-1] = skeleton
    _thin_eight(image, _RING)
    return image[1:-1, 1:-1].astype(bool)


def _neighbour_count(mask: BoolArray) -> IntArray:
    kernel = np.ones((3, 3), dtype=np.int64)
    kernel[1, 1] = 0
    counts = ndimage.convolve(mask.astype(np.int64), kernel, mode="constant")
    return np.where(mask, counts, 0)


@numba.njit(cache=True)
def _grow(buffer: IntArray, needed: int) -> IntArray:
    """``buffer`` (1-D) with room for at least ``needed`` entries (doubling)."""
    if needed <= buffer.shape[0]:
        return buffer
    grown = np.empty(max(needed, 2 * buffer.shape[0]), dtype=buffer.dtype)
    for i in range(buffer.shape[0]):  # a loop: a slice copy's shape check compiles slowly
        grown[i] = buffer[i]
    return grown


@numba.njit(cache=True)
def _grow_rows(buffer: IntArray, needed: int) -> IntArray:
    """``buffer`` (N, 2) with room for at least ``needed`` rows (doubling)."""
    if needed <= buffer.shape[0]:
        return buffer
    grown = np.empty((max(needed, 2 * buffer.shape[0]), 2), dtype=buffer.dtype)
    for i in range(buffer.shape[0]):  # a loop: a slice copy's shape check compiles slowly
        grown[i, 0] = buffer[i, 0]
        grown[i, 1] = buffer[i, 1]
    return grown


@numba.njit(cache=True)
def _trace_edges(
    thin: BoolArray, node_of: IntArray, node_count: int
) -> tuple[IntArray, IntArray, IntArray, IntArray, IntArray]:
    """The branches of :func:`skeleton_graph`: from every node pixel (row-major order)
    each ring neighbour (:data:`_RING` order) is either another node (a direct edge, once
    per pixel pair) or, when not yet visited, the start of a branch traced to the next
    node; then closed loops without nodes, each opened at its first pixel (row-major),
    which becomes a new node (``node_count`` onward; ``node_of`` is updated).

    Returns the edges' start and end nodes, the offsets of their cells in ``cells`` (the
    k-th edge is ``cells[offsets[k]:offsets[k + 1]]``) and the loop nodes' pixels.
    """
    rows, cols = thin.shape
    visited = np.zeros(thin.shape, dtype=np.bool_)
    cells = np.empty((1024, 2), dtype=np.int64)
    starts = np.empty(64, dtype=np.int64)
    ends = np.empty(64, dtype=np.int64)
    offsets = np.zeros(65, dtype=np.int64)
    n_edges = 0
    n_cells = 0
    ring = _RING
    loops = np.empty((16, 2), dtype=np.int64)
    n_loops = 0
    firsts = np.empty((8, 2), dtype=np.int64)
    for phase in range(2):
        for pixel in range(rows * cols):  # row-major
            r0, c0 = pixel // cols, pixel % cols
            if phase == 0 and node_of[r0, c0] < 0:
                continue
            n_first = 0
            if phase == 1:
                if not thin[r0, c0] or node_of[r0, c0] >= 0 or visited[r0, c0]:
                    continue
                loops = _grow_rows(loops, n_loops + 1)
                node_of[r0, c0] = node_count + n_loops
                loops[n_loops, 0] = r0
                loops[n_loops, 1] = c0
                n_loops += 1
                visited[r0, c0] = True
            for k in range(8):
                rr, cc = r0 + ring[k, 0], c0 + ring[k, 1]
                if 0 <= rr < rows and 0 <= cc < cols and thin[rr, cc]:
                    firsts[n_first, 0] = rr
                    firsts[n_first, 1] = cc
                    n_first += 1
            if phase == 1:
                n_first = min(n_first, 1)  # the loop is traced from its first neighbour
            for f in range(n_first):
                rn, cn = firsts[f, 0], firsts[f, 1]
                direct = phase == 0 and node_of[rn, cn] >= 0
                if direct:
                    if node_of[rn, cn] == node_of[r0, c0]:
                        continue  # inside one junction cluster
                    if rn * cols + cn < r0 * cols + c0:
                        continue  # added from that pixel, earlier in row-major order
                elif phase == 0 and visited[rn, cn]:
                    continue
                if n_edges + 1 >= starts.shape[0]:
                    starts = _grow(starts, 2 * starts.shape[0])
                    ends = _grow(ends, 2 * ends.shape[0])
                    offsets = _grow(offsets, 2 * starts.shape[0] + 1)
                cells = _grow_rows(cells, n_cells + 2)
                cells[n_cells, 0], cells[n_cells, 1] = r0, c0
                cells[n_cells + 1, 0], cells[n_cells + 1, 1] = rn, cn
                n_cells += 2
                if direct:
                    end_node = node_of[rn, cn]
                else:
                    pr, pc, cr, cc = r0, c0, rn, cn
                    while node_of[cr, cc] < 0:
                        visited[cr, cc] = True
                        found = False
                        nr, nc = -1, -1
                        for k in range(8):
                            rr, c2 = cr + ring[k, 0], cc + ring[k, 1]
                            if 0 <= rr < rows and 0 <= c2 < cols and thin[rr, c2]:
                                if rr == pr and c2 == pc:
                                    continue
                                nr, nc = rr, c2
                                found = True
                                break
                        if not found:  # cannot happen on an 8-thin skeleton; stop safely
                            break
                        pr, pc, cr, cc = cr, cc, nr, nc
                        cells = _grow_rows(cells, n_cells + 1)
                        cells[n_cells, 0], cells[n_cells, 1] = cr, cc
                        n_cells += 1
                        if cr == r0 and cc == c0:
                            break
                    end_node = node_of[cr, cc] if node_of[cr, cc] >= 0 else node_of[r0, c0]
                starts[n_edges] = node_of[r0, c0]
                ends[n_edges] = end_node
                n_edges += 1
                offsets[n_edges] = n_cells
    return (
        starts[:n_edges].copy(),
        ends[:n_edges].copy(),
        offsets[: n_edges + 1].copy(),
        cells[:n_cells].copy(),
        loops[:n_loops].copy(),
    )


def skeleton_graph(skeleton: BoolArray) -> SkeletonGraph:
    """Junction/end nodes and the branches between them.

    Parameters
    ----------
    skeleton : ndarray of bool, shape (rows, cols)
        A thin skeleton (e.g. from :func:`skeletonize_free_space`); not modified. It is
        first reduced with :func:`thin_to_eight_connected`.

    Returns
    -------
    SkeletonGraph
        Nodes are pixels with one neighbour (ends), none (isolated), or three or more
        (junctions; adjacent junction pixels form one node). Every branch is traced once;
        a closed loop without nodes gets a :data:`NODE_LOOP` node.
    """
    thin = thin_to_eight_connected(skeleton)
    degree = _neighbour_count(thin)
    node_of = np.full(thin.shape, -1, dtype=np.int64)
    nodes: list[tuple[int, int]] = []
    kinds: list[int] = []
    junction_labels, _ = ndimage.label(thin & (degree >= 3), structure=_EIGHT)
    for index, pixels in enumerate(ndimage.find_objects(junction_labels)):
        if pixels is None:
            continue
        corner = np.array([pixels[0].start, pixels[1].start])
        cells = np.argwhere(junction_labels[pixels] == index + 1) + corner
        centre = cells[np.argmin(((cells - cells.mean(axis=0)) ** 2).sum(axis=1))]
        node_of[cells[:, 0], cells[:, 1]] = len(nodes)
        nodes.append((int(centre[0]), int(centre[1])))
        kinds.append(NODE_JUNCTION)
    for kind, value in ((NODE_END, 1), (NODE_ISOLATED, 0)):
        for r, c in np.argwhere(thin & (degree == value)):
            node_of[r, c] = len(nodes)
            nodes.append((int(r), int(c)))
            kinds.append(kind)

    starts, ends, offsets, cells, loops = _trace_edges(thin, node_of, len(nodes))
    for r, c in loops:
        nodes.append((int(r), int(c)))
        kinds.append(NODE_LOOP)
    edges = [
        SkeletonEdge(int(starts[k]), int(ends[k]), cells[offsets[k] : offsets[k + 1]].copy())
        for k in range(len(starts))
    ]
    return SkeletonGraph(
        skeleton=thin,
        nodes=np.array(nodes, dtype=np.int64).reshape(-1, 2),
        node_kinds=np.array(kinds, dtype=np.int64),
        edges=edges,
    )


def prune_spurs(skeleton: BoolArray, min_length: float) -> BoolArray:
    """Remove branches shorter than ``min_length`` that end in a free end.

    Repeats until no such branch is left (pruning a spur can merge two branches into a
    longer one). A whole component shorter than ``min_length`` (a branch with two free
    ends, or an isolated pixel) is removed too.

    Parameters
    ----------
    skeleton : ndarray of bool, shape (rows, cols)
        A thin skeleton; not modified.
    min_length : float
        Minimum branch length to keep, in cells (diagonal steps count sqrt(2)).

    Returns
    -------
    ndarray of bool, shape (rows, cols)
        The pruned, 8-connected skeleton.
    """
    if not (math.isfinite(min_length) and min_length >= 0):
        raise ValueError(f"prune_spurs: min_length must be a finite number >= 0, got {min_length}")
    current = thin_to_eight_connected(skeleton)
    while True:
        graph = skeleton_graph(current)
        kinds = graph.node_kinds
        removed = False
        for r, c in graph.nodes[kinds == NODE_ISOLATED]:
            if min_length > 0:
                current[r, c] = False
                removed = True
        for edge in graph.edges:
            if edge.length >= min_length:
                continue
            start_kind, end_kind = kinds[edge.start], kinds[edge.end]
            if start_kind == NODE_END and end_kind == NODE_END:
                current[edge.cells[:, 0], edge.cells[:, 1]] = False
                removed = True
            elif start_kind == NODE_END and end_kind == NODE_JUNCTION:
                current[edge.cells[:-1, 0], edge.cells[:-1, 1]] = False
                removed = True
            elif end_kind == NODE_END and start_kind == NODE_JUNCTION:
                current[edge.cells[1:, 0], edge.cells[1:, 1]] = False
                removed = True
        if not removed:
            return current
        current = thin_to_eight_connected(current)


def free_space_graph(grid: GridMap, config: SkeletonConfig | None = None) -> SkeletonGraph:
    """Skeleton graph of a map's free space: clean, thin, prune, trace (step 1 in full).

    Parameters
    ----------
    grid : GridMap
        The map.
    config : SkeletonConfig, optional
        Cleaning and pruning parameters (defaults if omitted).
    """
    config = config or SkeletonConfig()
    skeleton = skeletonize_free_space(
        grid,
        clearance=config.clearance,
        min_hole_area=config.min_hole_area,
        smoothing_radius=config.smoothing_radius,
        min_component_area=config.min_component_area,
    )
    pruned = prune_spurs(skeleton, config.min_spur_length / grid.resolution)
    return skeleton_graph(pruned)
