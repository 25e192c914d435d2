"""An SE(2) pose graph and its sparse least-squares optimiser (docs/design.md §4).

Nodes are poses ``(x, y, theta)`` named by integer ids (any ints, in any order: a team
graph can give each robot its own range of ids, e.g. ``robot * 1_000_000 + keyframe``).
An edge ``i -> j`` says "node j seen from node i is ``z``" (``inverse(x_i) ∘ x_j = z``)
with a 3 x 3 information matrix ``Omega`` (the inverse covariance of ``z``, in the frame
of ``i``, order x, y, theta). Its error, as in g2o's SE2 edge, is

``e = (R(theta_i + theta_z)^T (t_j - t_i) - R(theta_z)^T t_z,  wrap(theta_j - theta_i - theta_z))``

and the graph's cost ``sum_odometry e^T Omega e + sum_loop rho(e^T Omega e)``: the loop
edges (``kind="loop"``) go through a robust kernel ``rho``, so that one false loop closure
cannot bend the whole graph.

:meth:`PoseGraph.optimize` minimises that cost by Gauss–Newton with the normal equations
assembled as a sparse matrix (3 x 3 blocks per edge) and solved by a sparse LU
(:func:`scipy.sparse.linalg.spsolve`), with Levenberg damping whenever a step would raise
the cost. It runs in two phases: plain least squares first (every loop edge at full
weight), then iteratively reweighted least squares (IRLS) with the kernel's weights taken
at the current residuals. Starting the robust phase from the least-squares solution keeps
a *true* loop whose error is large against its own information (the drift it corrects) at
full weight: once the graph has taken it in, its residual is small. A false one stays far
from what the rest of the graph says and loses its weight. The fixed nodes (at least one
per connected component; :class:`PoseGraph` fixes none by itself) do not move.

Kernels (``robust``):

* ``"switchable"``: the closed form of switchable constraints (Sünderhauf & Protzel 2012,
  as in Agarwal et al.'s dynamic covariance scaling 2013): minimising ``s^2 chi^2 +
  Phi (1 - s)^2`` over the switch ``s`` gives ``s = Phi / (Phi + chi^2)`` and the cost
  ``rho = Phi chi^2 / (Phi + chi^2)`` (Geman–McClure), weight ``s^2``. A gross outlier's
  pull falls to zero.
* ``"huber"``: ``rho = chi^2`` up to ``chi = k``, then ``2 k chi - k^2`` (weight ``k /
  chi``): an outlier's pull is bounded but never zero.
* ``"none"``: least squares.

Everything here is deterministic for a given graph (the order edges were added in fixes
the order of every sum).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, NamedTuple, get_args

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.sparse.linalg import spsolve

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

__all__ = [
    "EDGE_KINDS",
    "ROBUST_KERNELS",
    "Edge",
    "EdgeKind",
    "OptimizationResult",
    "PoseGraph",
    "RobustKernel",
    "edge_errors",
    "robust_weights",
]

EdgeKind = Literal["odometry", "loop"]
EDGE_KINDS: tuple[str, ...] = get_args(EdgeKind)
RobustKernel = Literal["switchable", "huber", "none"]
ROBUST_KERNELS: tuple[str, ...] = get_args(RobustKernel)

_DAMPING_START = 1e-4
"""Levenberg damping (times the mean of the Hessian's diagonal) after the first rejected
step; it grows tenfold per rejected step and shrinks tenfold per accepted one."""
_DAMPING_TRIES = 8
"""Rejected steps in a row before an optimisation phase gives up."""


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class Edge:
    """One constraint: node ``j`` seen from node ``i`` is ``measurement``.

    Attributes
    ----------
    i, j : int
        Node ids.
    measurement : ndarray, shape (3,)
        ``inverse(x_i) ∘ x_j``, m, m, rad.
    information : ndarray, shape (3, 3)
        Inverse covariance of ``measurement`` (in node i's frame).
    kind : str
        ``"odometry"`` (consecutive keyframes, least squares) or ``"loop"`` (robust).
    """

    i: int
    j: int
    measurement: FloatArray
    information: FloatArray
    kind: EdgeKind


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class OptimizationResult:
    """What one :meth:`PoseGraph.optimize` did.

    Attributes
    ----------
    iterations : int
        Gauss–Newton steps taken (accepted or not), both phases.
    initial_cost, final_cost : float
        The robust cost (module docstring) before and after.
    max_translation, max_rotation : float
        The largest change of a node's position (m) and heading (rad).
    loop_weights : ndarray, shape (L,)
        The kernel's weight of each loop edge at the end (in the order they were added; 1:
        fully in, near 0: switched off).
    converged : bool
        Whether the last step was below the tolerance (else the iterations or the damping
        ran out).
    """

    iterations: int
    initial_cost: float
    final_cost: float
    max_translation: float
    max_rotation: float
    loop_weights: FloatArray
    converged: bool


class _Edges(NamedTuple):
    """A graph's edges as arrays: node rows (E,), measurements (E, 3), information (E, 3,
    3), loop flags (E,)."""

    i: IntArray
    j: IntArray
    z: FloatArray
    omega: FloatArray
    loop: NDArray[np.bool_]


def _chi2(poses: FloatArray, edges: _Edges) -> FloatArray:
    """``e^T Omega e`` (E,) of every edge at ``poses``."""
    e = edge_errors(poses, edges.i, edges.j, edges.z)
    return np.asarray(np.einsum("ka,kab,kb->k", e, edges.omega, e), dtype=np.float64)


def _cost(poses: FloatArray, edges: _Edges, kernel: RobustKernel, width: float) -> float:
    """The graph's cost at ``poses``: chi^2 of the odometry edges, ``rho(chi^2)`` of the
    loop edges."""
    if len(edges.z) == 0:
        return 0.0
    chi2 = _chi2(poses, edges)
    return float(np.where(edges.loop, _robust_cost(chi2, kernel, width), chi2).sum())


def _wrap(angle: FloatArray) -> FloatArray:
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


def edge_errors(
    poses: FloatArray, i: IntArray, j: IntArray, measurements: FloatArray
) -> FloatArray:
    """The errors (E, 3) of edges ``i[k] -> j[k]`` (row indices into ``poses`` (N, 3))
    with measurements (E, 3); see the module docstring."""
    pi, pj = poses[i], poses[j]
    dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
    angle = pi[:, 2] + measurements[:, 2]
    c, s = np.cos(angle), np.sin(angle)
    cz, sz = np.cos(measurements[:, 2]), np.sin(measurements[:, 2])
    mx, my = measurements[:, 0], measurements[:, 1]
    return np.column_stack(
        [
            c * dx + s * dy - (cz * mx + sz * my),
            -s * dx + c * dy - (-sz * mx + cz * my),
            _wrap(pj[:, 2] - pi[:, 2] - measurements[:, 2]),
        ]
    )


def robust_weights(chi2: FloatArray, kernel: RobustKernel, width: float) -> FloatArray:
    """IRLS weights ``d rho / d chi^2`` of squared Mahalanobis errors ``chi2`` under a
    kernel of ``width`` (``Phi`` for ``"switchable"``, ``k^2`` for ``"huber"``, both in
    units of chi^2)."""
    if kernel == "switchable":
        return np.asarray((width / (width + chi2)) ** 2, dtype=np.float64)
    if kernel == "huber":
        k = math.sqrt(width)
        chi = np.sqrt(chi2)
        return np.where(chi <= k, 1.0, k / np.maximum(chi, k))
    return np.ones_like(chi2)


def _robust_cost(chi2: FloatArray, kernel: RobustKernel, width: float) -> FloatArray:
    if kernel == "switchable":
        return np.asarray(width * chi2 / (width + chi2), dtype=np.float64)
    if kernel == "huber":
        k = math.sqrt(width)
        chi = np.sqrt(chi2)
        return np.where(chi <= k, chi2, 2.0 * k * chi - width)
    return chi2


class PoseGraph:
    """An SE(2) pose graph: nodes by id, edges with information matrices (module
    docstring).

    Examples
    --------
    >>> graph = PoseGraph()
    >>> graph.add_node(0, [0.0, 0.0, 0.0], fixed=True)
    >>> graph.add_node(1, [1.1, 0.0, 0.0])
    >>> graph.add_edge(0, 1, [1.0, 0.0, 0.0], np.eye(3))
    0
    >>> result = graph.optimize()
    >>> bool(np.allclose(graph.pose(1), [1.0, 0.0, 0.0]))
    True
    """

    def __init__(self) -> None:
        self._index: dict[int, int] = {}
        self._ids: list[int] = []
        self._poses = np.zeros((64, 3))
        self._fixed: list[bool] = []
        self._edges: list[Edge] = []
        # Edge arrays, rebuilt lazily after edges were added.
        self._arrays: _Edges
        self._arrays_for = -1

    # --- nodes --------------------------------------------------------------------------

    def __len__(self) -> int:
        return len(self._ids)

    def __contains__(self, node_id: object) -> bool:
        return node_id in self._index

    @property
    def node_ids(self) -> tuple[int, ...]:
        """The node ids in the order they were added."""
        return tuple(self._ids)

    @property
    def poses(self) -> FloatArray:
        """The node poses (N, 3), in the order of :attr:`node_ids` (a copy)."""
        return self._poses[: len(self._ids)].copy()

    @property
    def edges(self) -> tuple[Edge, ...]:
        """The edges in the order they were added."""
        return tuple(self._edges)

    def index(self, node_id: int) -> int:
        """The row of ``node_id`` in :attr:`poses`."""
        return self._index[node_id]

    def pose(self, node_id: int) -> FloatArray:
        """The pose (3,) of a node (a copy)."""
        return self._poses[self._index[node_id]].copy()

    def is_fixed(self, node_id: int) -> bool:
        return self._fixed[self._index[node_id]]

    def add_node(self, node_id: int, pose: ArrayLike, *, fixed: bool = False) -> None:
        """Add a node at ``pose`` (its initial estimate); ``fixed`` nodes never move."""
        if not isinstance(node_id, int) or isinstance(node_id, bool):
            raise ValueError(f"node ids must be ints, got {node_id!r}")
        if node_id in self._index:
            raise ValueError(f"node {node_id} already exists")
        value = np.asarray(pose, dtype=np.float64)
        if value.shape != (3,) or not np.all(np.isfinite(value)):
            raise ValueError(f"pose must be a finite (x, y, theta), got {pose!r}")
        n = len(self._ids)
        if n == len(self._poses):
            self._poses = np.concatenate([self._poses, np.zeros_like(self._poses)])
        self._poses[n] = value
        self._poses[n, 2] = _wrap(value[2:3])[0]
        self._index[node_id] = n
        self._ids.append(node_id)
        self._fixed.append(bool(fixed))

    def set_poses(self, poses: ArrayLike) -> None:
        """Replace every node's pose (N, 3), in the order of :attr:`node_ids`."""
        value = np.asarray(poses, dtype=np.float64)
        if value.shape != (len(self._ids), 3) or not np.all(np.isfinite(value)):
            raise ValueError(f"poses must be finite, shape ({len(self._ids)}, 3)")
        self._poses[: len(self._ids)] = value
        self._poses[: len(self._ids), 2] = _wrap(value[:, 2])

    # --- edges --------------------------------------------------------------------------

    def add_edge(
        self,
        i: int,
        j: int,
        measurement: ArrayLike,
        information: ArrayLike,
        kind: EdgeKind = "odometry",
    ) -> int:
        """Add the constraint "node ``j`` seen from node ``i`` is ``measurement``" with an
        information matrix (3, 3, symmetric positive semi-definite); returns its index in
        :attr:`edges`."""
        self._edges.append(self._edge(i, j, measurement, information, kind))
        return len(self._edges) - 1

    def _edge(
        self, i: int, j: int, measurement: ArrayLike, information: ArrayLike, kind: EdgeKind
    ) -> Edge:
        """A validated edge (the checks of :meth:`add_edge`)."""
        if i not in self._index or j not in self._index or i == j:
            raise ValueError(f"an edge needs two distinct existing nodes, got {i} -> {j}")
        if kind not in EDGE_KINDS:
            raise ValueError(f"kind must be one of {EDGE_KINDS}, got {kind!r}")
        z = np.asarray(measurement, dtype=np.float64).copy()
        omega = np.asarray(information, dtype=np.float64).copy()
        if z.shape != (3,) or not np.all(np.isfinite(z)):
            raise ValueError(f"measurement must be a finite (x, y, theta), got {measurement!r}")
        if omega.shape != (3, 3) or not np.all(np.isfinite(omega)):
            raise ValueError("information must be a finite 3 x 3 matrix")
        omega = 0.5 * (omega + omega.T)
        if np.linalg.eigvalsh(omega)[0] < -1e-9 * max(1.0, float(np.abs(omega).max())):
            raise ValueError("information must be positive semi-definite")
        z[2] = _wrap(z[2:3])[0]
        z.flags.writeable = False
        omega.flags.writeable = False
        return Edge(i=i, j=j, measurement=z, information=omega, kind=kind)

    def replace_edge(self, index: int, measurement: ArrayLike, information: ArrayLike) -> None:
        """Give edge ``index`` another measurement and information matrix (same nodes and
        kind), e.g. once a better measurement of it is known."""
        edge = self._edges[index]
        self._edges[index] = self._edge(edge.i, edge.j, measurement, information, edge.kind)
        self._arrays_for = -1

    def _edge_arrays(self) -> _Edges:
        if self._arrays_for != len(self._edges):
            edges = self._edges
            self._arrays = _Edges(
                np.array([self._index[e.i] for e in edges], dtype=np.int64),
                np.array([self._index[e.j] for e in edges], dtype=np.int64),
                np.array([e.measurement for e in edges]).reshape(-1, 3),
                np.array([e.information for e in edges]).reshape(-1, 3, 3),
                np.array([e.kind == "loop" for e in edges], dtype=np.bool_),
            )
            self._arrays_for = len(edges)
        return self._arrays

    def errors(self) -> FloatArray:
        """The current error (E, 3) of every edge."""
        edges = self._edge_arrays()
        return edge_errors(self._poses[: len(self._ids)], edges.i, edges.j, edges.z)

    def chi2(self) -> FloatArray:
        """The current squared Mahalanobis error ``e^T Omega e`` (E,) of every edge."""
        return _chi2(self._poses[: len(self._ids)], self._edge_arrays())

    # --- optimisation -------------------------------------------------------------------

    def optimize(
        self,
        *,
        robust: RobustKernel = "switchable",
        robust_width: float = 9.0,
        max_iterations: int = 30,
        tolerance: float = 1e-7,
    ) -> OptimizationResult:
        """Minimise the graph's cost (module docstring); the poses are updated in place.

        Parameters
        ----------
        robust : {"switchable", "huber", "none"}
            The loop edges' kernel.
        robust_width : float
            The kernel's width in units of chi^2 (``Phi``, or ``k^2`` for Huber): a loop
            edge with ``chi^2`` below it keeps most of its weight.
        max_iterations : int
            Gauss–Newton steps per phase.
        tolerance : float
            A phase ends once no node moves more than this (m and rad) in a step.

        Returns
        -------
        OptimizationResult
        """
        if robust not in ROBUST_KERNELS:
            raise ValueError(f"robust must be one of {ROBUST_KERNELS}, got {robust!r}")
        if not (math.isfinite(robust_width) and robust_width > 0):
            raise ValueError(f"robust_width must be > 0, got {robust_width!r}")
        n = len(self._ids)
        before = self._poses[:n].copy()
        edges = self._edge_arrays()
        # The variables: 3 per free node, in node order.
        fixed = np.array(self._fixed, dtype=np.bool_)
        if n > 0 and not fixed.any():
            raise ValueError("a pose graph needs a fixed node to optimise")
        slot = np.full(n, -1, dtype=np.int64)
        slot[~fixed] = np.arange(int((~fixed).sum()))
        iterations = 0
        converged = True
        initial_cost = _cost(before, edges, robust, robust_width)
        if len(edges.z) > 0 and slot.max(initial=-1) >= 0:
            phases: list[RobustKernel] = ["none"]
            if robust != "none" and edges.loop.any():
                phases.append(robust)
            for kernel in phases:
                steps, converged = self._gauss_newton(
                    edges, slot, kernel, robust_width, max_iterations, tolerance
                )
                iterations += steps
        poses = self._poses[:n]
        final_cost = _cost(poses, edges, robust, robust_width)
        chi2 = _chi2(poses, edges)
        change = poses - before
        return OptimizationResult(
            iterations=iterations,
            initial_cost=initial_cost,
            final_cost=final_cost,
            max_translation=float(np.hypot(change[:, 0], change[:, 1]).max(initial=0.0)),
            max_rotation=float(np.abs(_wrap(change[:, 2])).max(initial=0.0)),
            loop_weights=robust_weights(chi2[edges.loop], robust, robust_width),
            converged=converged,
        )

    def _gauss_newton(
        self,
        edges: _Edges,
        slot: IntArray,
        kernel: RobustKernel,
        width: float,
        max_iterations: int,
        tolerance: float,
    ) -> tuple[int, bool]:
        """Gauss–Newton with Levenberg damping on a rejected step; IRLS weights of the loop
        edges from the residuals at the start of each step. Returns (steps, converged)."""
        n = len(self._ids)
        n_vars = 3 * int(slot.max()) + 3
        poses = self._poses[:n]
        cost = _cost(poses, edges, kernel, width)
        damping = 0.0
        rejected = 0
        steps = 0
        while steps < max_iterations:
            hessian, gradient = _normal_equations(poses, edges, slot, n_vars, kernel, width)
            diagonal = hessian.diagonal()
            while True:
                steps += 1
                system = hessian
                if damping > 0.0:
                    system = hessian + sparse.diags(damping * np.maximum(diagonal, 1e-12))
                step = np.asarray(spsolve(system.tocsc(), -gradient), dtype=np.float64)
                trial = poses.copy()
                free = slot >= 0
                if np.all(np.isfinite(step)):
                    trial[free] += step.reshape(-1, 3)[slot[free]]
                    trial[:, 2] = _wrap(trial[:, 2])
                    new_cost = _cost(trial, edges, kernel, width)
                else:
                    new_cost = math.inf
                if new_cost <= cost * (1.0 + 1e-12) + 1e-15:
                    break
                rejected += 1
                if rejected >= _DAMPING_TRIES or steps >= max_iterations:
                    return steps, False
                damping = _DAMPING_START if damping == 0.0 else 10.0 * damping
            rejected = 0
            damping = 0.0 if damping <= _DAMPING_START else 0.1 * damping
            poses[:] = trial
            largest = float(np.abs(step).max(initial=0.0))
            decrease = cost - new_cost
            cost = new_cost
            if largest < tolerance or decrease <= 1e-12 * max(cost, 1e-300):
                return steps, True
        return steps, False


