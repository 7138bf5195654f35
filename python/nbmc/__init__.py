# SPDX-License-Identifier: MIT
"""nbmc — narrow-band marching cubes surface reconstruction of particle fluids.

A Python binding of libnbmc over its stable C ABI (ctypes; no compiled
extension). Quick start::

    import numpy as np, nbmc
    points = np.fromfile("examples/data/double_dam_break_4732.xyz", "<f4").reshape(-1, 3)
    mesh = nbmc.reconstruct(points, particle_radius=0.025)
    mesh.vertices, mesh.triangles, mesh.normals   # numpy views, no copies
    mesh.write("surface.ply")

For sequences, one :class:`Context` reuses its buffers across frames.
See docs/python.md.
"""
from __future__ import annotations

import warnings

from . import _capi
from ._arrays import DeviceArray
from ._capi import library_path
from ._core import (STAGES, Context, Frame, Mesh, Particles, Stats, defaults, frames,
                    read_particles, reconstruct)
from ._errors import (BackendUnavailable, Cancelled, DomainTooLarge, Error, FileError,
                      FormatError, InternalError, InvalidArgument, InvalidParameter,
                      InvalidParticles, MemoryBudgetExceeded, NoParticles, OutOfMemory)
from ._version import header_version

__all__ = [
    "reconstruct", "Context", "Mesh", "Stats", "DeviceArray", "Particles", "read_particles",
    "frames", "Frame", "defaults", "backends", "backend_available", "library_version",
    "library_version_string", "library_path", "STAGES", "Error", "InvalidArgument",
    "InvalidParticles", "NoParticles", "InvalidParameter", "DomainTooLarge", "OutOfMemory",
    "BackendUnavailable", "FileError", "InternalError", "MemoryBudgetExceeded", "Cancelled",
    "FormatError", "__version__",
]


def library_version() -> str:
    """"major.minor.patch" of the loaded libnbmc (``nbmc_version``)."""
    v = _capi.lib.nbmc_version()
    return f"{v // 10000}.{v // 100 % 100}.{v % 100}"


def library_version_string() -> str:
    """The library's version with its compiled-in backends (``nbmc_version_string``)."""
    return _capi.text(_capi.lib.nbmc_version_string())


def backend_available(backend: str) -> bool:
    """True if the backend ("serial", "openmp", "cuda", "auto") is compiled in and usable."""
    from ._core import BACKENDS, _enum
    return bool(_capi.lib.nbmc_backend_available(_enum(BACKENDS, backend, "backend")))


def backends() -> list:
    """The backends usable on this machine, e.g. ["serial", "openmp"]."""
    return [b for b in ("serial", "openmp", "cuda") if backend_available(b)]


#: The package's version: that of the nbmc.h it was built against (which must
#: match the loaded library; a different major version refuses to load).
__version__: str = header_version() or library_version()

if __version__.split(".")[0] != library_version().split(".")[0]:
    raise ImportError(f"nbmc {__version__} cannot use libnbmc {library_version()} "
                      f"({library_path}): the major versions differ")
if __version__ != library_version():
    warnings.warn(f"nbmc Python package {__version__} runs with libnbmc {library_version()} "
                  f"({library_path})", RuntimeWarning, stacklevel=2)
