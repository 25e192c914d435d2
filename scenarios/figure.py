"""The run's summary figure, in the style of the paper's Figure 6.

Five panels side by side, each a map drawn in ROS grey levels (free white, occupied
black, unknown grey): the ground truth, robot 0's map m1, robot 1's map m2, the merge
with the preliminary (verified, unrefined) estimate, and the merge after refinement.
Maps are drawn at one scale (one pixel per cell of the finest map) and each panel is
labelled. Panels without content (no merge) say so. A team of more than two robots adds
one panel per further robot's map after m2.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw

from mrslam_env.gridmap import FREE, OCCUPIED, GridMap

__all__ = ["map_image", "summary_figure"]

_LABEL_HEIGHT = 22
_GAP = 12
_BACKGROUND = 255


def map_image(grid: GridMap) -> NDArray[np.uint8]:
    """Grey image of a map, row 0 at the top (highest y)."""
    image = np.full(grid.cells.shape, 205, dtype=np.uint8)
    image[grid.cells == FREE] = 254
    image[grid.cells == OCCUPIED] = 0
    return image[::-1]


def _panel(grid: GridMap | None, label: str, height: int) -> Image.Image:
    if grid is None:
        body = Image.new("L", (height, height), 230)
        ImageDraw.Draw(body).text((10, height // 2), "no merge", fill=0)
    else:
        body = Image.fromarray(map_image(grid))
    panel = Image.new("L", (body.width, body.height + _LABEL_HEIGHT), _BACKGROUND)
    panel.paste(body, (0, _LABEL_HEIGHT))
    ImageDraw.Draw(panel).text((4, 4), label, fill=0)
    return panel


def summary_figure(
    path: str | Path,
    ground_truth: GridMap,
    map0: GridMap,
    map1: GridMap,
    preliminary: GridMap | None,
    refined: GridMap | None,
    *,
    more_maps: Sequence[GridMap] = (),
) -> Path:
    """Write the five-panel PNG (one more panel per map of ``more_maps``, robot 2's and
    on, after m2); maps of other resolutions are scaled to the finest."""
    maps = [ground_truth, map0, map1, *more_maps, preliminary, refined]
    finest = min(m.resolution for m in maps if m is not None)
    labels = [
        "ground truth",
        "m1 (robot_0)",
        "m2 (robot_1)",
        *(f"m{k + 3} (robot_{k + 2})" for k in range(len(more_maps))),
        "merge, preliminary estimate",
        "merge, after refinement",
    ]
    height = max(round(m.cells.shape[0] * m.resolution / finest) for m in maps if m is not None)
    panels = []
    for grid, label in zip(maps, labels, strict=True):
        panel = _panel(grid, label, height)
        if grid is not None and not np.isclose(grid.resolution, finest):
            scale = grid.resolution / finest
            panel = panel.resize((round(panel.width * scale), round(panel.height * scale)))
        panels.append(panel)
    width = sum(p.width for p in panels) + _GAP * (len(panels) - 1)
    figure = Image.new("L", (width, max(p.height for p in panels)), _BACKGROUND)
    x = 0
    for panel in panels:
        figure.paste(panel, (x, 0))
        x += panel.width + _GAP
    out = Path(path)
    figure.save(out)
    return out