@numba.njit(cache=True)
def _assemble(
    poses: FloatArray,
    i: IntArray,
    j: IntArray,
    z: FloatArray,
    omega: FloatArray,
    weights: FloatArray,
    slot: IntArray,
    rows: IntArray,
    cols: IntArray,
    data: FloatArray,
    gradient: FloatArray,
) -> int:
    """Fill the COO triplets of ``H = J^T W J`` (``rows``, ``cols``, ``data``, 36 per
    edge at most) and ``gradient = J^T W e``; returns the number of triplets. Edge ``k``
    has information ``weights[k] * omega[k]``; ``slot`` is each node's first variable
    (-1: fixed)."""
    count = 0
    a = np.zeros((3, 3))
    b = np.zeros((3, 3))
    w = np.zeros((3, 3))
    jw = np.zeros((3, 3))
    e = np.zeros(3)
    jacobians = (a, b)
    for k in range(z.shape[0]):
        ni, nj = i[k], j[k]
        dx = poses[nj, 0] - poses[ni, 0]
        dy = poses[nj, 1] - poses[ni, 1]
        angle = poses[ni, 2] + z[k, 2]
        c, s = math.cos(angle), math.sin(angle)
        cz, sz = math.cos(z[k, 2]), math.sin(z[k, 2])
        e[0] = c * dx + s * dy - (cz * z[k, 0] + sz * z[k, 1])
        e[1] = -s * dx + c * dy - (-sz * z[k, 0] + cz * z[k, 1])
        turn = poses[nj, 2] - poses[ni, 2] - z[k, 2]
        e[2] = math.pi - (math.pi - turn) % (2.0 * math.pi)
        b[0, 0], b[0, 1], b[1, 0], b[1, 1], b[2, 2] = c, s, -s, c, 1.0
        a[0, 0], a[0, 1], a[1, 0], a[1, 1], a[2, 2] = -c, -s, s, -c, -1.0
        a[0, 2] = -s * dx + c * dy
        a[1, 2] = -c * dx - s * dy
        for r in range(3):
            for q in range(3):
                w[r, q] = weights[k] * omega[k, r, q]
        nodes = (ni, nj)
        for left in range(2):
            row_slot = slot[nodes[left]]
            if row_slot < 0:
                continue
            jl = jacobians[left]
            for r in range(3):  # jw = jl^T W
                for q in range(3):
                    value = 0.0
                    for t in range(3):
                        value += jl[t, r] * w[t, q]
                    jw[r, q] = value
            for r in range(3):
                gradient[row_slot + r] += jw[r, 0] * e[0] + jw[r, 1] * e[1] + jw[r, 2] * e[2]
            for right in range(2):
                col_slot = slot[nodes[right]]
                if col_slot < 0:
                    continue
                jr = jacobians[right]
                for r in range(3):
                    for q in range(3):
                        value = jw[r, 0] * jr[0, q] + jw[r, 1] * jr[1, q] + jw[r, 2] * jr[2, q]
                        rows[count] = row_slot + r
                        cols[count] = col_slot + q
                        data[count] = value
                        count += 1
    return count


def _normal_equations(
    poses: FloatArray,
    edges: _Edges,
    slot: IntArray,
    n_vars: int,
    kernel: RobustKernel,
    width: float,
) -> tuple[sparse.csc_matrix, FloatArray]:
    """``H = J^T W J`` (sparse, n_vars x n_vars) and ``b = J^T W e`` at ``poses``."""
    i, j, z, omega, loop = edges
    weights = np.ones(len(z))
    if kernel != "none" and loop.any():
        weights[loop] = robust_weights(_chi2(poses, edges)[loop], kernel, width)
    size = 36 * len(z)
    rows = np.empty(size, dtype=np.int64)
    cols = np.empty(size, dtype=np.int64)
    data = np.empty(size)
    gradient = np.zeros(n_vars)
    count = _assemble(poses, i, j, z, omega, weights, 3 * slot, rows, cols, data, gradient)
    hessian = sparse.coo_matrix(
        (data[:count], (rows[:count], cols[:count])), shape=(n_vars, n_vars)
    ).tocsc()
    return hessian, gradient
