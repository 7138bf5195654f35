# SPDX-License-Identifier: MIT
"""Contexts, meshes, particle files and sequences over the C ABI."""

import dataclasses
import inspect
import os
import re
import threading
import weakref
from ctypes import byref, c_int32, c_uint32, c_uint64, c_void_p
from typing import (Any, Callable, Dict, Iterable, Iterator, Mapping, NamedTuple, Optional, Sequence,
                    Tuple, Union)

import numpy as np

from . import _arrays as A
from . import _capi as C
from ._errors import Cancelled, error_for

lib = C.lib

PathLike = Union[str, os.PathLike]
#: ``progress(stage, fraction)``: stage name ("upload", "field", ...) and the
#: fraction of it done; a true return value cancels the reconstruction.
ProgressFn = Callable[[str, float], Any]

BACKENDS = {"auto": C.BACKEND_AUTO, "serial": C.BACKEND_SERIAL, "openmp": C.BACKEND_OPENMP,
            "cuda": C.BACKEND_CUDA}
METHODS = {"ssp07": C.METHOD_SSP07, "zb05": C.METHOD_ZB05, "sph": C.METHOD_SPH, "yt10": C.METHOD_YT10}
FIELDS = {"narrow-band": C.FIELD_NARROW_BAND, "dense": C.FIELD_DENSE, "scatter": C.FIELD_SCATTER}
UNITS = {"spacing": C.UNIT_SPACING, "absolute": C.UNIT_ABSOLUTE}
ISOLATED = {"keep": C.ISOLATED_KEEP, "drop": C.ISOLATED_DROP, "sphere": C.ISOLATED_SPHERE}
SMOOTH_WEIGHTS = {"uniform": C.SMOOTH_UNIFORM, "feature": C.SMOOTH_FEATURE}
MEMORIES = {"host": C.MEMORY_HOST, "device": C.MEMORY_DEVICE}


def _name_of(table: Dict[str, int], value: int) -> str:
    for k, v in table.items():
        if v == value:
            return k
    return str(value)


def _enum(table: Dict[str, int], value: Union[str, int], what: str) -> int:
    """A name from table (case-insensitive, '_' for '-'), or an int passed
    through for the library to judge."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return int(value)
    key = str(value).lower().replace("_", "-")
    if key not in table:
        raise ValueError(f"unknown {what} {value!r}; choose one of {', '.join(table)}")
    return table[key]


STAGES: Tuple[str, ...] = tuple(C.text(lib.nbmc_stage_name(i)) for i in range(C.STAGE_COUNT))


def stage_name(stage: int) -> str:
    """Name of a pipeline stage (``nbmc_stage_name``)."""
    return STAGES[stage] if 0 <= stage < len(STAGES) else f"stage {stage}"


# ---------------------------------------------------------------- parameters
# Keyword arguments of reconstruct() that map onto nbmc_params, named like the
# CLI's options (--cell-size -> cell_size); 'normals' is the inverse of --no-normals.
_LENGTHS = ("cell_size", "influence_radius", "band_width", "surface_radius", "iso_radius", "max_distance")
_ANISO = ("aniso_kr", "aniso_ks", "aniso_kn", "aniso_lambda")
_PARAM_KEYS = _LENGTHS + ("method", "field", "t_low", "t_high", "iso_threshold", "color_threshold",
                          "neighbour_threshold", "normals", "length_unit", "isolated", "min_cluster",
                          "double_positions", "cleanup", "smooth", "smooth_weights", "decimate") + _ANISO + (
                              "aniso_neighbours",)


def defaults() -> Dict[str, Any]:
    """The library's default parameters (``nbmc_params_init``), by keyword name.

    Lengths are multiples of the spacing (``length_unit="spacing"``).
    """
    p = C.Params()
    lib.nbmc_params_init(byref(p))
    d: Dict[str, Any] = {k: p.__getattribute__(k) for k in _LENGTHS}
    d.update(method=_name_of(METHODS, p.method), field=_name_of(FIELDS, p.field), t_low=p.t_low,
             t_high=p.t_high, iso_threshold=p.iso_threshold, color_threshold=p.color_threshold,
             neighbour_threshold=p.neighbour_threshold, normals=bool(p.compute_normals),
             length_unit=_name_of(UNITS, p.length_unit),
             isolated=_name_of(ISOLATED, p.isolated), min_cluster=p.min_cluster,
             double_positions=bool(p.double_positions), cleanup=bool(p.cleanup),
             smooth=p.smooth_iterations, smooth_weights=_name_of(SMOOTH_WEIGHTS, p.smooth_weighting),
             decimate=p.decimate_fraction, aniso_neighbours=p.aniso_neighbours)
    d.update({k: p.__getattribute__(k) for k in _ANISO})
    return d


def _bbox(bbox: Any) -> Tuple[Sequence[float], Sequence[float]]:
    b = np.asarray(bbox, dtype=np.float64)
    if b.shape == (6,):
        return b[:3], b[3:]
    if b.shape == (2, 3):
        return b[0], b[1]
    raise ValueError("bbox must be (xmin, ymin, zmin, xmax, ymax, zmax) or "
                     f"((xmin, ymin, zmin), (xmax, ymax, zmax)), not shape {b.shape}")


def make_params(spacing: Optional[float] = None, particle_radius: Optional[float] = None,
                bbox: Any = None, **kw: Any) -> C.Params:
    """nbmc_params from keyword arguments; None means the library default."""
    unknown = set(kw) - set(_PARAM_KEYS)
    if unknown:
        raise TypeError(f"unknown parameter(s) {', '.join(sorted(unknown))}; "
                        f"known: spacing, particle_radius, bbox, {', '.join(_PARAM_KEYS)}")
    if (spacing is None) == (particle_radius is None):
        raise TypeError("give the particle spacing: spacing=r or particle_radius=r/2 (one of them)")
    p = C.Params()
    lib.nbmc_params_init(byref(p))
    p.spacing = float(spacing) if spacing is not None else 2.0 * float(particle_radius)  # type: ignore[arg-type]
    for k in _LENGTHS + ("t_low", "t_high", "iso_threshold", "color_threshold") + _ANISO:
        if kw.get(k) is not None:
            setattr(p, k, float(kw[k]))
    if kw.get("neighbour_threshold") is not None:
        p.neighbour_threshold = int(kw["neighbour_threshold"])
    if kw.get("aniso_neighbours") is not None:
        p.aniso_neighbours = int(kw["aniso_neighbours"])
    if kw.get("isolated") is not None:
        p.isolated = _enum(ISOLATED, kw["isolated"], "isolated")
    if kw.get("min_cluster") is not None:
        p.min_cluster = int(kw["min_cluster"])
    if kw.get("method") is not None:
        p.method = _enum(METHODS, kw["method"], "method")
    if kw.get("field") is not None:
        p.field = _enum(FIELDS, kw["field"], "field")
    if kw.get("length_unit") is not None:
        p.length_unit = _enum(UNITS, kw["length_unit"], "length_unit")
    if kw.get("normals") is not None:
        p.compute_normals = 1 if kw["normals"] else 0
    if kw.get("double_positions") is not None:
        p.double_positions = 1 if kw["double_positions"] else 0
    if kw.get("cleanup") is not None:
        p.cleanup = 1 if kw["cleanup"] else 0
    if kw.get("smooth") is not None:
        p.smooth_iterations = int(kw["smooth"])
    if kw.get("smooth_weights") is not None:
        p.smooth_weighting = _enum(SMOOTH_WEIGHTS, kw["smooth_weights"], "smooth_weights")
    if kw.get("decimate") is not None:
        p.decimate_fraction = float(kw["decimate"])
    if bbox is not None:
        lo, hi = _bbox(bbox)
        p.use_bbox = 1
        p.bbox_min[:] = [float(v) for v in lo]
        p.bbox_max[:] = [float(v) for v in hi]
    return p


def parse_bytes(value: Union[int, str, None]) -> int:
    """A memory budget: bytes as an int, or a string like the CLI's ("4G", "512M", "64k")."""
    if value is None:
        return 0
    if isinstance(value, (int, np.integer)):
        if value < 0:
            raise ValueError("memory_budget must be >= 0")
        return int(value)
    m = re.fullmatch(r"\s*(\d+(?:\.\d*)?)\s*([kKmMgGtT]?)(?:i?[bB])?\s*", str(value))
    if not m:
        raise ValueError(f"memory_budget {value!r} is not a size like 4G, 512M or 1000000")
    scale = {"": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}[m.group(2).lower()]
    return int(float(m.group(1)) * scale)


