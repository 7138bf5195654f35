# SPDX-License-Identifier: MIT
"""The ctypes declarations against the installed nbmc.h: constants, every
function, struct layouts (through the C compiler), and the version."""
import ctypes
import re
import shutil
import subprocess

import pytest

import nbmc
from nbmc import _capi as C
from conftest import HEADER


@pytest.fixture(scope="module")
def header():
    if not HEADER.exists():
        pytest.skip(f"no header at {HEADER}")
    return HEADER.read_text()


def test_constants_match_header(header):
    defines = dict(re.findall(r"^#define NBMC_(\w+)\s+(\d+)u?\b", header, re.M))
    defines.pop("H", None)
    skip = {"VERSION_MAJOR", "VERSION_MINOR", "VERSION_PATCH"}
    checked = 0
    for name, value in defines.items():
        if name in skip:
            continue
        assert hasattr(C, name), f"NBMC_{name} is missing from nbmc/_capi.py"
        assert getattr(C, name) == int(value), name
        checked += 1
    assert checked >= 30


def test_every_function_is_declared(header):
    names = set(re.findall(r"^NBMC_API\b[^;]*?\b(nbmc_\w+)\s*\(", header, re.M))
    assert len(names) > 30
    assert names == set(C._SIGNATURES)


def test_version(header):
    major, minor, patch = (re.search(rf"#define NBMC_VERSION_{k}\s+(\d+)", header).group(1)
                           for k in ("MAJOR", "MINOR", "PATCH"))
    assert nbmc.__version__ == f"{major}.{minor}.{patch}" == nbmc.library_version()
    assert nbmc.library_version_string().startswith(nbmc.__version__)
    assert "serial" in nbmc.backends() and nbmc.backend_available("auto")


LAYOUT_C = r"""
#include <stdio.h>
#include <stddef.h>
#include "nbmc.h"
#define F(T, f) printf(#T " " #f " %zu %zu\n", offsetof(T, f), sizeof(((T*)0)->f));
int main(void) {
  printf("nbmc_context_desc SIZE %zu 0\n", sizeof(nbmc_context_desc));
  printf("nbmc_params SIZE %zu 0\n", sizeof(nbmc_params));
  printf("nbmc_stats SIZE %zu 0\n", sizeof(nbmc_stats));
  printf("nbmc_mesh_check_result SIZE %zu 0\n", sizeof(nbmc_mesh_check_result));
  printf("nbmc_subdomain_stats SIZE %zu 0\n", sizeof(nbmc_subdomain_stats));
  printf("nbmc_subdomain_entry SIZE %zu 0\n", sizeof(nbmc_subdomain_entry));
  %FIELDS%
  return 0;
}
"""

STRUCTS = {"nbmc_context_desc": C.ContextDesc, "nbmc_params": C.Params, "nbmc_stats": C.Stats,
           "nbmc_mesh_check_result": C.MeshCheckResult, "nbmc_subdomain_stats": C.SubdomainStats,
           "nbmc_subdomain_entry": C.SubdomainEntry}


def test_struct_layouts(header, tmp_path):
    cc = shutil.which("cc") or shutil.which("gcc")
    if not cc:
        pytest.skip("no C compiler")
    fields = "\n".join(f"F({s}, {name})" for s, cls in STRUCTS.items() for name, _ in cls._fields_)
    src = tmp_path / "layout.c"
    src.write_text(LAYOUT_C.replace("%FIELDS%", fields))
    exe = tmp_path / "layout"
    subprocess.run([cc, "-std=c99", "-I", str(HEADER.parent), str(src), "-o", str(exe)], check=True)
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        struct, field, offset, size = line.split()
        cls = STRUCTS[struct]
        if field == "SIZE":
            assert ctypes.sizeof(cls) == int(offset), struct
        else:
            assert getattr(cls, field).offset == int(offset), (struct, field)
            assert getattr(cls, field).size == int(size), (struct, field)


def test_init_functions_fill_struct_size():
    for cls, init in [(C.ContextDesc, C.lib.nbmc_context_desc_init), (C.Params, C.lib.nbmc_params_init),
                      (C.Stats, C.lib.nbmc_stats_init), (C.SubdomainStats, C.lib.nbmc_subdomain_stats_init),
                      (C.SubdomainEntry, C.lib.nbmc_subdomain_entry_init)]:
        s = cls()
        init(ctypes.byref(s))
        assert s.struct_size == ctypes.sizeof(cls)


def test_stage_names():
    assert nbmc.STAGES == ("upload", "neighbourhood", "surface particles", "band", "field",
                           "triangulation", "output")
