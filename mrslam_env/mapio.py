"""Read and write ROS ``map_server`` map files (docs/design.md §2).

A map is a YAML file naming an image (relative to the YAML's folder) plus the image::

    image: lab.pgm
    mode: trinary            # optional: trinary (default) | scale | raw
    resolution: 0.05         # m / pixel
    origin: [-10.0, -5.0, 0.0]   # x, y (m) of the lower-left pixel's outer corner, yaw (rad)
    negate: 0
    occupied_thresh: 0.65
    free_thresh: 0.196

Reading follows ROS ``map_server`` (``image_loader.cpp``; nav2 ``map_io.cpp``): a grey
value ``v`` in 0..255 gives the occupancy probability ``p = (255 - v) / 255`` (``v / 255``
with ``negate: 1``); ``p > occupied_thresh`` is OCCUPIED, ``p < free_thresh`` is FREE and
everything in between is UNKNOWN. ``mode: scale`` would keep the in-between values as a
percentage in ROS; a :class:`~mrslam_env.gridmap.GridMap` is trinary, so they become
UNKNOWN as in ``trinary`` mode. The grey levels that Cartographer and slam_toolbox write
between the thresholds therefore read as UNKNOWN.

``mode: raw`` (ROS: pixel value = cell value) is read as an occupancy percentage: a value
``v`` in 0..100 (after ``negate``) is OCCUPIED when ``v >= 100 * occupied_thresh``, FREE
when ``v <= 100 * free_thresh`` and UNKNOWN otherwise; values 101..255 (ROS writes 255 for
-1) are UNKNOWN.

Images: PGM ``P5`` (binary) and ``P2`` (ascii) with up to 8 bits per sample are parsed
here (a ``maxval`` below 255 is stretched to 0..255 as SDL_image does); anything else
(PNG, BMP, ...) goes through Pillow. Colour images are reduced to grey as the integer mean of
the colour channels (ROS 1); the alpha channel is ignored (ROS averages alpha into trinary maps,
a quirk not reproduced). Images with 16-bit samples are rejected. Image row 0 is the
**top** of the map (highest y) whereas grid row 0 is the lowest y, so rows are flipped on
read and write.

The origin is the pose of the outer corner of the image's bottom-left pixel in the map
frame, yaw included (the ROS meaning; many ROS nodes ignore the yaw). :func:`load_map`
honours it: a map with a non-zero yaw is resampled (nearest cell,
:func:`~mrslam_env.gridmap.grid_in_frame`) into an axis-aligned grid of the map frame, so
that everything computed from it (a merge transform, a fused map) is in the file's frame.
:func:`load_map_lattice` gives the image's own grid and the yaw instead, unresampled.

Writing produces what ``map_saver`` writes: a PGM ``P5`` with 0 = occupied, 254 = free,
205 = unknown and a YAML with ``occupied_thresh: 0.65``, ``free_thresh: 0.196``,
``negate: 0``, ``mode: trinary`` and the yaw given (default 0).
``load_map(save_map(path, grid))`` reproduces ``grid`` exactly, and
``load_map_lattice(save_map(path, grid, yaw=a))`` gives back ``grid`` and ``a``.

Every problem with an input file raises :class:`MapFileError` with a one-line message
``"<file>: <problem>"``. Input files are checked before their data is read: a YAML or an
image must be a regular file (after resolving links: not a FIFO, a device or a folder, which
could block or never end), a YAML at most :data:`MAX_YAML_BYTES`, an image at most
:data:`MAX_IMAGE_FILE_BYTES` with a header-declared size within :data:`MAX_GRID_CELLS`; and
an origin must lie where float64 holds a cell (:data:`ORIGIN_PRECISION`).
"""

from __future__ import annotations

import math
import os
import re
import stat
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import NDArray

from mrslam_env.atomic import write_bytes_atomic, write_text_atomic
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap, grid_in_frame