# --------------------------------------------------------------------- stats
@dataclasses.dataclass(frozen=True)
class Stats:
    """Figures of one reconstruction (``nbmc_stats``)."""

    particle_count: int
    surface_particle_count: int
    occupied_cell_count: int
    band_vertex_count: int
    band_block_count: int
    grid_vertex_count: int
    triangulated_cell_count: int
    vertex_count: int
    triangle_count: int
    grid_dims: Tuple[int, int, int]
    peak_memory_bytes: int
    neighbour_evaluations: int
    #: wall time per stage in seconds, by stage name, in pipeline order
    stage_seconds: Dict[str, float]
    total_seconds: float
    grid_origin: Tuple[float, float, float]
    #: absolute marching-cubes cell edge
    cell_size: float
    #: particles left out by ``isolated="drop"``, and the clusters they formed
    dropped_particle_count: int = 0
    dropped_cluster_count: int = 0
    #: triangles before ``decimate`` (``triangle_count`` without it)
    pre_decimation_triangle_count: int = 0
    #: triangles of the marching-cubes mesh, before the clean-up
    raw_triangle_count: int = 0
    #: the clean-up's counts (all 0 with ``cleanup=False``; summed over its
    #: two runs with smoothing): bad (degenerate + sliver) triangles it found
    #: and left, its repairs, and the triangles removed with whole bad
    #: components; ``raw_triangle_count - pre_decimation_triangle_count ==
    #: 2 * cleanup_collapses + 6 * cleanup_cuts +
    #: cleanup_removed_component_triangles``
    cleanup_bad_triangles_before: int = 0
    cleanup_bad_triangles_after: int = 0
    cleanup_moves: int = 0
    cleanup_flips: int = 0
    cleanup_collapses: int = 0
    cleanup_cuts: int = 0
    cleanup_removed_component_triangles: int = 0

    @classmethod
    def _from_c(cls, s: C.Stats) -> "Stats":
        return cls(
            particle_count=s.particle_count, surface_particle_count=s.surface_particle_count,
            occupied_cell_count=s.occupied_cell_count, band_vertex_count=s.band_vertex_count,
            band_block_count=s.band_block_count, grid_vertex_count=s.grid_vertex_count,
            triangulated_cell_count=s.triangulated_cell_count, vertex_count=s.vertex_count,
            triangle_count=s.triangle_count, grid_dims=tuple(s.grid_dims),  # type: ignore[arg-type]
            peak_memory_bytes=s.peak_memory_bytes, neighbour_evaluations=s.neighbour_evaluations,
            stage_seconds={STAGES[i]: s.stage_seconds[i] for i in range(C.STAGE_COUNT)},
            total_seconds=s.total_seconds, grid_origin=tuple(s.grid_origin),  # type: ignore[arg-type]
            cell_size=s.cell_size, dropped_particle_count=s.dropped_particle_count,
            dropped_cluster_count=s.dropped_cluster_count,
            pre_decimation_triangle_count=s.pre_decimation_triangle_count,
            raw_triangle_count=s.raw_triangle_count,
            cleanup_bad_triangles_before=s.cleanup_bad_triangles_before,
            cleanup_bad_triangles_after=s.cleanup_bad_triangles_after,
            cleanup_moves=s.cleanup_moves, cleanup_flips=s.cleanup_flips,
            cleanup_collapses=s.cleanup_collapses, cleanup_cuts=s.cleanup_cuts,
            cleanup_removed_component_triangles=s.cleanup_removed_component_triangles)


