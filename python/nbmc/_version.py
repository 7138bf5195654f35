# SPDX-License-Identifier: MIT
"""The package version: the NBMC_VERSION_* macros of the nbmc.h it was built
against (recorded by setup.py in _build_info.py), or, in a source checkout,
of <repo>/include/nbmc.h."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Optional


def parse_header(text: str) -> Optional[str]:
    """"major.minor.patch" from the NBMC_VERSION_* macros of nbmc.h."""
    parts = []
    for name in ("MAJOR", "MINOR", "PATCH"):
        m = re.search(r"^\s*#\s*define\s+NBMC_VERSION_" + name + r"\s+(\d+)", text, re.M)
        if not m:
            return None
        parts.append(m.group(1))
    return ".".join(parts)


def header_version() -> Optional[str]:
    try:
        from . import _build_info
        return _build_info.VERSION
    except ImportError:
        pass
    header = Path(__file__).resolve().parent.parent.parent / "include" / "nbmc.h"
    try:
        return parse_header(header.read_text())
    except OSError:
        return None