__all__ = [
    "FREE_PIXEL",
    "MAX_GRID_CELLS",
    "MAX_IMAGE_FILE_BYTES",
    "MAX_YAML_BYTES",
    "OCCUPIED_PIXEL",
    "ORIGIN_PRECISION",
    "UNKNOWN_PIXEL",
    "MapFileError",
    "check_grid_size",
    "grey_to_cells",
    "load_map",
    "load_map_lattice",
    "map_frame_from_lattice",
    "map_images",
    "map_yaml_path",
    "read_image",
    "save_map",
]

OCCUPIED_PIXEL = 0
FREE_PIXEL = 254
UNKNOWN_PIXEL = 205

SAVED_OCCUPIED_THRESH = 0.65
SAVED_FREE_THRESH = 0.196

MODES = ("trinary", "scale", "raw")
REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")

PathLike = str | os.PathLike[str]


class MapFileError(ValueError):
    """A map file (YAML or image) is missing or malformed.

    Parameters
    ----------
    path : path-like
        The offending file.
    problem : str
        What is wrong with it; newlines are folded so the message stays on one line.

    Attributes
    ----------
    path : pathlib.Path
    problem : str
    """

    def __init__(self, path: PathLike, problem: str) -> None:
        self.path = Path(path)
        self.problem = " ".join(str(problem).split())
        super().__init__(f"{self.path}: {self.problem}")


# --------------------------------------------------------------------------------------
# Images


_PNM_TOKEN = re.compile(rb"\s*(?:#[^\n\r]*[\n\r]\s*)*(\S+)")


MAX_GRID_CELLS = 100_000_000
"""The largest map grid read or made, in cells (100 M cells: 10,000 x 10,000, about 0.1 GB
as int8 and several times that while a map is processed). Larger ones are refused with
their size before anything is allocated."""


def check_grid_size(shape: tuple[float, float], what: str) -> None:
    """Refuse a grid of ``shape`` (rows, cols) over :data:`MAX_GRID_CELLS`, naming ``what``.

    Raises
    ------
    ValueError
        With the size asked for and the limit.
    """
    rows, cols = shape
    if rows * cols > MAX_GRID_CELLS:
        raise ValueError(
            f"{what} would be a grid of {rows:,.0f} x {cols:,.0f} = {rows * cols:,.0f} cells; "
            f"the limit is {MAX_GRID_CELLS:,} (about {MAX_GRID_CELLS / 1e9:.1f} GB as int8)"
        )


MAX_YAML_BYTES = 1 << 20
"""The largest map YAML read, in bytes (1 MiB; a map YAML is a few lines)."""

MAX_IMAGE_FILE_BYTES = 4 * MAX_GRID_CELLS + (1 << 20)
"""The largest map image file read, in bytes: 4 bytes a pixel (an ascii PGM's ``255 ``, an
RGBA bitmap) of a :data:`MAX_GRID_CELLS` image, plus 1 MiB of header."""

ORIGIN_PRECISION = 1e-5
"""An origin is refused where float64 cannot hold a cell: the spacing of float64 numbers at
the map's farthest corner (``max(|x|, |y|)`` of the origin plus the image's diagonal) must be
under this fraction of the resolution. At 0.05 m/cell (a bound of 5e-7 m) that allows
corners up to 2**32 m, about 4.3e9 m, from 0 (the spacing is 4.8e-7 m below 2**32 and
9.5e-7 m from there; an origin of 1e15 m is off by 0.125 m, 2.5 cells); real maps' origins
are hundreds of metres."""

_PNM_HEADER_BYTES = 1 << 16