# ---------------------------------------------------------------------- mesh
class _MeshHandle:
    """Owns one nbmc_mesh; every array view holds a reference to it."""

    __slots__ = ("ptr", "memory", "device_id", "__weakref__")

    def __init__(self, ptr: int, device_id: int) -> None:
        self.ptr = ptr
        self.memory = lib.nbmc_mesh_memory(ptr)
        self.device_id = device_id

    def __del__(self, _destroy=lib.nbmc_mesh_destroy) -> None:
        if self.ptr:
            _destroy(self.ptr)
            self.ptr = None

    def copy_to_host(self, which: str) -> np.ndarray:
        n = lib.nbmc_mesh_triangle_count(self.ptr) if which == "triangles" else \
            lib.nbmc_mesh_vertex_count(self.ptr)
        out = np.empty((n, 3), dtype=np.uint32 if which == "triangles" else np.float32)
        ptrs = {"vertices": None, "normals": None, "triangles": None}
        ptrs[which] = out.ctypes.data
        status = lib.nbmc_mesh_copy_to_host(self.ptr, ptrs["vertices"], ptrs["normals"],
                                            ptrs["triangles"])
        if status:
            raise error_for(status, "nbmc_mesh_copy_to_host failed")
        return out


class Mesh:
    """A triangle mesh made by nbmc. Immutable; independent of its context.

    ``vertices`` (V, 3) float32, ``normals`` (V, 3) float32 or None, and
    ``triangles`` (T, 3) uint32 (counter-clockwise seen from outside the
    fluid) are read-only numpy views of nbmc's memory, without a copy, that
    stay valid as long as any of them (or the mesh) is referenced. A mesh left
    on the GPU (``mesh_memory="device"``) gives :class:`DeviceArray` objects
    instead, which expose ``__cuda_array_interface__`` and ``__dlpack__``.
    """

    def __init__(self, handle: _MeshHandle, stats: Optional[Stats]) -> None:
        self._h = handle
        self._cache: Dict[str, Any] = {}
        #: figures of the reconstruction that made this mesh (counts, grid, timings)
        self.stats = stats

    @property
    def vertex_count(self) -> int:
        return int(lib.nbmc_mesh_vertex_count(self._h.ptr))

    @property
    def triangle_count(self) -> int:
        return int(lib.nbmc_mesh_triangle_count(self._h.ptr))

    @property
    def memory(self) -> str:
        """"host" or "device" (CUDA memory of the context's GPU)."""
        return _name_of(MEMORIES, self._h.memory)

    @property
    def has_normals(self) -> bool:
        """False without normals (``normals=False``) and for an empty mesh."""
        return bool(lib.nbmc_mesh_normals(self._h.ptr))

    def _array(self, which: str, getter: Callable[[int], Optional[int]], rows: int, dtype: Any):
        if which not in self._cache:
            ptr = getter(self._h.ptr)
            if which == "normals" and not ptr and rows:
                self._cache[which] = None
            elif self._h.memory == C.MEMORY_DEVICE:
                self._cache[which] = A.DeviceArray(ptr or 0, (rows, 3), dtype, self._h.device_id,
                                                   self._h, which)
            else:
                self._cache[which] = A.host_view(ptr or 0, (rows, 3), dtype, self._h)
        return self._cache[which]

    @property
    def double_positions(self) -> bool:
        """True when the mesh was made with ``double_positions=True``: its
        ``vertices`` are float64."""
        return bool(lib.nbmc_mesh_positions_f64(self._h.ptr))

    @property
    def vertices(self) -> Union[np.ndarray, A.DeviceArray]:
        """(V, 3) vertex positions (a view, no copy): float32, or float64 for a
        mesh made with ``double_positions=True`` (``nbmc_mesh_positions_f64``)."""
        if self.double_positions:
            return self._array("vertices", lib.nbmc_mesh_positions_f64, self.vertex_count, np.float64)
        return self._array("vertices", lib.nbmc_mesh_positions, self.vertex_count, np.float32)

    @property
    def spheres(self) -> np.ndarray:
        """``isolated="sphere"``: the particles of the dropped clusters as
        spheres, (S, 4) float32 x, y, z, radius (a read-only view in host
        memory, in the particles' order); (0, 4) otherwise."""
        if "spheres" not in self._cache:
            n = int(lib.nbmc_mesh_sphere_count(self._h.ptr))
            self._cache["spheres"] = A.host_view(lib.nbmc_mesh_spheres(self._h.ptr) or 0, (n, 4), np.float32,
                                                 self._h)
        return self._cache["spheres"]

    @property
    def normals(self) -> Union[np.ndarray, A.DeviceArray, None]:
        """(V, 3) float32 unit normals pointing out of the fluid, or None when
        the mesh was made with ``normals=False``."""
        return self._array("normals", lib.nbmc_mesh_normals, self.vertex_count, np.float32)

    @property
    def triangles(self) -> Union[np.ndarray, A.DeviceArray]:
        """(T, 3) uint32 vertex indices per triangle (a view, no copy)."""
        return self._array("triangles", lib.nbmc_mesh_triangles, self.triangle_count, np.uint32)

    @property
    def attributes(self) -> Dict[str, np.ndarray]:
        """Particle attributes interpolated onto the vertices
        (:meth:`Context.set_attribute`): name -> read-only float32 view of
        shape (V,) for a scalar or (V, 3) for a vector, in host memory for
        every mesh (``nbmc_mesh_attribute``); ``{}`` without attributes."""
        if "attributes" not in self._cache:
            out: Dict[str, np.ndarray] = {}
            nv = self.vertex_count
            for i in range(int(lib.nbmc_mesh_attribute_count(self._h.ptr))):
                raw = lib.nbmc_mesh_attribute_name(self._h.ptr, i)
                comps = c_uint32(0)
                ptr = lib.nbmc_mesh_attribute(self._h.ptr, raw, byref(comps))
                shape = (nv,) if comps.value == 1 else (nv, int(comps.value))
                out[raw.decode("utf-8", "replace")] = A.host_view(ptr or 0, shape, np.float32, self._h)
            self._cache["attributes"] = out
        return dict(self._cache["attributes"])

    @property
    def timings(self) -> Dict[str, float]:
        """Seconds per pipeline stage, plus "total" (from :attr:`stats`)."""
        if self.stats is None:
            return {}
        return {**self.stats.stage_seconds, "total": self.stats.total_seconds}

    def to_host(self) -> Tuple[np.ndarray, Optional[np.ndarray], np.ndarray]:
        """Copies (vertices, normals, triangles) into new numpy arrays, from
        host or device memory (``nbmc_mesh_copy_to_host``)."""
        v = self._h.copy_to_host("vertices")
        n = self._h.copy_to_host("normals") if lib.nbmc_mesh_normals(self._h.ptr) else None
        t = self._h.copy_to_host("triangles")
        return v, n, t

    def write(self, path: PathLike, format: Optional[str] = None) -> None:
        """Writes the mesh with nbmc's writers: "ply" (binary), "obj", "vtk"
        (legacy), "vtu" or "glb"; by default from the extension. The file
        appears complete or not at all (written under a temporary name)."""
        fmt = format.encode() if format else None
        status = lib.nbmc_mesh_write(self._h.ptr, os.fsencode(path), fmt)
        if status:
            raise error_for(status, C.text(lib.nbmc_last_error()))

    def __repr__(self) -> str:
        return (f"<nbmc.Mesh {self.vertex_count} vertices, {self.triangle_count} triangles, "
                f"{'normals, ' if self.has_normals else ''}{self.memory}>")


