"""The run's summary figure, in the style of the paper's Figure 6.

Two rows of panels, all drawn in one frame (robot 0's map frame, i.e. its start pose), at
one scale and of one size, each with a scale bar in metres:

- top: the ground truth (the world raster moved into robot 0's frame by robot 0's true
  start pose), robot 0's map m1, robot 1's map m2 (placed by its true start pose), and
  one panel per further robot;
- bottom: the merge with the preliminary (verified, unrefined) estimate and the merge
  after refinement, each titled with its error against the truth, and an overlay of the
  refined merge: walls both robots mapped in black, walls only robot 0 mapped in blue,
  walls only the others mapped in orange, and in red the fused walls where the truth is
  free (more than a cell from any wall).

Maps are grey as in ROS (free white, occupied black, unknown grey). A panel without a
merge says why (:func:`no_merge_reason`).
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from PIL import Image, ImageDraw, ImageFont
from scipy import ndimage

from mrslam_env.evaluation import relative_transform_error
from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import FREE, OCCUPIED, UNKNOWN, GridMap

__all__ = ["map_image", "no_merge_reason", "panel_boxes", "summary_figure"]

_TITLE_HEIGHT = 52
_LEGEND_HEIGHT = 44
_GAP = 16
_MARGIN = 12
_MAX_PANEL = 560
"""Largest panel side, px: larger worlds are drawn at less than a pixel per cell."""

_GREY = {int(UNKNOWN): (205, 205, 205), int(FREE): (255, 255, 255), int(OCCUPIED): (0, 0, 0)}
_BOTH = (0, 0, 0)
_ROBOT0 = (30, 90, 220)
_OTHERS = (240, 140, 0)
_WRONG = (230, 0, 0)

Pose = ArrayLike


def map_image(grid: GridMap) -> NDArray[np.uint8]:
    """Grey image of a map, row 0 at the top (highest y)."""
    image = np.full(grid.cells.shape, 205, dtype=np.uint8)
    image[grid.cells == FREE] = 254
    image[grid.cells == OCCUPIED] = 0
    return image[::-1]


def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    return ImageFont.load_default(size=size)


class _Canvas:
    """The common frame: pixel (row, col) centres as points of robot 0's map frame."""

    def __init__(self, bounds: tuple[float, float, float, float], pixel: float) -> None:
        xmin, ymin, xmax, ymax = bounds
        self.pixel = pixel
        self.width = max(1, math.ceil((xmax - xmin) / pixel))
        self.height = max(1, math.ceil((ymax - ymin) / pixel))
        cols = xmin + (np.arange(self.width) + 0.5) * pixel
        rows = ymax - (np.arange(self.height) + 0.5) * pixel
        xs, ys = np.meshgrid(cols, rows)
        self.points = np.column_stack([xs.ravel(), ys.ravel()])

    def sample(self, grid: GridMap, frame_from_grid: Pose) -> NDArray[np.int8]:
        """The cells of ``grid`` (nearest) under each pixel; UNKNOWN outside it."""
        in_grid = transform_points(inverse(frame_from_grid), self.points)
        cells = grid.world_to_cell(in_grid)
        inside = grid.contains(cells)
        out = np.full(len(cells), UNKNOWN, dtype=np.int8)
        out[inside] = grid.cells[cells[inside, 0], cells[inside, 1]]
        return out.reshape(self.height, self.width)


def _known_corners(grid: GridMap) -> NDArray[np.float64]:
    """The corners of the box of a map's known cells, in its frame (none: no corner)."""
    rows, cols = np.nonzero(grid.cells != UNKNOWN)
    if len(rows) == 0:
        return np.zeros((0, 2))
    x0, y0 = grid.origin[0], grid.origin[1]
    r = grid.resolution
    xs = (x0 + cols.min() * r, x0 + (cols.max() + 1) * r)
    ys = (y0 + rows.min() * r, y0 + (rows.max() + 1) * r)
    return np.array([[x, y] for x in xs for y in ys])