_FILE_KINDS = (
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _check_input_file(path: Path, what: str, limit: int, why: str) -> int:
    """The size in bytes of an input, refused before reading when it is not a regular file
    (a FIFO would block, a device never end) or is larger than ``limit`` bytes (``why``
    says why that limit)."""
    problem = _regular_file_problem(path)
    if problem is not None:
        raise MapFileError(path, problem)
    size = path.stat().st_size
    if size > limit:
        raise MapFileError(path, f"{what} of {size:,} bytes; the limit is {limit:,} ({why})")
    return size


def _regular_file_problem(path: Path) -> str | None:
    """Why ``path`` (links resolved) is not a regular file, or None if it is one.

    Raises
    ------
    OSError
        From ``stat`` (e.g. FileNotFoundError).
    """
    mode = path.stat().st_mode  # follows links
    if stat.S_ISREG(mode):
        return None
    kind = next((name for test, name in _FILE_KINDS if test(mode)), "not a file")
    target = f", {path.resolve()}" if path.is_symlink() else ""
    return f"not a regular file ({kind}{target})"


def _read_at_most(path: Path, limit: int, what: str) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (it may not grow past it)."""
    with path.open("rb") as handle:
        data = handle.read(limit + 1)
    if len(data) > limit:
        raise MapFileError(path, f"{what} grew past the limit of {limit:,} bytes while read")
    return data


def _check_origin_precision(
    yaml_path: Path, origin: tuple[float, float], resolution: float, shape: tuple[int, int]
) -> None:
    """Refuse an origin where float64 cannot hold a cell (:data:`ORIGIN_PRECISION`)."""
    x0, y0 = origin
    reach = max(abs(x0), abs(y0)) + math.hypot(*shape) * resolution
    spacing = math.ulp(reach)
    if not spacing < ORIGIN_PRECISION * resolution:
        raise MapFileError(
            yaml_path,
            f"origin ({x0:g}, {y0:g}) m is too far from 0: the float64 spacing at the map's "
            f"farthest corner ({reach:.3g} m) is {spacing:.3g} m, not under {ORIGIN_PRECISION:g} "
            f"of the resolution ({resolution:g} m); move the origin nearer 0",
        )


def _check_image_size(path: Path, width: int, height: int) -> None:
    try:
        check_grid_size((height, width), f"image of {width} x {height} pixels")
    except ValueError as error:
        raise MapFileError(path, str(error)) from None


def map_images(*yaml_paths: PathLike) -> list[Path]:
    """The image files that readable map YAML files name (for checks on outputs)."""
    images = []
    for yaml_path in map(Path, yaml_paths):
        image = Path(str(_read_yaml(yaml_path).get("image", "")))
        images.append(image if image.is_absolute() else yaml_path.parent / image)
    return images


def _pnm_header(path: Path, data: bytes, complete: bool = True) -> tuple[int, int, int, int]:
    """(width, height, maxval, end of the header) of a PGM, its size and maxval checked;
    ``complete`` False: ``data`` is the file's start only (a token that reaches its end
    may be cut)."""
    position = 2
    header: list[int] = []
    for name in ("width", "height", "maxval"):
        match = _PNM_TOKEN.match(data, position)
        if match is None or (not complete and match.end() >= len(data)):
            if not complete:
                raise MapFileError(path, f"PGM header longer than {len(data):,} bytes")
            raise MapFileError(path, f"corrupt PGM header: missing {name}")
        try:
            header.append(int(match.group(1)))
        except ValueError:
            raise MapFileError(
                path, f"corrupt PGM header: {name} is {match.group(1)[:20]!r}"
            ) from None
        position = match.end()
    width, height, maxval = header
    if width <= 0 or height <= 0:
        raise MapFileError(path, f"empty image ({width} x {height} pixels)")
    _check_image_size(path, width, height)
    if maxval > 255:
        raise MapFileError(path, f"16-bit images are not supported (PGM maxval {maxval})")
    if maxval <= 0:
        raise MapFileError(path, f"corrupt PGM header: maxval is {maxval}")
    return width, height, maxval, position


def _read_pnm_grey(path: Path, data: bytes) -> NDArray[np.uint8]:
    """Parse a PGM ``P5`` (binary) or ``P2`` (ascii) image into uint8 (height, width).

    Samples are stretched to 0..255 when ``maxval < 255`` (as SDL_image does, so ROS sees
    the same values); ``maxval > 255`` (16-bit) is rejected.
    """
    magic = data[:2]
    width, height, maxval, position = _pnm_header(path, data)
    count = width * height
    if magic == b"P5":
        # Exactly one whitespace character separates the header from the raster, and the
        # raster is exactly width x height bytes: anything else would load shifted or
        # sheared without a word.
        raster = data[position + 1 :]
        if len(raster) != count:
            crlf = data[position : position + 2] == b"\r\n" and len(raster) == count + 1
            raise MapFileError(
                path,
                f"PGM data is {len(raster)} bytes but the header says {width} x {height} = "
                f"{count}" + (" (header lines end in CRLF)" if crlf else ""),
            )
        samples = np.frombuffer(raster, dtype=np.uint8)
        if maxval == 255:  # the common case: the bytes are the grey levels
            return samples.reshape(height, width)
        samples = samples.astype(np.int64)
    else:
        tokens = data[position:].split()
        if len(tokens) != count:
            raise MapFileError(
                path,
                f"PGM data has {len(tokens)} values but the header says {width} x {height} = "
                f"{count}",
            )
        try:
            samples = np.array([int(t) for t in tokens[:count]], dtype=np.int64)
        except ValueError:
            raise MapFileError(path, "corrupt image: non-integer value in P2 data") from None
    if samples.size and (samples.max() > maxval or samples.min() < 0):
        raise MapFileError(path, f"corrupt image: pixel value above maxval {maxval}")
    if maxval != 255:
        samples = samples * 255 // maxval
    return samples.astype(np.uint8).reshape(height, width)


def _read_pillow_grey(path: Path) -> NDArray[np.uint8]:
    """Read any Pillow-supported 8-bit image and reduce it to grey uint8 (height, width).

    Colour is reduced as ROS 1 ``map_server`` does: the integer mean of the colour
    channels (alpha ignored).
    """
    from PIL import Image, UnidentifiedImageError

    try:
        # Pillow's own decompression-bomb limits (a warning, then an error, at other sizes
        # than ours) give way to MAX_GRID_CELLS: the header's size is checked before load().
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            opened = Image.open(path)
    except Image.DecompressionBombError as error:  # over twice Pillow's limit, so ours
        pixels = re.search(r"\((\d+) pixels\)", str(error))
        size = f"of {int(pixels[1]):,} pixels" if pixels else "over Pillow's limit"
        raise MapFileError(path, f"image {size}; the limit is {MAX_GRID_CELLS:,}") from None
    except UnidentifiedImageError as error:
        raise MapFileError(path, "unreadable image: not a PGM or an image Pillow knows") from error
    except (OSError, ValueError, SyntaxError) as error:
        raise MapFileError(path, f"corrupt image: {error}") from error
    try:
        with opened:
            _check_image_size(path, *opened.size)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", Image.DecompressionBombWarning)
                opened.load()
            mode = opened.mode
            if mode in ("I", "F") or mode.startswith("I;"):
                raise MapFileError(
                    path, f"16-bit or float images are not supported (Pillow mode {mode})"
                )
            if mode == "P":
                image = opened.convert("RGBA" if "transparency" in opened.info else "RGB")
            elif mode == "1":
                image = opened.convert("L")
            elif mode not in ("L", "LA", "RGB", "RGBA", "RGBX"):
                image = opened.convert("RGB")
            else:
                image = opened
            array = np.asarray(image)
            mode = image.mode
    except MapFileError:
        raise
    except UnidentifiedImageError as error:
        raise MapFileError(path, "unreadable image: not a PGM or an image Pillow knows") from error
    except (OSError, ValueError, SyntaxError) as error:
        raise MapFileError(path, f"corrupt image: {error}") from error
    if array.dtype != np.uint8:
        raise MapFileError(path, f"16-bit images are not supported ({array.dtype})")
    if array.ndim == 3:
        colour_channels = 1 if mode == "LA" else 3
        total = array[..., :colour_channels].astype(np.int64).sum(axis=2)
        array = (total // colour_channels).astype(np.uint8)
    if array.size == 0:
        raise MapFileError(path, f"empty image ({array.shape[1]} x {array.shape[0]} pixels)")
    return array


def read_image(path: PathLike) -> NDArray[np.uint8]:
    """Read a map image as grey levels.

    Parameters
    ----------
    path : path-like
        A PGM (``P5`` or ``P2``) or any 8-bit image Pillow can read (PNG, BMP, ...).

    Returns
    -------
    ndarray of uint8, shape (height, width)
        Grey levels, image row 0 = top of the picture (not flipped).

    Raises
    ------
    MapFileError
        Missing, not a regular file, unreadable, corrupt, empty or 16-bit image, or one
        over :data:`MAX_IMAGE_FILE_BYTES` or (its header says) :data:`MAX_GRID_CELLS`:
        checked before the pixels are read.
    """
    path = Path(path)
    try:
        size = _check_input_file(
            path,
            "image file",
            MAX_IMAGE_FILE_BYTES,
            f"4 bytes a pixel of {MAX_GRID_CELLS:,} pixels, plus 1 MiB",
        )
        with path.open("rb") as handle:
            head = handle.read(_PNM_HEADER_BYTES)
        if len(head) == 0:
            raise MapFileError(path, "empty image file (0 bytes)")
        if not (head[:2] in (b"P5", b"P2") and len(head) > 2 and head[2:3].isspace()):
            return _read_pillow_grey(path)
        if len(head) < size:  # the header's size checked before the pixels are read
            _pnm_header(path, head, complete=False)
        data = _read_at_most(path, MAX_IMAGE_FILE_BYTES, "image file")
    except FileNotFoundError:
        raise MapFileError(path, "image file not found") from None
    except OSError as error:
        raise MapFileError(path, f"cannot read image file ({error.strerror})") from error
    return _read_pnm_grey(path, data)


def grey_to_cells(
    grey: NDArray[np.uint8],
    *,
    negate: bool,
    occupied_thresh: float,
    free_thresh: float,
    mode: str = "trinary",
) -> NDArray[np.int8]:
    """Apply map_server's thresholds to grey levels.

    Parameters
    ----------
    grey : ndarray of uint8, shape (H, W)
        Grey levels 0..255.
    negate : bool
        Whether white means occupied.
    occupied_thresh, free_thresh : float
        Probability thresholds in [0, 1], ``free_thresh < occupied_thresh``.
    mode : {"trinary", "scale", "raw"}
        See the module docstring; ``scale`` gives the same result as ``trinary``.

    Returns
    -------
    ndarray of int8, shape (H, W)
        ``FREE``, ``OCCUPIED`` or ``UNKNOWN``, same row order as ``grey``.
    """
    if mode not in MODES:
        raise ValueError(f"unsupported map mode {mode!r}; expected one of {MODES}")
    # The rule applied to each of the 256 grey levels once, then looked up: one byte per
    # pixel of working memory, whatever the image size.
    value = np.arange(256, dtype=np.int64)
    if negate:
        value = 255 - value
    table = np.full(256, UNKNOWN, dtype=np.int8)
    if mode == "raw":
        percent = value
        table[(percent <= 100) & (percent >= 100.0 * occupied_thresh)] = OCCUPIED
        table[(percent <= 100) & (percent <= 100.0 * free_thresh)] = FREE
    else:
        occupancy = (255.0 - value) / 255.0
        table[occupancy > occupied_thresh] = OCCUPIED
        table[occupancy < free_thresh] = FREE
    return table[np.asarray(grey, dtype=np.uint8)]


# --------------------------------------------------------------------------------------
# YAML


def _number(yaml_path: Path, key: str, value: Any) -> float:
    """A finite float from a YAML value (PyYAML reads ``1e-3`` as a string: accept it)."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise MapFileError(yaml_path, f"{key} must be a number, got {value!r}")
    try:
        number = float(value)
    except ValueError:
        raise MapFileError(yaml_path, f"{key} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise MapFileError(yaml_path, f"{key} must be finite, got {value!r}")
    return number


def _read_yaml(yaml_path: Path) -> dict[str, Any]:
    try:
        if yaml_path.is_dir():
            raise IsADirectoryError
        _check_input_file(yaml_path, "map YAML", MAX_YAML_BYTES, "a map YAML is a few lines")
        text = _read_at_most(yaml_path, MAX_YAML_BYTES, "map YAML").decode("utf-8")
    except FileNotFoundError:
        raise MapFileError(yaml_path, "map YAML file not found") from None
    except IsADirectoryError:
        raise MapFileError(yaml_path, "map YAML path is a directory") from None
    except (OSError, UnicodeDecodeError) as error:
        raise MapFileError(yaml_path, f"cannot read map YAML ({error})") from error
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        problem = getattr(error, "problem", None) or type(error).__name__
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise MapFileError(yaml_path, f"invalid YAML syntax{where}: {problem}") from error
    if not isinstance(document, dict):
        raise MapFileError(
            yaml_path, f"map YAML must be a mapping of keys, got {type(document).__name__}"
        )
    return document


def load_map(path: PathLike) -> GridMap:
    """Load a ROS ``map_server`` map (YAML + image) as a grid of the map's frame.

    Parameters
    ----------
    path : path-like
        The map's YAML file. Its ``image`` is resolved relative to the YAML's folder.

    Returns
    -------
    GridMap
        With a zero origin yaw: the image's cells with row 0 at the lowest y (the image's
        bottom row), ``resolution`` in m per cell, ``origin`` = the YAML's origin x, y (m),
        exactly. With a non-zero yaw: the image turned by the yaw about the origin corner
        and resampled (nearest cell) into an axis-aligned grid of the map frame, the
        bounding box of its footprint (:func:`load_map_lattice` gives the image's grid
        and the yaw unresampled).

    Raises
    ------
    MapFileError
        Missing or unparsable YAML, a missing or invalid key, an unsupported mode, bad
        thresholds, or a missing, corrupt, empty or 16-bit image.
    """
    grid, yaw = load_map_lattice(path)
    if yaw == 0.0:
        return grid
    return grid_in_frame(grid, map_frame_from_lattice(grid, yaw))


def map_frame_from_lattice(grid: GridMap, yaw: float) -> NDArray[np.float64]:
    """``map_from_lattice``: where a point of ``grid`` (as :func:`load_map_lattice` reads
    it, origin x, y and no yaw) lies in the map frame of a file whose origin has ``yaw``:
    the grid turned by ``yaw`` about its origin corner."""
    x0, y0 = grid.origin
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x0 - (c * x0 - s * y0), y0 - (s * x0 + c * y0), yaw], dtype=np.float64)