class Frame(NamedTuple):
    """One file of a sequence: its number, the digits as in the name
    (zero padding kept, for output names) and its path."""

    number: int
    label: str
    path: str

    def output(self, pattern: PathLike) -> str:
        """pattern with ``{}`` replaced by this frame's digits."""
        return os.fspath(pattern).replace("{}", self.label)


# ------------------------------------------------------------------- context
def _interruptible(call: Callable[[], int], on_interrupt: Callable[[], None]) -> int:
    """Runs call() (a blocking foreign call; ctypes releases the GIL) so that
    Ctrl-C reaches it: on the main thread it runs in a helper thread while the
    main thread waits where Python can raise KeyboardInterrupt; then
    on_interrupt() asks the library to stop, the call is awaited and the
    exception re-raised. Elsewhere (no signals there) it runs directly."""
    if threading.current_thread() is not threading.main_thread():
        return call()
    result: Dict[str, Any] = {}
    done = threading.Event()

    def worker() -> None:
        try:
            result["status"] = call()
        except BaseException as e:  # noqa: BLE001 - handed to the waiting thread
            result["error"] = e
        finally:
            done.set()

    threading.Thread(target=worker, name="nbmc-call", daemon=True).start()
    try:
        while not done.wait(0.5):
            pass
    except BaseException:
        on_interrupt()
        while True:  # the library stops at its next progress report
            try:
                done.wait()
                break
            except BaseException:  # noqa: BLE001 - a second Ctrl-C while stopping
                continue
        raise
    if "error" in result:
        raise result["error"]
    return result["status"]


