"""The Hough-spectrum map merger (Carpin, "Fast and accurate map merging for multi-robot
systems", Autonomous Robots 25, 2008), our re-implementation, a baseline of the merge
benchmark (method ``hough``).

1. Both maps' occupied cells (map 2 resampled to map 1's resolution, both coarsened to
   :attr:`HoughConfig.resolution` when finer) are points.
2. The Hough transform of each point set over ``angles`` directions in [0, pi): the
   accumulator ``H(rho, theta)`` counts the points with ``x cos(theta) + y sin(theta)`` in
   each ``rho`` bin (one cell wide). The **Hough spectrum** is ``S(theta) = sum_rho H²``:
   walls make tall, narrow peaks, and the spectrum of a rotated map is the spectrum
   circularly shifted by the rotation (mod pi).
3. The circular cross-correlation of the two spectra peaks at the candidate rotations;
   the ``rotation_candidates`` highest local maxima are kept, each as theta and theta + pi
   (the spectrum cannot tell them apart).
4. For each rotation, map 2's rotated occupied points and map 1's are rasterised, blurred by
   one cell, and cross-correlated by FFT: the highest peak is the translation.
5. The (rotation, translation) with the highest correlation wins, optionally polished by
   the random walk (:func:`~mrslam_env.merge.refine.refine_random_walk`).

Steps 1-3 are :mod:`mrslam_env.merge.spectrum`, which the merge pipeline also uses as a
proposal source. It answers every pair (no acceptance test), which is its known
weakness: a pair without overlap still gets a transform.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import gaussian_filter
from scipy.signal import fftconvolve

from mrslam_env.gridmap import GridMap
from mrslam_env.merge.spectrum import hough_spectrum, occupied_points, spectrum_rotations
from mrslam_env.validation import check_fields

FloatArray = NDArray[np.float64]

__all__ = ["HoughConfig", "HoughResult", "estimate_transform_hough", "hough_spectrum"]


@dataclass(frozen=True, slots=True, kw_only=True)
class HoughConfig:
    """Settings of :func:`estimate_transform_hough`."""

    resolution: float = 0.1
    """Working cell size, m: finer maps are coarsened to it (occupied wins)."""
    angles: int = 360
    """Hough directions over [0, pi) (0.5° apart by default)."""
    rotation_candidates: int = 4
    """Spectrum cross-correlation peaks tried, each as theta and theta + pi."""
    blur_cells: float = 1.0
    """Gaussian blur (cells) of the rasters before the translation correlation."""
    polish: bool = True
    """Polish the winner with the random walk."""

    def __post_init__(self) -> None:
        check_fields(
            self,
            positive=("resolution",),
            counts=("angles", "rotation_candidates"),
            non_negative=("blur_cells",),
        )


@dataclass(frozen=True, slots=True)
class HoughResult:
    """``transform`` (map1_from_map2) or None when a map has no occupied cell, and the
    winning correlation peak ``score`` (blurred coincident occupied cells)."""

    transform: FloatArray | None
    score: float


def _raster(
    points: FloatArray, lower: FloatArray, shape: tuple[int, int], step: float
) -> FloatArray:
    image = np.zeros(shape)
    cells = np.floor((points - lower) / step).astype(np.int64)
    image[cells[:, 1], cells[:, 0]] = 1.0
    return image


def _translation(
    points1: FloatArray, rotated2: FloatArray, step: float, blur: float
) -> tuple[FloatArray, float]:
    """The translation t maximising the correlation of points1 and rotated2 + t, and the
    peak value."""
    lower1, lower2 = points1.min(axis=0) - step, rotated2.min(axis=0) - step
    shape1 = tuple(int(v) + 2 for v in np.ceil((points1.max(axis=0) - lower1) / step)[::-1])
    shape2 = tuple(int(v) + 2 for v in np.ceil((rotated2.max(axis=0) - lower2) / step)[::-1])
    a = _raster(points1, lower1, (shape1[0], shape1[1]), step)
    b = _raster(rotated2, lower2, (shape2[0], shape2[1]), step)
    if blur > 0:
        a, b = gaussian_filter(a, blur), gaussian_filter(b, blur)
    correlation = fftconvolve(a, b[::-1, ::-1], mode="full")
    row, col = np.unravel_index(int(np.argmax(correlation)), correlation.shape)
    shift = np.array([col - (b.shape[1] - 1), row - (b.shape[0] - 1)], dtype=np.float64)
    return shift * step + lower1 - lower2, float(correlation[row, col])


def estimate_transform_hough(
    m1: GridMap,
    m2: GridMap,
    config: HoughConfig | None = None,
    *,
    rng: np.random.Generator | None = None,
) -> HoughResult:
    """``map1_from_map2`` by the Hough spectrum (module docstring); None only when a map
    has no occupied cell."""
    config = config if config is not None else HoughConfig()
    step = max(config.resolution, m1.resolution, m2.resolution)
    points1 = occupied_points(m1, step)
    points2 = occupied_points(m2, step)
    if len(points1) == 0 or len(points2) == 0:
        return HoughResult(None, 0.0)
    s1 = hough_spectrum(points1, config.angles, step)
    s2 = hough_spectrum(points2, config.angles, step)
    best: tuple[float, FloatArray] = (-math.inf, np.zeros(3))
    for base in spectrum_rotations(s1, s2, config.rotation_candidates):
        for theta in (base, base + math.pi):
            # the spectrum of map 2 is map 1's shifted by -theta: rotate map 2 back by it
            rotation = -theta
            c, s = math.cos(rotation), math.sin(rotation)
            rotated = points2 @ np.array([[c, s], [-s, c]])
            translation, score = _translation(points1, rotated, step, config.blur_cells)
            if score > best[0]:
                wrapped = math.atan2(math.sin(rotation), math.cos(rotation))
                best = (score, np.array([translation[0], translation[1], wrapped]))
    score, transform = best
    if config.polish:
        from mrslam_env.merge.refine import refine_random_walk

        polished = refine_random_walk(
            m1, m2, transform, rng=rng if rng is not None else np.random.default_rng(0)
        )
        if math.isfinite(polished.psi):
            transform = np.asarray(polished.transform, dtype=np.float64)
    return HoughResult(transform, score)