def load_map_lattice(path: PathLike) -> tuple[GridMap, float]:
    """Load a ROS ``map_server`` map as the image's own grid and the origin's yaw.

    Returns
    -------
    tuple of (GridMap, float)
        The cells with row 0 at the image's bottom row, ``origin`` = the YAML's origin x, y
        (m), and the origin yaw (rad, as written). The grid lies in the map frame when the
        yaw is 0; otherwise :func:`map_frame_from_lattice` places it there.

    Raises
    ------
    MapFileError
        As :func:`load_map`.
    """
    yaml_path = Path(path)
    document = _read_yaml(yaml_path)
    missing = [key for key in REQUIRED_KEYS if key not in document]
    if missing:
        raise MapFileError(yaml_path, f"missing required key(s): {', '.join(missing)}")

    image_name = document["image"]
    if not isinstance(image_name, str) or not image_name.strip():
        raise MapFileError(yaml_path, f"image must be a file name, got {image_name!r}")
    resolution = _number(yaml_path, "resolution", document["resolution"])
    if resolution <= 0:
        raise MapFileError(yaml_path, f"resolution must be > 0 m/pixel, got {resolution}")
    origin = document["origin"]
    if not isinstance(origin, list | tuple) or len(origin) != 3:
        raise MapFileError(yaml_path, f"origin must be 3 numbers [x, y, yaw], got {origin!r}")
    x0, y0, yaw = (_number(yaml_path, "origin", value) for value in origin)
    negate = document["negate"]
    if isinstance(negate, bool) or negate in (0, 1):
        negate = bool(negate)
    else:
        raise MapFileError(yaml_path, f"negate must be 0 or 1, got {negate!r}")
    occupied_thresh = _number(yaml_path, "occupied_thresh", document["occupied_thresh"])
    free_thresh = _number(yaml_path, "free_thresh", document["free_thresh"])
    for key, value in (("occupied_thresh", occupied_thresh), ("free_thresh", free_thresh)):
        if not 0.0 <= value <= 1.0:
            raise MapFileError(yaml_path, f"{key} must lie in [0, 1], got {value}")
    if free_thresh >= occupied_thresh:
        raise MapFileError(
            yaml_path,
            f"free_thresh ({free_thresh}) must be below occupied_thresh ({occupied_thresh})",
        )
    mode = document.get("mode", "trinary")
    if mode not in MODES:
        raise MapFileError(
            yaml_path, f"unsupported mode {mode!r}; expected one of {', '.join(MODES)}"
        )
    _check_origin_precision(yaml_path, (x0, y0), resolution, (0, 0))
    image_path = Path(image_name)
    if not image_path.is_absolute():
        image_path = yaml_path.parent / image_path
    try:
        problem = _regular_file_problem(image_path)
    except OSError:
        raise MapFileError(yaml_path, f"image file not found: {image_path}") from None
    if problem is not None:
        raise MapFileError(yaml_path, f"image {image_path} is {problem}")
    grey = read_image(image_path)
    _check_origin_precision(yaml_path, (x0, y0), resolution, grey.shape)
    cells = grey_to_cells(
        grey,
        negate=negate,
        occupied_thresh=occupied_thresh,
        free_thresh=free_thresh,
        mode=mode,
    )
    grid = GridMap(cells=np.ascontiguousarray(cells[::-1]), resolution=resolution, origin=(x0, y0))
    return grid, yaw


