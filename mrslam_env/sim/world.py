"""Static world geometry: wall polygons, the lidar's segments, start poses, ground truth.

A :class:`WorldSpec` is pure data (numpy arrays, no pymunk): scenarios build it, the
simulator turns its wall polygons into static pymunk shapes and hands its segments to the
lidar kernel. Walls are convex quadrilaterals; the lidar sees exactly their boundary, so
robots collide with exactly what the lidar measures.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
from mrslam_env.validation import require

FloatArray = NDArray[np.float64]

__all__ = [
    "WorldSpec",
    "box",
    "ground_truth_map",
    "polygon_edges",
    "polyline_walls",
    "thick_segment",
]

DEFAULT_WALL_THICKNESS = 0.1  # m


def box(x0: float, y0: float, x1: float, y1: float) -> FloatArray:
    """Axis-aligned rectangle as a counter-clockwise quad (4, 2), metres."""
    xa, xb = sorted((float(x0), float(x1)))
    ya, yb = sorted((float(y0), float(y1)))
    return np.array([[xa, ya], [xb, ya], [xb, yb], [xa, yb]], dtype=np.float64)


def thick_segment(
    p: ArrayLike, q: ArrayLike, thickness: float = DEFAULT_WALL_THICKNESS
) -> FloatArray:
    """A wall of ``thickness`` metres centred on segment p–q, extended by half the
    thickness past both ends so that walls meeting at a corner leave no gap.

    Returns a counter-clockwise quad (4, 2).
    """
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    d = q - p
    length = float(np.hypot(*d))
    if length == 0.0:
        raise ValueError(f"wall segment has zero length at {p.tolist()}")
    u = d / length
    n = np.array([-u[1], u[0]])
    h = thickness / 2.0
    a, b = p - u * h, q + u * h
    return np.array([a - n * h, b - n * h, b + n * h, a + n * h], dtype=np.float64)


def polyline_walls(
    points: Sequence[Sequence[float]], thickness: float = DEFAULT_WALL_THICKNESS
) -> list[FloatArray]:
    """Walls along a polyline: one :func:`thick_segment` per consecutive pair of points."""
    pts = np.asarray(points, dtype=np.float64)
    return [thick_segment(pts[i], pts[i + 1], thickness) for i in range(len(pts) - 1)]


def polygon_edges(polygons: FloatArray) -> FloatArray:
    """Edges (K*4, 4) ``(x0, y0, x1, y1)`` of quads (K, 4, 2)."""
    polygons = np.asarray(polygons, dtype=np.float64)
    start = polygons.reshape(-1, 2)
    end = np.roll(polygons, -1, axis=1).reshape(-1, 2)
    return np.concatenate([start, end], axis=1)


def _ccw_convex(quads: FloatArray) -> FloatArray:
    """Quads (K, 4, 2) in counter-clockwise order; raises if any is degenerate or not convex."""
    x, y = quads[..., 0], quads[..., 1]
    area2 = np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)
    quads = np.where((area2 < 0)[:, None, None], quads[:, ::-1], quads)
    edges = np.roll(quads, -1, axis=1) - quads
    following = np.roll(edges, -1, axis=1)
    cross = edges[..., 0] * following[..., 1] - edges[..., 1] * following[..., 0]
    short_edge = np.any(np.hypot(edges[..., 0], edges[..., 1]) < 1e-9, axis=1)
    bad = (np.abs(area2) < 1e-12) | np.any(cross < -1e-12, axis=1) | short_edge
    if bad.any():
        index = int(np.argmax(bad))
        raise ValueError(
            f"wall polygon {index} is degenerate or not convex: {quads[index].tolist()}"
        )
    return quads


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class WorldSpec:
    """A static 2-D world.

    Attributes
    ----------
    name : str
        Short identifier (``"office"``, ``"map:plant.yaml"``...).
    walls : ndarray, shape (K, 4, 2), float64
        Convex wall quads, counter-clockwise, metres.
    starts : ndarray, shape (S, 3), float64
        Default start poses ``(x, y, theta)`` in the world frame; robot i starts at
        ``starts[i]`` (robots beyond S get automatic starts in free space).
    segments : ndarray, shape (M, 4), float64, optional
        What the lidar sees: boundary segments ``(x0, y0, x1, y1)`` of the union of the
        walls. Defaults to all quad edges (interior edges are never the first hit of a ray
        from free space). Worlds built from grids pass a traced outline instead.
    bounds : tuple of float, optional
        ``(xmin, ymin, xmax, ymax)``; defaults to the walls' bounding box.
    description : str
        One line for ``mrslam scenarios``.
    """

    name: str
    walls: FloatArray
    starts: FloatArray
    segments: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    bounds: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    description: str = ""

    def __post_init__(self) -> None:
        owner = "WorldSpec"
        walls = np.asarray(self.walls, dtype=np.float64)
        ok = walls.ndim == 3 and walls.shape[1:] == (4, 2) and len(walls) > 0
        require(owner, "walls", walls.shape, ok, "an array of shape (K>0, 4, 2)")
        finite = np.isfinite(walls).all(axis=(1, 2))
        if not finite.all():
            bad = walls[int(np.argmin(finite))].tolist()
            require(owner, "walls", bad, False, "free of non-finite coordinates")
        walls = _ccw_convex(walls)
        starts = np.asarray(self.starts, dtype=np.float64).reshape(-1, 3)
        ok = len(starts) > 0 and bool(np.all(np.isfinite(starts)))
        require(owner, "starts", starts.tolist(), ok, "one or more finite (x, y, theta) poses")
        segments = np.asarray(self.segments, dtype=np.float64).reshape(-1, 4)
        if len(segments) == 0:
            segments = polygon_edges(walls)
        bounds = tuple(float(b) for b in self.bounds)
        if bounds == (0.0, 0.0, 0.0, 0.0):
            lo, hi = walls.reshape(-1, 2).min(axis=0), walls.reshape(-1, 2).max(axis=0)
            bounds = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        ok = bounds[2] > bounds[0] and bounds[3] > bounds[1]
        require(owner, "bounds", bounds, ok, "a non-empty (xmin, ymin, xmax, ymax)")
        for name, value in (("walls", walls), ("starts", starts), ("segments", segments)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "bounds", bounds)

    @staticmethod
    def from_walls(
        name: str,
        walls: Iterable[ArrayLike],
        starts: ArrayLike,
        description: str = "",
    ) -> WorldSpec:
        """Build from an iterable of quads (4, 2)."""
        return WorldSpec(
            name=name,
            walls=np.stack([np.asarray(w, dtype=np.float64) for w in walls]),
            starts=np.asarray(starts, dtype=np.float64),
            description=description,
        )

    def clearance(self, points: ArrayLike) -> FloatArray:
        """Distance (m) from each point (N, 2) to the nearest wall; negative inside a wall."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        seg = self.segments
        a, b = seg[None, :, :2], seg[None, :, 2:]
        ab = b - a
        t = np.einsum("nmk,nmk->nm", p[:, None, :] - a, ab) / np.maximum(
            np.einsum("nmk,nmk->nm", ab, ab), 1e-18
        )
        closest = a + np.clip(t, 0.0, 1.0)[..., None] * ab
        distance = np.linalg.norm(p[:, None, :] - closest, axis=-1).min(axis=1)
        return np.where(self.inside_walls(p), -distance, distance)

    def inside_walls(self, points: ArrayLike) -> NDArray[np.bool_]:
        """Whether each point (N, 2) lies strictly inside any wall quad."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        w = self.walls
        edge = np.roll(w, -1, axis=1) - w  # (K, 4, 2)
        rel = p[:, None, None, :] - w[None]  # (N, K, 4, 2)
        cross = edge[None, ..., 0] * rel[..., 1] - edge[None, ..., 1] * rel[..., 0]
        return np.any(np.all(cross > 0.0, axis=2), axis=1)


def ground_truth_map(
    world: WorldSpec,
    resolution: float,
    margin: float = 0.0,
    anchor: tuple[float, float] = (0.0, 0.0),
) -> GridMap:
    """Rasterise the world: a cell is OCCUPIED when its square overlaps any wall, else FREE.

    Parameters
    ----------
    world : WorldSpec
    resolution : float
        Cell size in metres.
    margin : float
        Extra border (m) around ``world.bounds``.
    anchor : tuple of float
        A point of the cell-corner lattice (m): the grid's origin is ``anchor`` plus whole
        cells. Pass a map's origin to rasterise a world built from that map cell for cell.

    Returns
    -------
    GridMap
        Covering the bounds plus the margin.
    """
    if not (resolution > 0 and np.isfinite(resolution)):
        raise ValueError(f"resolution must be > 0 m, got {resolution}")
    xmin, ymin, xmax, ymax = world.bounds
    ax, ay = float(anchor[0]), float(anchor[1])
    x0 = ax + np.floor((xmin - margin - ax) / resolution + 1e-9) * resolution
    y0 = ay + np.floor((ymin - margin - ay) / resolution + 1e-9) * resolution
    cols = int(np.ceil((xmax + margin - x0) / resolution - 1e-9))
    rows = int(np.ceil((ymax + margin - y0) / resolution - 1e-9))
    occupied = np.zeros((rows, cols), dtype=bool)
    # A shared edge or corner is not an overlap: shrink the cells a hair.
    eps = 1e-9
    half = resolution / 2.0 - eps
    for quad in world.walls:
        lo, hi = quad.min(axis=0), quad.max(axis=0)
        c0 = max(int(np.floor((lo[0] - x0) / resolution)), 0)
        c1 = min(int(np.ceil((hi[0] - x0) / resolution)), cols)
        r0 = max(int(np.floor((lo[1] - y0) / resolution)), 0)
        r1 = min(int(np.ceil((hi[1] - y0) / resolution)), rows)
        if c0 >= c1 or r0 >= r1:
            continue
        edges = np.roll(quad, -1, axis=0) - quad
        axis_aligned = np.all(np.abs(edges).min(axis=1) < 1e-12)
        cx = x0 + (np.arange(c0, c1) + 0.5) * resolution
        cy = y0 + (np.arange(r0, r1) + 0.5) * resolution
        overlap = (
            (cx[None, :] + half > lo[0])
            & (cx[None, :] - half < hi[0])
            & (cy[:, None] + half > lo[1])
            & (cy[:, None] - half < hi[1])
        )
        if not axis_aligned:
            # Separating-axis test on the quad's edge normals (the cell's own axes are the
            # bounding-box test above).
            for k in range(4):
                normal = np.array([-edges[k, 1], edges[k, 0]])
                proj = quad @ normal
                centre = cx[None, :] * normal[0] + cy[:, None] * normal[1]
                radius = half * (abs(normal[0]) + abs(normal[1]))
                overlap &= (centre + radius > proj.min()) & (centre - radius < proj.max())
        occupied[r0:r1, c0:c1] |= overlap
    cells = np.where(occupied, OCCUPIED, FREE).astype(np.int8)
    return GridMap(cells=cells, resolution=resolution, origin=(float(x0), float(y0)))
