# SPDX-License-Identifier: MIT
"""Test setup: which library, which CLI, which package.

NBMC_PREFIX (set by scripts/test_python.sh) names the install prefix under
test: PREFIX/lib/libnbmc.so is loaded and PREFIX/bin/nbmc is the CLI the
meshes are compared with. Without it, <repo>/build/install. The package is
the one of this source tree (python/nbmc), so the checkout is what is tested;
test_install.py checks the pip-installed copy separately.
"""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
PREFIX = Path(os.environ.get("NBMC_PREFIX") or REPO / "build" / "install").resolve()
os.environ.setdefault("NBMC_LIBRARY", str(PREFIX / "lib" / "libnbmc.so"))
sys.path.insert(0, str(HERE.parent))

import nbmc  # noqa: E402

assert Path(nbmc.__file__).resolve().parent == HERE.parent / "nbmc", nbmc.__file__

DATA = REPO / "examples" / "data" / "double_dam_break_4732.xyz"
RADIUS = 0.025  # particle radius of the example frame (spacing 0.05)
CLI = PREFIX / "bin" / "nbmc"
HEADER = PREFIX / "include" / "nbmc.h"


def run_cli(*args, check=True):
    """Runs the CLI of the prefix under test (one thread keeps the 2-core CI calm)."""
    if not CLI.exists():
        pytest.skip(f"no CLI at {CLI}")
    r = subprocess.run([str(CLI), "reconstruct", *map(str, args), "-q", "--threads", "1"],
                       capture_output=True, text=True)
    if check and r.returncode != 0:
        raise AssertionError(f"nbmc {' '.join(map(str, args))} failed: {r.stderr}")
    return r


def read_ply(path):
    """(vertices, normals or None, triangles) of a binary little-endian PLY as nbmc writes it."""
    raw = Path(path).read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    header = raw[:end].decode().splitlines()
    nv = nt = 0
    props = []
    for line in header:
        w = line.split()
        if w[:2] == ["element", "vertex"]:
            nv = int(w[2])
        elif w[:2] == ["element", "face"]:
            nt = int(w[2])
        elif w[:2] == ["property", "float"]:
            props.append(w[2])
    vdata = np.frombuffer(raw, dtype="<f4", count=nv * len(props), offset=end).reshape(nv, len(props))
    faces = np.frombuffer(raw, dtype=[("n", "u1"), ("v", "<u4", 3)], count=nt,
                          offset=end + vdata.nbytes)
    assert (faces["n"] == 3).all()
    normals = vdata[:, 3:6] if "nx" in props else None
    return vdata[:, :3], normals, faces["v"]


@pytest.fixture(scope="session")
def points():
    """The example frame, (N, 3) float32, read-only."""
    p = np.fromfile(DATA, dtype="<f4").reshape(-1, 3)
    p.flags.writeable = False
    return p


@pytest.fixture(scope="session")
def mesh(points):
    """The example frame's mesh with default parameters."""
    return nbmc.reconstruct(points, particle_radius=RADIUS, threads=1)


@pytest.fixture(scope="session")
def cli_ply(tmp_path_factory):
    """The CLI's mesh of the example frame with default parameters."""
    out = tmp_path_factory.mktemp("cli") / "surface.ply"
    run_cli(DATA, "--particle-radius", RADIUS, "-o", out)
    return out
