#!/usr/bin/env python3
"""Make the README's and the docs' images from the current code, in one command.

Usage::

    .venv/bin/python scripts/make_docs_images.py [--viewer] [--only docs/NAME.png ...]

- ``docs/office.png``: the office scenario as the env renders it (``render_mode=
  "rgb_array"``) at the start of seed 0;
- ``docs/figure6.png``: ``figure.png`` of the default run (``mrslam run``, in a temporary
  folder);
- ``docs/viewer-run.png``: with ``--viewer`` only, the default run's recording in the
  Rerun web viewer through ``scripts/screenshot_rrd.py`` (needs Debian's ``chromium``
  and a few minutes).

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

ROOT = Path(__file__).resolve().parents[1]


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


def make_viewer_run(out: Path, work: Path) -> None:
    recording = _default_run(work) / "recording.rrd"
    prefix = str(out.with_suffix(""))
    script = ROOT / "scripts" / "screenshot_rrd.py"
    subprocess.run([sys.executable, str(script), str(recording), prefix], check=True)


Maker = Callable[[Path, Path], None]

IMAGES: dict[str, Maker] = {
    "docs/office.png": make_office,
    "docs/figure6.png": make_figure6,
    "docs/viewer-run.png": make_viewer_run,
}
"""Every image this command makes (repository path -> maker(out, work folder))."""

OPTIONAL = {"docs/viewer-run.png": "--viewer"}
"""Images made only with a flag (they need more than the package: chromium)."""

KEPT = {
    "docs/undecidable-pair.png": "drawn once from the twin search of `mrslam bench merge` "
    "(033-twin_wings); no maker yet",
}
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
