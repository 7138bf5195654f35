# SPDX-License-Identifier: MIT
"""ctypes declarations of include/nbmc.h and the loader of libnbmc.

Everything here mirrors the header by hand, as the Rust ``nbmc-sys`` crate
does; ``tests/test_abi.py`` checks the constants and the struct layouts
against the installed header with the C compiler.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
from ctypes import (CFUNCTYPE, POINTER, Structure, c_char_p, c_double, c_int32,
                    c_int64, c_uint32, c_uint64, c_void_p)
from pathlib import Path
from typing import List, Optional

# ------------------------------------------------------------------ status
OK = 0
ERROR_INVALID_ARGUMENT = 1
ERROR_INVALID_PARTICLES = 2
ERROR_NO_PARTICLES = 3
ERROR_INVALID_PARAMETER = 4
ERROR_DOMAIN_TOO_LARGE = 5
ERROR_OUT_OF_MEMORY = 6
ERROR_BACKEND_UNAVAILABLE = 7
ERROR_IO = 8
ERROR_INTERNAL = 9
ERROR_MEMORY_BUDGET = 10
ERROR_CANCELLED = 11
ERROR_FORMAT = 12

# --------------------------------------------------------------- constants
BACKEND_AUTO = 0
BACKEND_SERIAL = 1
BACKEND_OPENMP = 2
BACKEND_CUDA = 3

METHOD_SSP07 = 0
METHOD_ZB05 = 1
METHOD_SPH = 2
METHOD_YT10 = 3

ISOLATED_KEEP = 0
ISOLATED_DROP = 1
ISOLATED_SPHERE = 2

SMOOTH_UNIFORM = 0
SMOOTH_FEATURE = 1

FIELD_NARROW_BAND = 0
FIELD_DENSE = 1
FIELD_SCATTER = 2

CONTEXT_KOKKOS_ON_CALLING_THREAD = 1

MEMORY_HOST = 0
MEMORY_DEVICE = 1

UNIT_SPACING = 0
UNIT_ABSOLUTE = 1

STAGE_UPLOAD = 0
STAGE_NEIGHBOURHOOD = 1
STAGE_SURFACE_PARTICLES = 2
STAGE_BAND = 3
STAGE_FIELD = 4
STAGE_TRIANGULATION = 5
STAGE_OUTPUT = 6
STAGE_COUNT = 7
STAGE_SLOTS = 16
STAGE_POSTPROCESS = 7
STAGE_ATTRIBUTES = 8
SUBDOMAINS_AUTO = -1


# ----------------------------------------------------------------- structs
class ContextDesc(Structure):
    _fields_ = [
        ("struct_size", c_uint32),
        ("backend", c_int32),
        ("num_threads", c_int32),
        ("device_id", c_int32),
        ("flags", c_uint32),
        ("reserved0", c_uint32),
    ]


class Params(Structure):
    _fields_ = [
        ("struct_size", c_uint32),
        ("length_unit", c_int32),
        ("spacing", c_double),
        ("cell_size", c_double),
        ("influence_radius", c_double),
        ("band_width", c_double),
        ("surface_radius", c_double),
        ("iso_radius", c_double),
        ("method", c_int32),
        ("field", c_int32),
        ("t_low", c_double),
        ("t_high", c_double),
        ("color_threshold", c_double),
        ("neighbour_threshold", c_int32),
        ("compute_normals", c_int32),
        ("use_bbox", c_int32),
        ("reserved0", c_int32),
        ("bbox_min", c_double * 3),
        ("bbox_max", c_double * 3),
        # appended with the mesh post-processing (nbmc_params_init writes them)
        ("cleanup", c_int32),
        ("smooth_iterations", c_int32),
        # appended with METHOD_SPH
        ("iso_threshold", c_double),
        # appended with the isolated-particle filter
        ("isolated", c_int32),
        ("min_cluster", c_int32),
        # appended with double-precision positions
        ("double_positions", c_int32),
        # appended with decimation and feature-weighted smoothing
        ("decimate_fraction", c_double),
        ("smooth_weighting", c_int32),
        ("reserved1", c_int32),
        # appended with METHOD_YT10
        ("aniso_kr", c_double),
        ("aniso_ks", c_double),
        ("aniso_kn", c_double),
        ("aniso_lambda", c_double),
        ("aniso_neighbours", c_int32),
        ("reserved2", c_int32),
        # appended with the distance guard
        ("max_distance", c_double),
    ]


class Stats(Structure):
    _fields_ = [
        ("struct_size", c_uint32),
        ("reserved0", c_uint32),
        ("particle_count", c_uint64),
        ("surface_particle_count", c_uint64),
        ("occupied_cell_count", c_uint64),
        ("band_vertex_count", c_uint64),
        ("band_block_count", c_uint64),
        ("grid_vertex_count", c_uint64),
        ("triangulated_cell_count", c_uint64),
        ("vertex_count", c_uint64),
        ("triangle_count", c_uint64),
        ("grid_dims", c_uint64 * 3),
        ("peak_memory_bytes", c_uint64),
        ("neighbour_evaluations", c_uint64),
        ("stage_seconds", c_double * STAGE_SLOTS),
        ("total_seconds", c_double),
        ("grid_origin", c_double * 3),
        ("cell_size", c_double),
        # appended with the mesh post-processing
        ("raw_triangle_count", c_uint64),
        ("smoothing_volume_change", c_double),
        # appended with the isolated-particle filter
        ("dropped_particle_count", c_uint64),
        ("dropped_cluster_count", c_uint64),
        # appended with decimation
        ("pre_decimation_triangle_count", c_uint64),
        # appended with the clean-up's counts
        ("cleanup_bad_triangles_before", c_uint64),
        ("cleanup_bad_triangles_after", c_uint64),
        ("cleanup_moves", c_uint64),
        ("cleanup_flips", c_uint64),
        ("cleanup_collapses", c_uint64),
        ("cleanup_cuts", c_uint64),
        ("cleanup_removed_component_triangles", c_uint64),
    ]


class MeshCheckResult(Structure):
    _fields_ = [
        ("struct_size", c_uint32),
        ("closed", c_int32),
        ("manifold", c_int32),
        ("oriented", c_int32),
        ("vertex_count", c_uint64),
        ("triangle_count", c_uint64),
        ("edge_count", c_uint64),
        ("boundary_edge_count", c_uint64),
        ("nonmanifold_edge_count", c_uint64),
        ("misoriented_edge_count", c_uint64),
        ("nonmanifold_vertex_count", c_uint64),
        ("unreferenced_vertex_count", c_uint64),
        ("degenerate_triangle_count", c_uint64),
        ("sliver_triangle_count", c_uint64),
        ("component_count", c_uint64),
        ("euler_characteristic", c_int64),
        ("volume", c_double),
        ("area", c_double),
        ("min_angle_degrees", c_double),
    ]


class SubdomainStats(Structure):
    _fields_ = [
        ("struct_size", c_uint32),
        ("parts", c_int32 * 3),
        ("count", c_uint64),
        ("automatic", c_uint32),
        ("reserved", c_uint32),
        ("ghost_width", c_double),
        ("ghost_particles", c_uint64),
        ("reruns", c_uint64),
        ("exchanged_cells", c_uint64),
        ("shared_vertices", c_uint64),
        ("budget_bytes", c_uint64),
        ("stitch_seconds", c_double),
    ]


class SubdomainEntry(Structure):
    _fields_ = [
        ("struct_size", c_uint32),
        ("coord", c_int32 * 3),
        ("cell_lo", c_int64 * 3),
        ("cell_hi", c_int64 * 3),
        ("particles", c_uint64),
        ("ghost_particles", c_uint64),
        ("vertex_count", c_uint64),
        ("triangle_count", c_uint64),
        ("runs", c_uint32),
        ("rank", c_int32),
        ("seconds", c_double),
    ]


PROGRESS_FN = CFUNCTYPE(c_int32, c_void_p, c_int32, c_double)

_ctx_p = c_void_p
_mesh_p = c_void_p

# name: (restype, argtypes)
_SIGNATURES = {
    "nbmc_version": (c_uint32, []),
    "nbmc_version_string": (c_char_p, []),
    "nbmc_status_string": (c_char_p, [c_int32]),
    "nbmc_stage_name": (c_char_p, [c_int32]),
    "nbmc_backend_available": (c_int32, [c_int32]),
    "nbmc_context_desc_init": (None, [POINTER(ContextDesc)]),
    "nbmc_context_create": (c_int32, [POINTER(ContextDesc), POINTER(_ctx_p)]),
    "nbmc_context_destroy": (None, [_ctx_p]),
    "nbmc_context_last_error": (c_char_p, [_ctx_p]),
    "nbmc_context_backend": (c_int32, [_ctx_p, POINTER(c_int32)]),
    "nbmc_context_set_particles_f32": (c_int32, [_ctx_p, c_void_p, c_uint64, c_uint64]),
    "nbmc_context_set_particles_f64": (c_int32, [_ctx_p, c_void_p, c_uint64, c_uint64]),
    "nbmc_context_set_particles_device_f32": (c_int32, [_ctx_p, c_void_p, c_uint64, c_uint64]),
    "nbmc_context_set_particles_device_f64": (c_int32, [_ctx_p, c_void_p, c_uint64, c_uint64]),
    "nbmc_context_set_mesh_memory": (c_int32, [_ctx_p, c_int32]),
    "nbmc_context_set_progress": (c_int32, [_ctx_p, PROGRESS_FN, c_void_p]),
    "nbmc_context_set_memory_budget": (c_int32, [_ctx_p, c_uint64]),
    "nbmc_params_init": (None, [POINTER(Params)]),
    "nbmc_context_reconstruct": (c_int32, [_ctx_p, POINTER(Params), POINTER(_mesh_p)]),
    "nbmc_stats_init": (None, [POINTER(Stats)]),
    "nbmc_context_stats": (c_int32, [_ctx_p, POINTER(Stats)]),
    "nbmc_mesh_vertex_count": (c_uint64, [_mesh_p]),
    "nbmc_mesh_triangle_count": (c_uint64, [_mesh_p]),
    "nbmc_mesh_positions": (c_void_p, [_mesh_p]),
    "nbmc_mesh_positions_f64": (c_void_p, [_mesh_p]),
    "nbmc_mesh_sphere_count": (c_uint64, [_mesh_p]),
    "nbmc_mesh_spheres": (c_void_p, [_mesh_p]),
    "nbmc_mesh_normals": (c_void_p, [_mesh_p]),
    "nbmc_mesh_triangles": (c_void_p, [_mesh_p]),
    "nbmc_mesh_destroy": (None, [_mesh_p]),
    "nbmc_mesh_memory": (c_int32, [_mesh_p]),
    "nbmc_mesh_copy_to_host": (c_int32, [_mesh_p, c_void_p, c_void_p, c_void_p]),
    "nbmc_context_load_particles": (c_int32, [_ctx_p, c_char_p, c_char_p, POINTER(c_uint64)]),
    "nbmc_mesh_write": (c_int32, [_mesh_p, c_char_p, c_char_p]),
    "nbmc_last_error": (c_char_p, []),
    "nbmc_kokkos_finalize": (c_int32, []),
    "nbmc_mesh_check_result_init": (None, [POINTER(MeshCheckResult)]),
    "nbmc_mesh_check": (c_int32, [_mesh_p, POINTER(MeshCheckResult)]),
    "nbmc_context_set_subdomains": (c_int32, [_ctx_p, c_int32, c_int32, c_int32]),
    "nbmc_subdomain_stats_init": (None, [POINTER(SubdomainStats)]),
    "nbmc_subdomain_entry_init": (None, [POINTER(SubdomainEntry)]),
    "nbmc_context_subdomain_stats": (c_int32, [_ctx_p, POINTER(SubdomainStats)]),
    "nbmc_context_subdomain_entry": (c_int32, [_ctx_p, c_uint64, POINTER(SubdomainEntry)]),
    "nbmc_mesh_global_vertex_ids": (c_void_p, [_mesh_p]),
    "nbmc_mesh_global_vertex_count": (c_uint64, [_mesh_p]),
    "nbmc_context_set_attribute_f32": (c_int32, [_ctx_p, c_char_p, c_void_p, c_uint32, c_uint64]),
    "nbmc_context_set_attribute_f64": (c_int32, [_ctx_p, c_char_p, c_void_p, c_uint32, c_uint64]),
    "nbmc_context_set_attribute_device_f32": (c_int32, [_ctx_p, c_char_p, c_void_p, c_uint32, c_uint64]),
    "nbmc_context_set_attribute_device_f64": (c_int32, [_ctx_p, c_char_p, c_void_p, c_uint32, c_uint64]),
    "nbmc_mesh_attribute_count": (c_uint32, [_mesh_p]),
    "nbmc_mesh_attribute_name": (c_char_p, [_mesh_p, c_uint32]),
    "nbmc_mesh_attribute": (c_void_p, [_mesh_p, c_char_p, POINTER(c_uint32)]),
    "nbmc_context_set_radii_f32": (c_int32, [_ctx_p, c_void_p, c_uint64, c_uint64]),
    "nbmc_context_set_radii_f64": (c_int32, [_ctx_p, c_void_p, c_uint64, c_uint64]),
    "nbmc_context_set_radii_device_f32": (c_int32, [_ctx_p, c_void_p, c_uint64, c_uint64]),
    "nbmc_context_set_radii_device_f64": (c_int32, [_ctx_p, c_void_p, c_uint64, c_uint64]),
}

_NAMES = ("libnbmc.so.0", "libnbmc.so") if sys.platform.startswith("linux") else (
    ("libnbmc.0.dylib", "libnbmc.dylib") if sys.platform == "darwin" else ("nbmc.dll",))


def _build_library_dirs() -> List[str]:
    try:
        from . import _build_info  # written by setup.py
        return list(getattr(_build_info, "LIBRARY_DIRS", []))
    except ImportError:
        return []


def candidates() -> List[str]:
    """Where libnbmc is looked for, in order (see docs/python.md)."""
    out: List[str] = []
    env = os.environ.get("NBMC_LIBRARY")
    if env:
        p = Path(env)
        if p.is_dir():
            out += [str(p / n) for n in _NAMES]
        else:
            out.append(env)
        return out  # an explicit choice is not second-guessed
    here = Path(__file__).resolve().parent
    dirs = [here]  # a bundled copy next to the package
    dirs += [Path(d) for d in _build_library_dirs()]  # the prefix given at install time
    dirs.append(here.parent.parent / "build" / "install" / "lib")  # running from the source tree
    for d in dirs:
        out += [str(d / n) for n in _NAMES]
    found = ctypes.util.find_library("nbmc")  # ldconfig, LD_LIBRARY_PATH, ...
    if found:
        out.append(found)
    out += list(_NAMES)  # whatever dlopen's own search finds
    return out


def _load() -> ctypes.CDLL:
    tried = []
    env = os.environ.get("NBMC_LIBRARY")
    for c in candidates():
        if os.sep in c and not os.path.exists(c):
            tried.append(f"{c} (no such file)")
            continue
        try:
            lib = ctypes.CDLL(c)
        except OSError as e:
            tried.append(f"{c} ({e})")
            continue
        lib._nbmc_path = c  # type: ignore[attr-defined]
        return lib
    where = "NBMC_LIBRARY=" + env if env else "the usual places"
    raise ImportError(
        "nbmc: cannot load libnbmc from " + where + ". Set NBMC_LIBRARY to the library "
        "(e.g. <repo>/build/install/lib/libnbmc.so) or reinstall the package with "
        "scripts/setup_python.sh PREFIX. Tried:\n  " + "\n  ".join(tried))


def _declare(lib: ctypes.CDLL) -> ctypes.CDLL:
    for name, (restype, argtypes) in _SIGNATURES.items():
        fn = getattr(lib, name)
        fn.restype = restype
        fn.argtypes = argtypes
    return lib


lib = _declare(_load())
#: path of the loaded library
library_path: str = getattr(lib, "_nbmc_path")


def text(p: Optional[bytes]) -> str:
    return p.decode("utf-8", "replace") if p else ""
