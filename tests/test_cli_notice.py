"""`mrslam run` says on stderr when the numba kernels are about to compile (empty cache)."""

from __future__ import annotations

from pathlib import Path

import pytest

from scenarios.cli import kernels_compiled


def test_an_empty_numba_cache_means_kernels_to_compile(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert not kernels_compiled()
    (tmp_path / "mrslam_env" / "slam").mkdir(parents=True)
    (tmp_path / "mrslam_env" / "slam" / "grid.integrate_scan-287.py311.nbi").write_bytes(b"")
    assert kernels_compiled()
