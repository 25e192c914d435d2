"""The run folder of ``mrslam run``: how a run claims, holds and reuses it (standard
library only, and :mod:`mrslam_env.mapio` for a map's image).

**The run folder.** A run never mixes its outputs with another's, nor writes into a folder
another run holds. It *claims* its folder by creating it (``mkdir``, which only one of
several runs started together can do): ``<out>/<name>`` when no such folder exists, else
the first ``<name>-2``, ``<name>-3``, … it can create; an existing folder, even an empty
one, is never claimed. With ``overwrite=True`` (``--overwrite``) the run reuses an existing
``<out>/<name>`` instead, after deleting the outputs of the earlier run there (the files
in :data:`OUTPUT_FILES`, ``robot_<i>.yaml``/``.pgm`` and temporaries a crashed run left;
nothing else is touched). Either way the
run holds its folder with a marker file, ``.mrslam-run``, created with ``O_EXCL`` and
removed when the run ends, also when it fails: ``--overwrite`` refuses a folder whose
marker names a live process, or one of another host (a run is writing there); a marker
naming a process of this host that no longer exists (a run killed with SIGKILL) is stale
and is replaced. Before ``--overwrite`` deletes anything, every input file (``--map``'s
YAML and its image, resolved through links) is checked; one that it would delete (an
earlier run's output name, in the run folder) is refused, and any other file is never
touched. Temporary names are unique per process (``.recording.<pid>.part.rrd``; the other
outputs through :func:`mrslam_env.atomic.atomic_path`).

**Run names.** ``name`` (``--name``) is one plain folder name: not empty, not ``.`` or
``..``, no ``/`` (nor ``os.sep``, ``os.altsep``) and no NUL; any other is refused (one-line
``ValueError``) before any work, as is an ``out`` that exists and is no folder. By default
the name is ``<scenario>-seed<seed>``, or ``<stem>-seed<seed>`` for ``--map <stem>.yaml``.
"""

from __future__ import annotations

import os
import re
import socket
from collections.abc import Sequence
from pathlib import Path

from mrslam_env.mapio import map_images

__all__ = [
    "OUTPUT_FILES",
    "RUN_MARKER",
    "check_inputs_outside",
    "check_out",
    "check_run_name",
    "deleted_by_overwrite",
    "input_files",
    "partial_recording",
    "prepare_run_dir",
    "release_run_dir",
]

OUTPUT_FILES = (
    "recording.rrd",
    "report.json",
    "figure.png",
    "merged.yaml",
    "merged.pgm",
)
"""A run's outputs besides the robots' maps (``robot_<i>.yaml`` / ``.pgm``)."""
ROBOT_MAP = re.compile(r"robot_\d+\.(yaml|pgm)")
RUN_MARKER = ".mrslam-run"
"""Created with ``O_EXCL`` in the run folder by the run that holds it; removed at its end."""
LEFTOVERS = re.compile(
    r"\.(recording|report|figure|merged|robot_\d+)\..*part\.(rrd|json|png|yaml|pgm)"
)
"""Temporary files a crashed run may have left (deleted by ``--overwrite``)."""


def partial_recording(run_dir: Path) -> Path:
    """The recording while this process writes it; renamed to ``recording.rrd`` when
    closed. Named for the process, so that no two runs ever share one."""
    return Path(run_dir) / f".recording.{os.getpid()}.part.rrd"


def input_files(map_path: Path | None) -> list[Path]:
    """The files a run reads: ``--map``'s YAML and the image it names (none for a scenario)."""
    if map_path is None:
        return []
    return [Path(map_path), *map_images(map_path)]


def deleted_by_overwrite(name: str) -> bool:
    """Whether ``--overwrite`` deletes a file of this name in the run folder (an earlier
    run's output or a temporary a crashed run left; the names a run writes are among
    them)."""
    return bool(name in OUTPUT_FILES or ROBOT_MAP.fullmatch(name) or LEFTOVERS.fullmatch(name))


def check_inputs_outside(folder: Path, inputs: Sequence[Path]) -> None:
    """Refuse (``ValueError``, one line) an input file that ``--overwrite`` would delete
    (or a run would write over): one that, resolved through links, lies directly in
    ``folder`` under a name :func:`deleted_by_overwrite`. Any other file there (e.g. the
    map's ``world.yaml``) is never touched, and is read as an input."""
    inside = Path(folder).resolve()
    for path in inputs:
        resolved = Path(path).resolve()
        if resolved.parent == inside and deleted_by_overwrite(resolved.name):
            link = "" if resolved == Path(path).absolute() else f" (through a link, {resolved})"
            raise ValueError(
                f"--overwrite would delete the input map file {path}: it is the earlier run's "
                f"{resolved.name} in the run folder {folder}{link}; copy it elsewhere or "
                "choose another --name"
            )


_HOLDER = re.compile(r"pid (\d+) on (.+)")
"""The marker's text: the process holding the folder and its host."""


