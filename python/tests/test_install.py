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