class Context:
    """A reconstruction context: a backend, uploaded particles, reusable
    buffers. Use one per sequence of frames so that buffers are reused.

    ``backend``: "auto" (CUDA if available, else OpenMP, else serial),
    "serial", "openmp" or "cuda". ``threads``: host threads (None: all cores).
    ``progress``: a callable ``progress(stage, fraction)``; a true return value
    cancels (:class:`nbmc.Cancelled`). ``mesh_memory="device"`` leaves meshes
    on the GPU (CUDA backend). ``memory_budget``: cap on nbmc's memory (bytes or
    "4G"). Ctrl-C during :meth:`reconstruct` cancels it cleanly and raises
    KeyboardInterrupt; the context stays usable.

    A context is not for concurrent use from several threads (calls are
    serialised by a lock); contexts on different threads are independent.
    """

    def __init__(self, backend: Union[str, int] = "auto", *, threads: Optional[int] = None,
                 device_id: int = 0, progress: Optional[ProgressFn] = None,
                 memory_budget: Union[int, str, None] = None, mesh_memory: str = "host",
                 subdomains: Union[str, int, Tuple[int, int, int], None] = None) -> None:
        desc = C.ContextDesc()
        lib.nbmc_context_desc_init(byref(desc))
        desc.backend = _enum(BACKENDS, backend, "backend")
        desc.num_threads = 0 if threads is None else int(threads)
        desc.device_id = int(device_id)
        h = c_void_p()
        status = lib.nbmc_context_create(byref(desc), byref(h))
        if status:
            raise error_for(status, C.text(lib.nbmc_context_last_error(None)))
        self._ptr: Optional[int] = h.value
        self._device_id = int(device_id)
        self._finalizer = weakref.finalize(self, lib.nbmc_context_destroy, h.value)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._callback_error: Optional[BaseException] = None
        self.progress: Optional[ProgressFn] = progress
        self._count = 0
        # One trampoline for the context's life; it holds only a weak reference.
        me = weakref.ref(self)

        def trampoline(_user: Any, stage: int, fraction: float) -> int:
            ctx = me()
            if ctx is None or ctx._stop.is_set():
                return 1
            fn = ctx.progress
            if fn is None:
                return 0
            try:
                return 1 if fn(stage_name(stage), fraction) else 0
            except BaseException as e:  # noqa: BLE001 - must not unwind through C
                ctx._callback_error = e
                ctx._stop.set()
                return 1

        self._trampoline = C.PROGRESS_FN(trampoline)
        self._check(lib.nbmc_context_set_progress(self._ptr, self._trampoline, None))
        if memory_budget is not None:
            self.memory_budget = memory_budget
        if mesh_memory != "host":
            self.mesh_memory = mesh_memory
        if subdomains is not None:
            self.subdomains = subdomains

    # -- plumbing
    @property
    def _handle(self) -> int:
        if not self._ptr:
            raise ValueError("the nbmc.Context is closed")
        return self._ptr

    def _check(self, status: int) -> None:
        if status:
            raise error_for(status, C.text(lib.nbmc_context_last_error(self._ptr)))

    def close(self) -> None:
        """Frees the context and its buffers now (meshes stay valid)."""
        with self._lock:
            self._finalizer()
            self._ptr = None

    def __enter__(self) -> "Context":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- properties
    @property
    def backend(self) -> str:
        """The backend really used ("serial", "openmp" or "cuda")."""
        b = c_int32()
        self._check(lib.nbmc_context_backend(self._handle, byref(b)))
        return _name_of(BACKENDS, b.value)

    @property
    def device_id(self) -> int:
        return self._device_id

    @property
    def particle_count(self) -> int:
        """Particles uploaded by the last successful upload (0 if none)."""
        return self._count

    _budget = 0

    @property
    def memory_budget(self) -> int:
        """Cap on nbmc's memory in bytes (0: none). Set an int or "4G"."""
        return self._budget

    @memory_budget.setter
    def memory_budget(self, value: Union[int, str, None]) -> None:
        n = parse_bytes(value)
        with self._lock:
            self._check(lib.nbmc_context_set_memory_budget(self._handle, n))
        self._budget = n

    _subdomains: Union[str, Tuple[int, int, int]] = (1, 1, 1)

    @property
    def subdomains(self) -> Union[str, Tuple[int, int, int]]:
        """How reconstructions are split (docs/scale-out.md): ``(nx, ny, nz)``
        subdomains stitched into the same mesh, bit for bit; ``"auto"``: split
        only when the frame's estimate exceeds the memory budget (or, on a
        GPU, its free memory); an int n means (n, n, n). Default (1, 1, 1)."""
        return self._subdomains

    @subdomains.setter
    def subdomains(self, value: Union[str, int, Tuple[int, int, int]]) -> None:
        if isinstance(value, str):
            if value.lower() != "auto":
                raise ValueError(f"subdomains must be 'auto', an int or (nx, ny, nz), not {value!r}")
            parts: Union[str, Tuple[int, int, int]] = "auto"
            args = (C.SUBDOMAINS_AUTO, 0, 0)
        else:
            t = (int(value),) * 3 if isinstance(value, int) else tuple(int(v) for v in value)
            if len(t) != 3:
                raise ValueError(f"subdomains needs three counts, got {value!r}")
            parts = (t[0], t[1], t[2])
            args = parts
        with self._lock:
            self._check(lib.nbmc_context_set_subdomains(self._handle, *args))
        self._subdomains = parts

    def subdomain_stats(self) -> Dict[str, Any]:
        """How the last reconstruction was split: counts, ghost particles,
        reruns, exchanged band cells, shared vertices, and one dict per
        subdomain (``"per_subdomain"``). ``count`` is 0 when it was not."""
        st = C.SubdomainStats()
        lib.nbmc_subdomain_stats_init(byref(st))
        with self._lock:
            self._check(lib.nbmc_context_subdomain_stats(self._handle, byref(st)))
            per = []
            for i in range(st.count):
                e = C.SubdomainEntry()
                lib.nbmc_subdomain_entry_init(byref(e))
                self._check(lib.nbmc_context_subdomain_entry(self._handle, i, byref(e)))
                per.append({"coord": tuple(e.coord), "cells": (tuple(e.cell_lo), tuple(e.cell_hi)),
                            "particles": e.particles, "ghost_particles": e.ghost_particles,
                            "vertices": e.vertex_count, "triangles": e.triangle_count, "runs": e.runs,
                            "seconds": e.seconds})
        return {"parts": tuple(st.parts), "count": st.count, "automatic": bool(st.automatic),
                "ghost_width": st.ghost_width, "ghost_particles": st.ghost_particles, "reruns": st.reruns,
                "exchanged_cells": st.exchanged_cells, "shared_vertices": st.shared_vertices,
                "budget_bytes": st.budget_bytes, "stitch_seconds": st.stitch_seconds, "per_subdomain": per}

    _mesh_memory = "host"

    @property
    def mesh_memory(self) -> str:
        """Where meshes go: "host" or "device" (CUDA only)."""
        return self._mesh_memory

    @mesh_memory.setter
    def mesh_memory(self, value: Union[str, int]) -> None:
        m = _enum(MEMORIES, value, "mesh_memory")
        with self._lock:
            self._check(lib.nbmc_context_set_mesh_memory(self._handle, m))
        self._mesh_memory = _name_of(MEMORIES, m)

    # -- particles
    def set_particles(self, points: Any) -> int:
        """Uploads (copies) particle positions and returns their count.

        ``points``: an (N, 3) array-like of float32 or float64 (other numeric
        types are converted to float64 once). Any row stride is read in place
        (structured arrays, every other row, the transpose of a Fortran
        ``pos(3, n)``); Fortran-ordered (N, 3) arrays, negative strides and
        non-native byte order are copied first. Arrays exposing
        ``__cuda_array_interface__`` or CUDA DLPack go to the device upload
        (CUDA backend) without a host copy.
        """
        with self._lock:
            return self._set_particles(points)

    def _set_particles(self, points: Any) -> int:
        self._count = 0
        if A.is_device_array(points):
            d = A.device_points(points)
            try:
                A.synchronize(d.stream)
                fn = (lib.nbmc_context_set_particles_device_f64 if d.double
                      else lib.nbmc_context_set_particles_device_f32)
                self._check(fn(self._handle, d.pointer, d.count, d.byte_stride))
            finally:
                if d.release is not None:
                    d.release()
            self._count = d.count
            return d.count
        h = A.host_points(points)
        fn = lib.nbmc_context_set_particles_f64 if h.double else lib.nbmc_context_set_particles_f32
        self._check(fn(self._handle, h.pointer, h.count, h.byte_stride))
        self._count = h.count  # h.keep held the array through the call
        return h.count

    def set_attribute(self, name: str, values: Any) -> None:
        """Sets (copies) the per-particle attribute ``name`` (velocity,
        density, temperature, ...) for the particles uploaded last: an (N,)
        array-like (a scalar) or (N, 3) (a vector), float32 or float64 (other
        numeric types are converted to float64), N the particle count. The
        next reconstruction interpolates it onto the mesh
        (:attr:`Mesh.attributes`) with the field's kernel. Every particle
        upload removes all attributes: set them after the particles. Setting
        a name again replaces it; ``values=None`` removes it. NaN or infinite
        values raise :class:`nbmc.InvalidParticles`; a wrong length
        ValueError."""
        with self._lock:
            self._set_attribute(name, values)

    def _set_attribute(self, name: str, values: Any) -> None:
        key = name.encode()
        if values is None:
            self._check(lib.nbmc_context_set_attribute_f64(self._handle, key, None, 1, 0))
            return
        a = np.asarray(values)
        if a.dtype not in (np.float32, np.float64) or not a.dtype.isnative:
            if a.dtype.kind not in "fiub":
                raise TypeError(f"attribute {name!r} must be numeric, not {a.dtype}")
            a = np.asarray(a, dtype=np.float64)
        if a.ndim == 1:
            comps = 1
        elif a.ndim == 2 and a.shape[1] in (1, 3):
            comps = a.shape[1]
        else:
            raise ValueError(f"attribute {name!r} must have shape (N,) or (N, 3), not {a.shape}")
        if not self._count:
            raise error_for(C.ERROR_NO_PARTICLES, f"set_attribute({name!r}): no particles uploaded; "
                            "upload the particles first (an upload removes all attributes)")
        # The library reads one item per particle it holds: the length must match.
        if a.shape[0] != self._count:
            raise ValueError(f"attribute {name!r} has {a.shape[0]} items for {self._count} particles")
        a = np.ascontiguousarray(a)
        fn = lib.nbmc_context_set_attribute_f64 if a.dtype == np.float64 else lib.nbmc_context_set_attribute_f32
        self._check(fn(self._handle, key, a.ctypes.data, comps, 0))

    def remove_attribute(self, name: str) -> None:
        """Removes the attribute ``name`` (no error when there is none)."""
        self.set_attribute(name, None)

    def set_radii(self, radii: Any) -> None:
        """Sets (copies) per-particle radii for the particles uploaded last:
        an (N,) array-like, float32 or float64 (other numeric types are
        converted to float64), absolute, N the particle count. A radius is a
        particle's r, the spacing it would have in a uniform frame: the
        parameters then describe a particle of radius ``spacing``, and each
        particle scales the influence radius, band width, surface radius and
        iso radius by its own radius over it; the cell size stays the
        frame's (docs/api.md, "Per-particle radii"). They stay for the
        following reconstructions until ``set_radii(None)`` or the next
        particle upload. A NaN, infinite, zero or negative radius raises
        :class:`nbmc.InvalidParameter`; a wrong length ValueError."""
        with self._lock:
            self._set_radii(radii)

    def _set_radii(self, radii: Any) -> None:
        if radii is None:
            self._check(lib.nbmc_context_set_radii_f64(self._handle, None, 0, 0))
            return
        a = np.asarray(radii)
        if a.dtype not in (np.float32, np.float64) or not a.dtype.isnative:
            if a.dtype.kind not in "fiub":
                raise TypeError(f"radii must be numeric, not {a.dtype}")
            a = np.asarray(a, dtype=np.float64)
        if a.ndim != 1:
            raise ValueError(f"radii must have shape (N,), not {a.shape}")
        if not self._count:
            raise error_for(C.ERROR_NO_PARTICLES, "set_radii: no particles uploaded; upload the particles "
                            "first (an upload removes the radii)")
        if a.shape[0] != self._count:
            raise ValueError(f"{a.shape[0]} radii for {self._count} particles")
        a = np.ascontiguousarray(a)
        fn = lib.nbmc_context_set_radii_f64 if a.dtype == np.float64 else lib.nbmc_context_set_radii_f32
        self._check(fn(self._handle, a.ctypes.data, a.shape[0], 0))

    def load_particles(self, path: PathLike, format: Optional[str] = None) -> int:
        """Reads a particle file with nbmc's readers (xyz, ply, vtk, vtu, vtp,
        bgeo, h5part, pysph, gadget/swift, hdf5; ``"run.h5:/PartType1"`` names
        an HDF5 object) and uploads its positions; returns the count.
        Multi-step H5Part files give their first step."""
        with self._lock:
            return self._load(path, format)

    def _load(self, path: PathLike, format: Optional[str]) -> int:
        self._count = 0
        n = c_uint64()
        fmt = format.encode() if format else None
        self._check(lib.nbmc_context_load_particles(self._handle, os.fsencode(path), fmt, byref(n)))
        self._count = n.value
        return n.value

    # -- reconstruction
    def reconstruct(self, points: Any = None, spacing: Optional[float] = None, *,
                    particle_radius: Optional[float] = None, bbox: Any = None,
                    format: Optional[str] = None,
                    attributes: Union[Mapping[str, Any], Sequence[str], None] = None,
                    radii: Any = None, **params: Any) -> Mesh:
        """Reconstructs the surface; see :func:`nbmc.reconstruct` for the
        parameters. ``points``: an array (uploaded first), a path (read with
        :meth:`load_particles`, ``format`` as there), a :class:`Particles`
        (its file is read), or None to reuse the particles uploaded last
        (and their radii, :meth:`set_radii`, unless ``radii`` is given)."""
        if attributes and not isinstance(attributes, Mapping):
            raise NotImplementedError(
                "attributes: the C ABI cannot read a particle file's attributes; pass arrays "
                "instead, attributes={'vel': array, ...} (see docs/python.md)")
        p = make_params(spacing, particle_radius, bbox, **params)
        with self._lock:
            if isinstance(points, Particles):
                self._load(points.path, points.format)
            elif isinstance(points, (str, os.PathLike)):
                self._load(points, format)
            elif points is not None:
                self._set_particles(points)
            for name, values in (attributes or {}).items():
                self._set_attribute(name, values)
            if radii is not None:
                self._set_radii(radii)
            return self._reconstruct(p)

    def _reconstruct(self, p: C.Params) -> Mesh:
        handle = self._handle
        out = c_void_p()
        self._stop.clear()
        self._callback_error = None

        def call() -> int:
            return lib.nbmc_context_reconstruct(handle, byref(p), byref(out))

        try:
            status = _interruptible(call, self._stop.set)
        except BaseException:
            if out.value:  # finished before it saw the request to stop
                lib.nbmc_mesh_destroy(out.value)
            raise
        if status == C.OK:
            mesh = Mesh(_MeshHandle(out.value, self._device_id), self._stats())
        if self._callback_error is not None:
            error, self._callback_error = self._callback_error, None
            raise error  # the progress callback's own exception (the mesh is dropped)
        if status == C.ERROR_CANCELLED:
            raise Cancelled(status, C.text(lib.nbmc_context_last_error(handle)) or
                            "the progress callback cancelled the reconstruction")
        self._check(status)
        return mesh

    def _stats(self) -> Optional[Stats]:
        s = C.Stats()
        lib.nbmc_stats_init(byref(s))
        if lib.nbmc_context_stats(self._ptr, byref(s)):
            return None
        return Stats._from_c(s)

    @property
    def stats(self) -> Stats:
        """Figures of the last successful reconstruction on this context."""
        s = C.Stats()
        lib.nbmc_stats_init(byref(s))
        with self._lock:
            self._check(lib.nbmc_context_stats(self._handle, byref(s)))
        return Stats._from_c(s)

    def reconstruct_frames(self, pattern: PathLike, spacing: Optional[float] = None, *,
                           numbers: Optional[Iterable[int]] = None,
                           format: Optional[str] = None,
                           **params: Any) -> Iterator[Tuple[Frame, Mesh]]:
        """Yields ``(frame, mesh)`` for every file of a ``{}`` pattern (see
        :func:`frames`), reusing this context's buffers."""
        for frame in frames(pattern, numbers):
            yield frame, self.reconstruct(frame.path, spacing, format=format, **params)

    def __repr__(self) -> str:
        state = "closed" if not self._ptr else self.backend
        return f"<nbmc.Context {state}>"