def _grey(cells: NDArray[np.int8]) -> NDArray[np.uint8]:
    image = np.empty((*cells.shape, 3), dtype=np.uint8)
    image[...] = _GREY[int(UNKNOWN)]
    image[cells == FREE] = _GREY[int(FREE)]
    image[cells == OCCUPIED] = _GREY[int(OCCUPIED)]
    return image


def _scale_bar(draw: ImageDraw.ImageDraw, size: tuple[int, int], pixel: float) -> None:
    """A bar of a round number of metres, about a fifth of the panel wide, bottom left."""
    width_m = size[0] * pixel
    metres = max((m for m in (0.5, 1, 2, 5, 10, 20, 50, 100) if m <= width_m / 4), default=0.5)
    length = round(metres / pixel)
    x0, y0 = 10, size[1] - 14
    draw.rectangle((x0 - 4, y0 - 22, x0 + length + 4, y0 + 8), fill=(255, 255, 255))
    draw.rectangle((x0, y0, x0 + length, y0 + 4), fill=(0, 0, 0))
    draw.text((x0, y0 - 20), f"{metres:g} m", fill=(0, 0, 0), font=_font(15))


def _message(size: tuple[int, int], text: str) -> Image.Image:
    """A light panel with ``text`` wrapped in its middle."""
    body = Image.new("RGB", size, (236, 236, 236))
    draw = ImageDraw.Draw(body)
    font = _font(17)
    lines = []
    for paragraph in text.splitlines():
        lines += textwrap.wrap(paragraph, width=max(12, size[0] // 9)) or [""]
    y = max(8, size[1] // 2 - 11 * len(lines))
    for line in lines:
        draw.text((12, y), line, fill=(60, 0, 0), font=font)
        y += 22
    return body


def _panel(body: Image.Image, title: str, legend: Sequence[tuple[str, Any]] = ()) -> Image.Image:
    panel = Image.new("RGB", (body.width, body.height + _TITLE_HEIGHT + _LEGEND_HEIGHT), "white")
    panel.paste(body, (0, _TITLE_HEIGHT))
    draw = ImageDraw.Draw(panel)
    draw.rectangle(
        (0, _TITLE_HEIGHT - 1, body.width - 1, _TITLE_HEIGHT + body.height), outline=(120, 120, 120)
    )
    head, _, tail = title.partition("\n")
    draw.text((2, 4), head, fill=(0, 0, 0), font=_font(19))
    if tail:
        draw.text((2, 28), tail, fill=(70, 70, 70), font=_font(16))
    x, y = 2, _TITLE_HEIGHT + body.height + 6
    for label, colour in legend:
        step = 22 + round(draw.textlength(label, font=_font(14)))
        if x > 2 and x + step > body.width:
            x, y = 2, y + 19
        draw.rectangle((x, y, x + 12, y + 12), fill=colour, outline=(0, 0, 0))
        draw.text((x + 16, y - 2), label, fill=(0, 0, 0), font=_font(14))
        x += step
    return panel


def _worst_error(
    estimates: Sequence[Pose | None], truths: Sequence[Pose]
) -> tuple[float, float] | None:
    errors = [
        relative_transform_error(e, t)
        for e, t in zip(estimates, truths, strict=True)
        if e is not None
    ]
    if not errors:
        return None
    return max(e[0] for e in errors), math.degrees(max(e[1] for e in errors))


def no_merge_reason(
    merge: Mapping[str, Any], team_state: str, decisions: Sequence[str] = ()
) -> str:
    """Why a run has no merge, from its report's ``merge`` entry, the team's last state and
    its decisions ("STEP text")."""
    tested = merge.get("hypotheses_tested") or 0
    last = next(
        (d.split(" ", 1)[-1] for d in reversed(decisions) if "reject" in d or "no hyp" in d),
        None,
    )
    if team_state == "no_interaction" and merge.get("first_hypothesis_step") is None and not last:
        reason = "no merge: the robots never exchanged maps (no interaction or radio contact)"
    elif merge.get("first_hypothesis_step") is None:
        reason = "no merge: no hypothesis yet (the maps did not single out a placement)"
    elif team_state == "hypothesis_verification":
        reason = f"no merge: stopped at coverage while verifying ({tested} hypotheses tested)"
    else:
        reason = f"no merge: every hypothesis refused ({tested} tested)"
    return reason if last is None else f"{reason}\nlast: {last}"


def panel_boxes(figure_size: tuple[int, int], n_top: int) -> list[tuple[int, int, int, int]]:
    """The map areas (left, top, right, bottom) of a figure's panels, top row first then
    the preliminary merge, the refined merge and the overlay (as drawn by
    :func:`summary_figure` for ``n_top`` panels in the top row)."""
    columns = max(n_top, 3)
    width = (figure_size[0] - 2 * _MARGIN - _GAP * (columns - 1)) // columns
    row = (figure_size[1] - 2 * _MARGIN - _GAP) // 2
    height = row - _TITLE_HEIGHT - _LEGEND_HEIGHT
    boxes = []
    for k in range(n_top + 3):
        r, c = (0, k) if k < n_top else (1, k - n_top)
        left = _MARGIN + c * (width + _GAP)
        top = _MARGIN + r * (row + _GAP) + _TITLE_HEIGHT
        boxes.append((left, top, left + width, top + height))
    return boxes


def summary_figure(
    path: str | Path,
    ground_truth: GridMap,
    map0: GridMap,
    map1: GridMap,
    preliminary: GridMap | None,
    refined: GridMap | None,
    *,
    more_maps: Sequence[GridMap] = (),
    world_from_maps: Sequence[Pose] | None = None,
    verified: Sequence[Pose | None] = (),
    transforms: Sequence[Pose | None] = (),
    no_merge: str = "no merge",
) -> Path:
    """Write the summary PNG.

    ``world_from_maps``: each robot's start pose in the world (robot 0's, robot 1's, then
    ``more_maps``'); None: every map frame is the world's. ``verified`` and ``transforms``:
    per robot from robot 1 on, its ``map0_from_map_k`` as verified and as refined (None:
    not merged) — the error titles and the overlay's colours come from them. ``no_merge``:
    the text of the merge panels when there is no merge (:func:`no_merge_reason`).
    """
    robot_maps = [map0, map1, *more_maps]
    starts = [np.zeros(3)] * len(robot_maps) if world_from_maps is None else list(world_from_maps)
    if len(starts) != len(robot_maps):
        raise ValueError(f"{len(starts)} start poses for {len(robot_maps)} maps")
    map0_from_world = inverse(starts[0])
    true_frames = [compose(map0_from_world, s) for s in starts]
    # Where each map is drawn (frame 0 from its frame): the truth and the robots' maps by
    # the true start poses, the merges as they are (already in frame 0).
    layers: list[tuple[GridMap | None, NDArray[np.float64]]] = [
        (ground_truth, map0_from_world),
        *zip(robot_maps, true_frames, strict=True),
        (preliminary, np.zeros(3)),
        (refined, np.zeros(3)),
    ]
    corners = [
        transform_points(frame, _known_corners(grid)) for grid, frame in layers if grid is not None
    ]
    corners = [c for c in corners if len(c)] or [
        transform_points(map0_from_world, _known_corners(ground_truth))
    ]
    points = np.vstack(corners)
    pad = 0.5
    bounds = (
        float(points[:, 0].min()) - pad,
        float(points[:, 1].min()) - pad,
        float(points[:, 0].max()) + pad,
        float(points[:, 1].max()) + pad,
    )
    finest = min(grid.resolution for grid, _ in layers if grid is not None)
    side = max(bounds[2] - bounds[0], bounds[3] - bounds[1])
    canvas = _Canvas(bounds, max(finest, side / _MAX_PANEL))
    size = (canvas.width, canvas.height)
    sampled = [None if grid is None else canvas.sample(grid, frame) for grid, frame in layers]

    def body(cells: NDArray[np.int8] | None) -> Image.Image:
        assert cells is not None
        image = Image.fromarray(_grey(cells))
        _scale_bar(ImageDraw.Draw(image), size, canvas.pixel)
        return image

    truths = true_frames[1:]
    n_others = len(robot_maps) - 1
    verified = list(verified) or [None] * n_others
    transforms = list(transforms) or [None] * n_others
    titles = [
        "ground truth\nin robot_0's start frame",
        "m1: robot_0's map",
        *(
            f"m{k + 1}: robot_{k}'s map\nplaced at its true start"
            for k in range(1, len(robot_maps))
        ),
    ]
    top = [_panel(body(cells), title) for cells, title in zip(sampled, titles, strict=False)]
    bottom = []
    for cells, name, estimates in (
        (sampled[-2], "merge, preliminary estimate", verified),
        (sampled[-1], "merge after refinement", transforms),
    ):
        error = _worst_error(estimates, truths)
        if cells is None:
            bottom.append(_panel(_message(size, no_merge), name))
            continue
        detail = "" if error is None else f"\n{error[0]:.3f} m / {error[1]:.2f}° from the truth"
        bottom.append(_panel(body(cells), name + detail))
    legend = [
        ("both robots agree", _BOTH),
        ("robot_0 only", _ROBOT0),
        ("robot_1+ only", _OTHERS),
        ("wall where the truth is free", _WRONG),
    ]
    if sampled[-1] is None:
        bottom.append(_panel(_message(size, no_merge), "overlay", legend))
    else:
        bottom.append(
            _panel(
                _overlay(canvas, sampled, robot_maps, transforms),
                "overlay: refined merge vs. truth",
                legend,
            )
        )

    columns = max(len(top), 3)
    pw, ph = top[0].size
    figure = Image.new(
        "RGB",
        (2 * _MARGIN + columns * pw + (columns - 1) * _GAP, 2 * _MARGIN + 2 * ph + _GAP),
        "white",
    )
    for r, row in enumerate((top, bottom)):
        for c, panel in enumerate(row):
            figure.paste(panel, (_MARGIN + c * (pw + _GAP), _MARGIN + r * (ph + _GAP)))
    out = Path(path)
    figure.save(out, format="PNG")
    return out


def _overlay(
    canvas: _Canvas,
    sampled: Sequence[NDArray[np.int8] | None],
    robot_maps: Sequence[GridMap],
    transforms: Sequence[Pose | None],
) -> Image.Image:
    fused = sampled[-1]
    truth = sampled[0]
    assert fused is not None and truth is not None
    own = sampled[1] == OCCUPIED
    assert own is not None
    others = np.zeros_like(own)
    for grid, frame in zip(robot_maps[1:], transforms, strict=True):
        if frame is not None:
            others |= canvas.sample(grid, frame) == OCCUPIED
    walls = fused == OCCUPIED
    near_truth = ndimage.binary_dilation(truth == OCCUPIED, structure=np.ones((3, 3), bool))
    image = _grey(np.where(walls, FREE, fused).astype(np.int8))
    image[walls] = (120, 120, 120)
    # A wall both mapped within a cell of each other is one they agree on.
    own_near, others_near = ndimage.binary_dilation(own), ndimage.binary_dilation(others)
    image[walls & own & ~others_near] = _ROBOT0
    image[walls & others & ~own_near] = _OTHERS
    image[walls & ((own & others_near) | (others & own_near))] = _BOTH
    wrong = walls & ~near_truth & (truth != UNKNOWN)
    image[ndimage.binary_dilation(wrong)] = _WRONG
    result = Image.fromarray(image)
    _scale_bar(ImageDraw.Draw(result), (canvas.width, canvas.height), canvas.pixel)
    return result
