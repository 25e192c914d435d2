#!/usr/bin/env python3
"""Make the README's and the docs' images from the current code, in one command.

Usage::

    .venv/bin/python scripts/make_docs_images.py [--viewer] [--only docs/NAME.png ...]

- ``docs/office.png``: the office scenario as the env renders it (``render_mode=
  "rgb_array"``) at the start of seed 0;
- ``docs/figure6.png``: ``figure.png`` of the default run (``mrslam run``, in a temporary
  folder);
- ``docs/undecidable-pair.png``: a pair of maps no method can decide, in ``twin_wings``
  (:mod:`scenarios.bench.merge.twins`): two robots wander in one room of the left wing;
  map 2 fits the mirror room of the right wing as well as its own;
- ``docs/viewer-run.png``, ``docs/recording-verifying.png`` and
  ``docs/recording-accepted.png``: with ``--viewer`` only, the default run's recording in
  the Rerun web viewer through ``scripts/screenshot_rrd.py`` (needs Debian's
  ``chromium`` and a few minutes), at its end and stopped at steps 130 and 200.

:data:`IMAGES` lists every image the command makes; another image maker registers itself
there (``IMAGES["docs/NAME.png"] = maker``). :data:`KEPT` lists the linked images that are
not remade, with why. ``tests/test_docs_images.py`` checks that every image the README
and docs/*.md link is in one of the two.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]

Maker = Callable[[Path, Path], None]
"""Makes one image: ``maker(out, work folder)``."""


def _mrslam() -> str:
    beside = Path(sys.executable).parent / "mrslam"
    return str(beside) if beside.exists() else shutil.which("mrslam") or "mrslam"


def _default_run(work: Path) -> Path:
    """The default run's folder (made once per invocation, in ``work``)."""
    run_dir = work / "run" / "office-seed0"
    if not run_dir.exists():
        subprocess.run([_mrslam(), "run", "--out", str(work / "run")], check=True)
    return run_dir


def make_office(out: Path, work: Path) -> None:
    from PIL import Image

    from mrslam_env import parallel_env

    env = parallel_env(scenario="office", seed=0, render_mode="rgb_array")
    env.reset()
    frame = env.render()
    env.close()
    Image.fromarray(frame).save(out)


def make_figure6(out: Path, work: Path) -> None:
    shutil.copyfile(_default_run(work) / "figure.png", out)


def make_undecidable_pair(out: Path, work: Path) -> None:
    """The world (black), map 1's floor (blue), map 2's walls at its robot's true start
    (green) and at the twin start (red), 20 px/m."""
    from PIL import Image

    from mrslam_env.geometry import compose, transform_points
    from mrslam_env.gridmap import FREE, OCCUPIED, GridMap
    from mrslam_env.registry import build_world
    from mrslam_env.sim.world import ground_truth_map
    from scenarios.bench.merge.pairs import merge_pair_from_runs, simulate_run
    from scenarios.bench.merge.twins import world_grid, world_twin

    world = build_world("twin_wings")
    start1, start2 = np.array([1.0, 13.0, 0.0]), np.array([1.2, 9.8, 1.0])  # the NW room
    world_from_map1, maps1 = simulate_run(world, start1, [150], seed=[0, 1])
    world_from_map2, maps2 = simulate_run(world, start2, [150], seed=[0, 2])
    starts = {"start1_world": list(world_from_map1), "start2_world": list(world_from_map2)}
    pair = merge_pair_from_runs(
        "twin_wings",
        "twin_wings",
        (world_from_map1, maps1[150]),
        (world_from_map2, maps2[150]),
        starts,
    )
    twin = world_twin(pair, world_grid(world, [world_from_map1, world_from_map2]))
    if not twin.undecidable or twin.twin is None:
        raise RuntimeError("the twin_wings pair has no twin any more: choose other starts")
    raster = ground_truth_map(world, 0.05, margin=1.0)
    image = np.full((*raster.shape, 3), 255, dtype=np.uint8)
    image[raster.cells == OCCUPIED] = 0

    def paint(
        grid: GridMap, state: int, world_from_map: NDArray[np.float64], rgb: tuple[int, int, int]
    ) -> None:
        rows, cols = np.nonzero(grid.cells == state)
        centres = grid.origin + (np.column_stack([cols, rows]) + 0.5) * grid.resolution
        points = transform_points(world_from_map, centres)
        col = np.floor((points[:, 0] - raster.origin[0]) / raster.resolution).astype(int)
        row = np.floor((points[:, 1] - raster.origin[1]) / raster.resolution).astype(int)
        mask = np.zeros(raster.shape, dtype=bool)
        inside = (row >= 0) & (row < raster.shape[0]) & (col >= 0) & (col < raster.shape[1])
        mask[row[inside], col[inside]] = True
        if state == OCCUPIED:  # walls two pixels wide, to be seen
            mask |= np.roll(mask, 1, axis=0) | np.roll(mask, 1, axis=1)
        image[mask] = rgb

    paint(pair.m1, int(FREE), world_from_map1, (200, 200, 255))
    paint(pair.m2, int(OCCUPIED), world_from_map2, (0, 150, 0))
    paint(pair.m2, int(OCCUPIED), compose(world_from_map1, twin.twin), (220, 0, 0))
    Image.fromarray(image[::-1]).save(out)


def _screenshot(recording: Path, out: Path) -> None:
    script = ROOT / "scripts" / "screenshot_rrd.py"
    prefix = str(out.with_suffix(""))
    subprocess.run([sys.executable, str(script), str(recording), prefix], check=True)


def make_viewer_run(out: Path, work: Path) -> None:
    _screenshot(_default_run(work) / "recording.rrd", out)


def _run_until(step: int) -> Maker:
    """A maker of the viewer at ``step`` of the default run: the run stopped there (the
    viewer opens at the recording's last step)."""

    def make(out: Path, work: Path) -> None:
        parent = work / f"until-{step}"
        subprocess.run(
            [_mrslam(), "run", "--max-steps", str(step), "--out", str(parent)], check=True
        )
        _screenshot(parent / "office-seed0" / "recording.rrd", out)

    return make


IMAGES: dict[str, Maker] = {
    "docs/office.png": make_office,
    "docs/figure6.png": make_figure6,
    "docs/undecidable-pair.png": make_undecidable_pair,
    "docs/viewer-run.png": make_viewer_run,
    "docs/recording-verifying.png": _run_until(130),
    "docs/recording-accepted.png": _run_until(200),
}
"""Every image this command makes (repository path -> maker(out, work folder))."""

OPTIONAL = {
    name: "--viewer"
    for name in (
        "docs/viewer-run.png",
        "docs/recording-verifying.png",
        "docs/recording-accepted.png",
    )
}
"""Images made only with a flag (they need more than the package: chromium)."""

KEPT: dict[str, str] = {}
"""Linked images not remade by this command, with why."""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--viewer", action="store_true", help="also the viewer screenshot")
    parser.add_argument("--only", nargs="+", metavar="IMAGE", help="make only these images")
    args = parser.parse_args(argv)
    wanted = args.only or [
        name for name in IMAGES if name not in OPTIONAL or (args.viewer and OPTIONAL[name])
    ]
    unknown = [name for name in wanted if name not in IMAGES]
    if unknown:
        parser.error(f"no maker for {', '.join(unknown)} (known: {', '.join(IMAGES)})")
    with tempfile.TemporaryDirectory(prefix="mrslam-docs-") as tmp:
        for name in wanted:
            print(f"making {name}", file=sys.stderr)
            IMAGES[name](ROOT / name, Path(tmp))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