# ------------------------------------------------------------ particle files
class Particles:
    """Particles read from a file by nbmc's readers (:func:`read_particles`).

    The C ABI has no call that hands positions back to the caller, so this is
    a handle, not an array: ``count``, ``path``, ``format`` and
    :meth:`reconstruct`, which runs on the context that holds the particles
    (no second read). ``context`` is that :class:`Context`.
    """

    def __init__(self, path: PathLike, format: Optional[str], context: Context, count: int) -> None:
        self.path = os.fspath(path)
        self.format = format
        self.context = context
        self.count = count

    def reconstruct(self, spacing: Optional[float] = None, **params: Any) -> Mesh:
        """Reconstructs these particles; parameters as :func:`nbmc.reconstruct`."""
        with self.context._lock:
            if self.context.particle_count != self.count:  # replaced meanwhile
                self.context._load(self.path, self.format)
        return self.context.reconstruct(None, spacing, **params)

    def __len__(self) -> int:
        return self.count

    def __repr__(self) -> str:
        return f"<nbmc.Particles {self.count} particles from {self.path!r}>"


def read_particles(path: PathLike, format: Optional[str] = None, *,
                   backend: Union[str, int] = "auto", threads: Optional[int] = None,
                   attributes: Optional[Sequence[str]] = None) -> Particles:
    """Reads a particle file with nbmc's own readers and validates it.

    Formats: xyz, ply, vtk, vtu, vtp, bgeo, h5part, pysph, gadget (swift),
    hdf5, from the extension unless ``format`` is given; an HDF5 object is
    named after the file (``"run.h5:/PartType1"``). Multi-step H5Part files
    give their first step. Returns a :class:`Particles` handle (the C ABI 0.1
    cannot return positions or attributes to Python; see docs/python.md).
    Raises :class:`nbmc.FileError`, :class:`nbmc.FormatError`,
    :class:`nbmc.InvalidParticles` or :class:`nbmc.NoParticles`.
    """
    if attributes:
        raise NotImplementedError("attributes: the nbmc C ABI 0.1 cannot return particle "
                                  "attributes (see docs/python.md)")
    ctx = Context(backend, threads=threads)
    count = ctx.load_particles(path, format)
    return Particles(path, format, ctx, count)


