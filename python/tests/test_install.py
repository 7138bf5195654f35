# SPDX-License-Identifier: MIT
"""The pip-installed package (scripts/setup_python.sh), if there is one."""
import os
import subprocess
import sys

import pytest

import nbmc
from conftest import HERE

PROBE = "import nbmc, sys; print(nbmc.__file__); print(nbmc.__version__); print(nbmc.library_path)"


def test_installed_package_imports_without_environment(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("NBMC_LIBRARY", "PYTHONPATH")}
    r = subprocess.run([sys.executable, "-c", PROBE], cwd=tmp_path, env=env,
                       capture_output=True, text=True)
    if "No module named 'nbmc'" in r.stderr:
        pytest.skip("nbmc is not pip-installed for this interpreter")
    assert r.returncode == 0, r.stderr
    path, version, library = r.stdout.split("\n")[:3]
    assert not path.startswith(str(HERE.parent)), "imported the source tree, not the install"
    assert version == nbmc.__version__
    assert os.path.exists(library) or library.startswith("libnbmc")


def test_missing_library_is_a_clear_import_error(tmp_path):
    env = dict(os.environ, NBMC_LIBRARY=str(tmp_path / "nope.so"), PYTHONPATH=str(HERE.parent))
    r = subprocess.run([sys.executable, "-c", "import nbmc"], cwd=tmp_path, env=env,
                       capture_output=True, text=True)
    assert r.returncode != 0
    assert "ImportError" in r.stderr and "NBMC_LIBRARY" in r.stderr and "nope.so" in r.stderr


def test_sequence_example_runs(tmp_path):
    example = HERE.parent.parent / "examples" / "python" / "sequence.py"
    env = dict(os.environ, PYTHONPATH=str(HERE.parent), MPLBACKEND="Agg")
    r = subprocess.run([sys.executable, str(example), "--frames", "2", "--out", str(tmp_path)],
                       env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "meshes").iterdir()) == ["surface_000.ply",
                                                                       "surface_001.ply"]
    assert "mean" in r.stdout