def _hold(folder: Path) -> None:
    """Create the run marker in ``folder`` (``O_EXCL``); ``ValueError`` when another run
    holds the folder. A marker left by a process that no longer exists on this host (a run
    killed with SIGKILL) is stale: it is removed and the marker created once more."""
    marker = folder / RUN_MARKER
    for attempt in range(2):
        try:
            descriptor = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                holder = marker.read_text(encoding="utf-8")
            except FileNotFoundError:  # its run let go meanwhile
                holder = ""
            except OSError:
                holder = "unknown"
            if attempt == 0 and (not holder or _remove_stale(marker, holder)):
                continue
            raise ValueError(
                f"run folder {folder} is held by another run ({holder.strip() or 'unknown'}); "
                f"if no run is using it, delete {marker}"
            ) from None
        try:
            with os.fdopen(descriptor, "w", encoding="utf-8") as file:
                file.write(f"pid {os.getpid()} on {socket.gethostname()}\n")
        except BaseException:  # the marker is ours: never leave it behind
            marker.unlink(missing_ok=True)
            raise
        return


def _remove_stale(marker: Path, holder: str) -> bool:
    """Remove ``marker`` when its text ``holder`` names a process of this host that no
    longer exists; True when it is gone. Stale markers are removed one run at a time (an
    exclusive ``flock`` on the folder, held for the check and the removal), and only the
    marker read: one that another run has meanwhile replaced by its own is kept."""
    found = _HOLDER.fullmatch(holder.strip())
    if found is None or found[2] != socket.gethostname():
        return False
    try:
        os.kill(int(found[1]), 0)
    except ProcessLookupError:
        pass  # no such process: stale
    except (OSError, OverflowError):  # alive under another user, or no pid at all
        return False
    else:
        return False
    import fcntl  # POSIX, as the pid check is

    descriptor = os.open(marker.parent, os.O_RDONLY)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)  # released as the descriptor closes
        try:
            if marker.read_text(encoding="utf-8") != holder:
                return False  # a run removed the stale one and took the folder
        except FileNotFoundError:
            return True  # a run removed the stale one
        marker.unlink()
        return True
    finally:
        os.close(descriptor)


def release_run_dir(run_dir: Path) -> None:
    """Let go of a folder :func:`prepare_run_dir` claimed (remove its marker)."""
    (Path(run_dir) / RUN_MARKER).unlink(missing_ok=True)


def prepare_run_dir(
    out: Path, name: str, *, overwrite: bool = False, inputs: Sequence[Path] = ()
) -> Path:
    """Claim the folder a run writes to (the module docstring's run-folder rule) and hold
    it; the caller releases it with :func:`release_run_dir` when the run ends.

    A new ``<out>/<name>``, else the first ``<name>-2``, ``<name>-3``, … that this call
    creates; with ``overwrite``, an existing ``<out>/<name>`` held by no other run, with
    the earlier run's outputs deleted, after checking that none of ``inputs`` lies in it.

    Raises
    ------
    ValueError
        ``name`` is no plain folder name (:func:`check_run_name`), ``out`` or
        ``<out>/<name>`` is a file; with ``overwrite``: an input lies in the folder, or
        another run holds it.
    """
    out = Path(out)
    check_run_name(name)
    check_out(out)
    folder = out / name
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"run folder {folder} exists and is a file")
    if overwrite and folder.is_dir():
        check_inputs_outside(folder, inputs)
        _hold(folder)
        try:
            for old in folder.iterdir():
                if deleted_by_overwrite(old.name):
                    old.unlink(missing_ok=True)
        except BaseException:  # e.g. an output's name taken by a folder: let go of it
            release_run_dir(folder)
            raise
        return folder
    out.mkdir(parents=True, exist_ok=True)
    index = 1
    while True:
        candidate = folder if index == 1 else out / f"{name}-{index}"
        index += 1
        try:
            candidate.mkdir()  # atomic: of runs started together, one creates it
        except FileExistsError:
            continue
        try:
            _hold(candidate)
        except ValueError:  # an --overwrite run took it between the two calls
            continue
        return candidate


def check_run_name(name: str) -> None:
    """Refuse (``ValueError``, one line naming ``--name``) a run name that is not one plain
    folder name: empty, ``.`` or ``..``, or with a path separator or a NUL in it."""
    separators = [s for s in ("/", os.sep, os.altsep) if s]
    if name in ("", ".", "..") or "\0" in name or any(s in name for s in separators):
        raise ValueError(
            f"--name {name!r}: a run name is one plain folder name inside --out "
            "(not empty, '.' or '..', no '/' or NUL)"
        )


def check_out(out: Path) -> None:
    """Refuse (``ValueError``, one line naming ``--out``) an ``out`` that exists and is no
    folder, or whose nearest existing parent is no folder."""
    for folder in (out, *out.parents):
        if folder.exists():
            if not folder.is_dir():
                which = "" if folder == out else f" {folder}"
                raise ValueError(f"--out {out}:{which} exists and is not a folder")
            return