# ----------------------------------------------------------------- sequences
def frames(pattern: PathLike, numbers: Optional[Iterable[int]] = None) -> Iterator[Frame]:
    """The files matching ``pattern`` with digits in place of ``{}``, in
    numeric order (``f_2`` before ``f_10``), like the CLI's sequences.

    ``{}`` must appear once, in the file-name part. ``numbers`` (e.g.
    ``range(0, 100, 5)``) keeps only those frame numbers. Raises
    FileNotFoundError if the folder does not exist.
    """
    pattern = os.fspath(pattern)
    folder, name = os.path.split(pattern)
    if pattern.count("{}") != 1:
        raise ValueError(f"the pattern {pattern!r} must contain {{}} exactly once")
    if "{}" not in name:
        raise ValueError("{} must be in the file name of the pattern, not in a folder name")
    prefix, suffix = name.split("{}")
    rx = re.compile(re.escape(prefix) + r"(\d+)" + re.escape(suffix))
    keep = None if numbers is None else set(int(n) for n in numbers)
    found = []
    with os.scandir(folder or ".") as it:
        for entry in it:
            m = rx.fullmatch(entry.name)
            if m and (keep is None or int(m.group(1)) in keep):
                found.append(Frame(int(m.group(1)), m.group(1), os.path.join(folder, entry.name)))
    found.sort(key=lambda f: (f.number, f.label))
    return iter(found)


