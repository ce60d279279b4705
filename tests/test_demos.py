"""Every demo runs to the end and writes its pictures (run as a subprocess, like a user)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(script: str, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "demos" / script), *args], cwd=cwd,
                          capture_output=True, text=True, timeout=900)


def test_valve_geometry_demo(tmp_path):
    proc = _run("valve_geometry.py", "--out", str(tmp_path), "--mesh-size", "1.0", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for name in ("flat_leaflet.png", "normal_valve.png", "graft_valve_W21_H27.png",
                 "flat_graft_W21_H27.png", "normal_valve.xdmf", "graft_valve_W21_H27.vtu"):
        assert (tmp_path / name).stat().st_size > 1000, name


def test_cli_mesh_rejects_bad_graft(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "valve_dolfinx.cli", "mesh", "--graft-width",
                           "-5", "--graft-height", "10", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    assert "graft_width_pct" in proc.stderr and "[0, 100]" in proc.stderr


@pytest.mark.parametrize("flag", ["--defaults"])
def test_cli_mesh_writes_reloadable_meshes(tmp_path, flag):
    proc = subprocess.run([sys.executable, "-m", "valve_dolfinx.cli", "mesh", flag, "--out",
                           str(tmp_path), "--mesh-size", "1.0"], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    from valve_dolfinx.io import load_valve_mesh

    valve = load_valve_mesh(tmp_path / "graft_valve_W21_H27.npz")
    assert valve.parameters.graft_width_pct == 21.0
