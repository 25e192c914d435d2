"""Rotations from Hough spectra (Carpin, "Fast and accurate map merging for multi-robot
systems", Autonomous Robots 25, 2008): a proposal source of the merge besides the wall
orientations.

The Hough transform of a map's occupied cells over ``angles`` directions in [0, pi) counts,
for each direction ``theta``, the points in each ``rho`` bin (``x cos(theta) + y
sin(theta)``, one cell wide); the **Hough spectrum** ``S(theta) = sum_rho H(rho, theta)²``
has tall, narrow peaks at the walls' normals, and the spectrum of a rotated map is the
spectrum circularly shifted by the rotation (mod pi). The highest local maxima of the
circular cross-correlation of the two maps' spectra are the candidate rotations, each as
``theta`` and ``theta + pi`` (the spectrum cannot tell them apart).

Unlike the wall-orientation histogram (:func:`~mrslam_env.merge.hypotheses.
wall_orientation_histogram`), which weighs every wall cell by its gradient, the spectrum
weighs long straight walls by the square of their length: a few long, collinear walls
(shelf rows, a corridor) decide it even in clutter. Used by
:func:`~mrslam_env.merge.pipeline.merge_maps` (``MergeConfig.hough_candidates``) and by
the benchmark's Hough-spectrum baseline (``scenarios/bench/merge/hough.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from mrslam_env.geometry import wrap_angle
from mrslam_env.gridmap import GridMap

__all__ = ["hough_rotations", "hough_spectrum", "occupied_points", "spectrum_rotations"]

FloatArray = NDArray[np.float64]


def occupied_points(grid: GridMap, resolution: float) -> FloatArray:
    """Centres (x, y) of the occupied cells, thinned to one point per ``resolution`` cell
    when that is coarser than the grid."""
    points = grid.cell_to_world(np.argwhere(grid.occupied)).reshape(-1, 2)
    if resolution <= grid.resolution or len(points) == 0:
        return points
    keys = np.unique(np.floor(points / resolution).astype(np.int64), axis=0)
    return np.asarray((keys + 0.5) * resolution, dtype=np.float64)


def hough_spectrum(points: FloatArray, angles: int, rho_step: float) -> FloatArray:
    """Carpin's Hough spectrum ``S(theta_k) = sum_rho H(rho, theta_k)²`` for
    ``theta_k = k pi / angles``, normalised to a maximum of 1 (zeros without points)."""
    spectrum = np.zeros(angles)
    if len(points) == 0:
        return spectrum
    centred = points - points.mean(axis=0)
    thetas = np.arange(angles) * math.pi / angles
    rho = centred @ np.vstack([np.cos(thetas), np.sin(thetas)])  # (points, angles)
    bins = np.floor(rho / rho_step).astype(np.int64)
    bins -= bins.min()
    width = int(bins.max()) + 1
    flat = bins + width * np.arange(angles)[None, :]
    counts = np.bincount(flat.ravel(), minlength=width * angles).reshape(angles, width)
    spectrum = (counts.astype(np.float64) ** 2).sum(axis=1)
    peak = spectrum.max()
    return spectrum / peak if peak > 0 else spectrum


def spectrum_rotations(s1: FloatArray, s2: FloatArray, count: int) -> list[float]:
    """Shifts ``theta`` (rad, in [0, pi)) with ``S1(phi) ~ S2(phi + theta)``: the
    ``count`` highest local maxima of the circular cross-correlation, best first."""
    n = len(s1)
    correlation = np.real(np.fft.ifft(np.conj(np.fft.fft(s1)) * np.fft.fft(s2)))
    peaks = [
        k
        for k in range(n)
        if correlation[k] >= correlation[k - 1] and correlation[k] >= correlation[(k + 1) % n]
    ]
    peaks.sort(key=lambda k: -correlation[k])
    return [k * math.pi / n for k in peaks[:count]]


def hough_rotations(
    m1: GridMap, m2: GridMap, *, peaks: int, angles: int = 360, resolution: float = 0.1
) -> list[float]:
    """Rotations of ``map1_from_map2`` (rad, wrapped) the two maps' Hough spectra allow:
    for each of the ``peaks`` best spectrum shifts ``theta``
    (:func:`spectrum_rotations`), ``-theta`` and ``pi - theta``, best peak first. Empty
    when a map has no occupied cell.

    Parameters
    ----------
    m1, m2 : GridMap
        The maps (any resolutions).
    peaks : int
        Spectrum cross-correlation peaks used.
    angles : int
        Hough directions over [0, pi) (360: 0.5° apart).
    resolution : float
        The points are thinned to one per cell of this size (m), and ``rho`` bins are
        this wide, or the coarser map's cell when that is coarser.
    """
    step = max(resolution, m1.resolution, m2.resolution)
    points1, points2 = occupied_points(m1, step), occupied_points(m2, step)
    if len(points1) == 0 or len(points2) == 0:
        return []
    s1 = hough_spectrum(points1, angles, step)
    s2 = hough_spectrum(points2, angles, step)
    # Map 2's spectrum is map 1's shifted by theta: map 2 turned by -theta lines up.
    return [
        float(wrap_angle(-theta + half))
        for theta in spectrum_rotations(s1, s2, peaks)
        for half in (0.0, math.pi)
    ]