# ----------------------------------------------------------- one-call helper
def reconstruct(points: Any, spacing: Optional[float] = None, *,
                particle_radius: Optional[float] = None,
                cell_size: Optional[float] = None, influence_radius: Optional[float] = None,
                band_width: Optional[float] = None, surface_radius: Optional[float] = None,
                iso_radius: Optional[float] = None, method: Optional[str] = None,
                field: Optional[str] = None, t_low: Optional[float] = None,
                t_high: Optional[float] = None, iso_threshold: Optional[float] = None,
                color_threshold: Optional[float] = None,
                neighbour_threshold: Optional[int] = None, normals: Optional[bool] = None,
                length_unit: Optional[str] = None, bbox: Any = None,
                isolated: Optional[str] = None, min_cluster: Optional[int] = None,
                double_positions: Optional[bool] = None, cleanup: Optional[bool] = None,
                smooth: Optional[int] = None, smooth_weights: Optional[str] = None,
                decimate: Optional[float] = None,
                aniso_kr: Optional[float] = None, aniso_ks: Optional[float] = None,
                aniso_kn: Optional[float] = None, aniso_neighbours: Optional[int] = None,
                aniso_lambda: Optional[float] = None, max_distance: Optional[float] = None,
                backend: Union[str, int] = "auto", threads: Optional[int] = None,
                device_id: int = 0, memory_budget: Union[int, str, None] = None,
                mesh_memory: str = "host", progress: Optional[ProgressFn] = None,
                format: Optional[str] = None,
                attributes: Union[Mapping[str, Any], Sequence[str], None] = None,
                radii: Any = None) -> Mesh:
    """Reconstructs the surface of particles as a triangle mesh.

    points
        (N, 3) float32 or float64 array-like (any strides; read in place when
        the layout allows), a CUDA array (``__cuda_array_interface__`` or
        DLPack; CUDA backend), a particle file path (``format`` overrides its
        extension), or a :class:`Particles`.
    spacing / particle_radius
        The particle spacing r (absolute), or the particle radius of
        SPlisHSPlasH/splashsurf (r/2). One of them is required.
    cell_size, influence_radius, band_width, surface_radius, iso_radius
        Lengths in multiples of the spacing (``length_unit="absolute"``: in the
        units of the positions); defaults {cell_size}, {influence_radius},
        {band_width}, {surface_radius}, {iso_radius}.
    method
        "ssp07" (Solenthaler et al. 2007), "zb05" (Zhu & Bridson 2005),
        "sph" (splashsurf's normalised SPH density, cubic spline kernel of
        support ``influence_radius``) or "yt10" (Yu & Turk 2010: that density
        with one anisotropic kernel per particle, isotropic support
        ``influence_radius / 2``); default {method!r}.
    iso_threshold
        "sph" and "yt10": the iso level of the normalised density, a fraction
        of the rest density in (0, 1) (splashsurf's ``--surface-threshold``);
        default {iso_threshold}.
    aniso_kr, aniso_ks, aniso_kn, aniso_neighbours, aniso_lambda
        "yt10" only (Yu & Turk's k_r, k_s, k_n, N_eps and lambda, docs/methods.md):
        the largest ratio of a kernel's axes (>= 1), the scale of the axes
        (1: a particle inside a uniform fluid gets the isotropic kernel), the
        kernel scale of particles with at most ``aniso_neighbours`` neighbours
        within ``influence_radius`` (in (0, 1.5]), and the smoothing of the
        kernel centres (in [0, 1]); defaults {aniso_kr}, {aniso_ks},
        {aniso_kn}, {aniso_neighbours}, {aniso_lambda}.
    max_distance
        "ssp07", "zb05", "sph": keep the surface within about this distance
        of the particles (a length like ``cell_size``): where no particle lies
        within it the field is raised, so bridges between splashes and
        fillets in concave corners are cut back; 0: off; default
        {max_distance}.
    field
        "narrow-band", or the baselines "dense" and "scatter"; default {field!r}.
    t_low, t_high, color_threshold, neighbour_threshold
        Surface-particle test; defaults {t_low}, {t_high}, {color_threshold},
        {neighbour_threshold}.
    normals
        Compute vertex normals (default {normals}).
    isolated, min_cluster
        "drop": clusters (particles linked when closer than
        ``surface_radius``) of fewer than ``min_cluster`` particles make no
        surface; defaults {isolated!r}, {min_cluster}. ``Context.stats``
        counts what was dropped.
    double_positions
        Keep the vertex positions in double precision: ``Mesh.vertices`` is
        float64 (for coordinates far from the origin, e.g. UTM metres, where
        float32 resolves only 0.5 m); host meshes only. Default
        {double_positions}.
    isolated="sphere"
        As "drop", and the dropped particles come back as spheres
        (:attr:`Mesh.spheres`, radius ``iso_radius``; "sph", "yt10": half the spacing).
    cleanup
        Remove degenerate and sliver triangles (default {cleanup}).
    smooth, smooth_weights
        Taubin smoothing iterations after the clean-up (default {smooth}),
        "uniform" or "feature" (each vertex's step scaled by the particles
        near it, so thin sheets, filaments and droplets are not eroded;
        default {smooth_weights!r}).
    decimate
        Keep this fraction of the triangles, 0 < f <= 1, by quadric-error
        edge collapses that keep the mesh closed and manifold (default
        {decimate}: off). ``Mesh.stats.pre_decimation_triangle_count`` has
        the count before.
    bbox
        Only reconstruct near this box (absolute): (xmin, ymin, zmin, xmax,
        ymax, zmax) or ((xmin, ymin, zmin), (xmax, ymax, zmax)).
    backend, threads, device_id, memory_budget, mesh_memory, progress
        As for :class:`Context`.
    attributes
        ``{{name: values}}``: per-particle arrays, (N,) or (N, 3), interpolated
        onto the vertices (:attr:`Mesh.attributes`; see
        :meth:`Context.set_attribute`). A particle file's own attributes
        cannot be read through the C ABI (a list of names raises
        NotImplementedError).
    radii
        Per-particle radii, an (N,) array-like (absolute): particles of
        different sizes (variable-resolution SPH); see
        :meth:`Context.set_radii`. The lengths above then describe a particle
        of radius ``spacing``.

    The defaults above are read from the loaded library (``nbmc_params_init``)
    and are what ``None`` means. Names follow the CLI's options
    (``--cell-size`` is ``cell_size``). Raises :class:`nbmc.Error` subclasses
    with the library's message; Ctrl-C cancels and raises KeyboardInterrupt.
    For a sequence of frames, use one :class:`Context` to reuse its buffers.
    """
    with Context(backend, threads=threads, device_id=device_id, progress=progress,
                 memory_budget=memory_budget, mesh_memory=mesh_memory) as ctx:
        return ctx.reconstruct(points, spacing, particle_radius=particle_radius, bbox=bbox,
                               format=format, attributes=attributes, radii=radii, cell_size=cell_size,
                               influence_radius=influence_radius, band_width=band_width,
                               surface_radius=surface_radius, iso_radius=iso_radius,
                               method=method, field=field, t_low=t_low, t_high=t_high,
                               iso_threshold=iso_threshold, color_threshold=color_threshold,
                               neighbour_threshold=neighbour_threshold, normals=normals,
                               length_unit=length_unit, isolated=isolated,
                               min_cluster=min_cluster, double_positions=double_positions,
                               cleanup=cleanup, smooth=smooth, smooth_weights=smooth_weights,
                               decimate=decimate, aniso_kr=aniso_kr, aniso_ks=aniso_ks, aniso_kn=aniso_kn,
                               aniso_neighbours=aniso_neighbours, aniso_lambda=aniso_lambda,
                               max_distance=max_distance)


def _show_library_defaults(fn: Callable[..., Any]) -> None:
    """Puts the library's defaults into fn's docstring and signature, so that
    help() shows the real numbers without this file repeating them."""
    d = defaults()
    fn.__doc__ = (fn.__doc__ or "").format(**d)
    sig = inspect.signature(fn)
    fn.__signature__ = sig.replace(parameters=[  # type: ignore[attr-defined]
        p.replace(default=d[p.name]) if p.name in d and p.default is None else p
        for p in sig.parameters.values()])


_show_library_defaults(reconstruct)