def save_map(
    path_yaml: PathLike, grid: GridMap, image_name: str | None = None, *, yaw: float = 0.0
) -> Path:
    """Write a grid as a ROS ``map_server`` map: a PGM ``P5`` image and a YAML file.

    Parameters
    ----------
    path_yaml : path-like
        The YAML file to write; its folder must exist. ``NAME.pgm`` or a bare ``NAME``
        stands for ``NAME.yaml`` (:func:`map_yaml_path`). Both files are written
        atomically (a temporary name, then a rename), the image first.
    grid : GridMap
        The map; row 0 (lowest y) becomes the image's bottom row.
    image_name : str, optional
        Image file name relative to the YAML's folder (default: the YAML's stem + ``.pgm``).
        Sub-folders are created as needed.
    yaw : float
        The origin's yaw (rad): the map frame in which the grid is turned by ``yaw`` about
        its origin corner (:func:`map_frame_from_lattice`). 0 (default): the grid's own
        frame.

    Returns
    -------
    pathlib.Path
        The YAML file written.
    """
    yaml_path = map_yaml_path(path_yaml)
    if not math.isfinite(yaw):
        raise ValueError(f"yaw must be finite, got {yaw}")
    if image_name is None:
        image_name = yaml_path.with_suffix(".pgm").name
    if Path(image_name).is_absolute():
        raise ValueError(f"image_name must be relative to the YAML's folder, got {image_name}")
    image_path = yaml_path.parent / image_name
    image_path.parent.mkdir(parents=True, exist_ok=True)

    pixels = np.full(grid.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    pixels[grid.cells == FREE] = FREE_PIXEL
    pixels[grid.cells == OCCUPIED] = OCCUPIED_PIXEL
    rows, cols = grid.shape
    header = f"P5\n# CREATOR: mrslam {grid.resolution:.3f} m/pix\n{cols} {rows}\n255\n"
    raster = np.ascontiguousarray(pixels[::-1]).tobytes()
    write_bytes_atomic(image_path, header.encode("ascii") + raster)

    document = {
        "image": Path(image_name).as_posix(),
        "mode": "trinary",
        "resolution": float(grid.resolution),
        "origin": [float(grid.origin[0]), float(grid.origin[1]), float(yaw)],
        "negate": 0,
        "occupied_thresh": SAVED_OCCUPIED_THRESH,
        "free_thresh": SAVED_FREE_THRESH,
    }
    write_text_atomic(yaml_path, yaml.safe_dump(document, sort_keys=False, default_flow_style=None))
    return yaml_path


def map_yaml_path(path: PathLike) -> Path:
    """The YAML file a map output name stands for: ``NAME.yaml`` as given, ``NAME.pgm`` or
    a bare ``NAME`` as ``NAME.yaml`` (its image is then ``NAME.pgm``)."""
    path = Path(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        return path
    if path.suffix.lower() == ".pgm":
        return path.with_suffix(".yaml")
    return path.with_name(path.name + ".yaml")
