# SPDX-License-Identifier: MIT
"""Array plumbing: numpy inputs without copies, device inputs through
``__cuda_array_interface__`` or DLPack, and zero-copy views of mesh arrays.
"""
from __future__ import annotations

import ctypes
from ctypes import POINTER, Structure, c_int32, c_int64, c_uint8, c_uint16, c_uint64, c_void_p
from typing import Any, NamedTuple, Optional, Tuple

import numpy as np

# ------------------------------------------------------------------ host input


class HostPoints(NamedTuple):
    """A host array as nbmc_context_set_particles_* reads it."""

    pointer: int
    count: int
    byte_stride: int
    double: bool  # float64 (else float32)
    keep: np.ndarray  # the array the pointer points into (kept alive by the caller)


def host_points(points: Any) -> HostPoints:
    """(N, 3) float32/float64 data as pointer + stride, copying only when the
    layout does not allow reading it in place: rows must hold x, y, z as three
    consecutive values, at a positive row stride that does not overlap, and
    the values must be aligned and in native byte order. Other dtypes are
    converted to float64 once."""
    a = np.asarray(points)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), not {a.shape}")
    if a.dtype not in (np.float32, np.float64) or not a.dtype.isnative:
        if a.dtype.kind not in "fiub":
            raise TypeError(f"points must be numeric, not {a.dtype}")
        # float16, integers, big-endian floats: one conversion here.
        target = np.float32 if a.dtype.kind == "f" and a.dtype.itemsize == 4 else np.float64
        a = np.ascontiguousarray(a, dtype=target)
    item = a.dtype.itemsize
    n = a.shape[0]
    rows_ok = n <= 1 or a.strides[0] >= 3 * item
    if not (a.flags.aligned and a.strides[1] == item and rows_ok):
        a = np.ascontiguousarray(a)
    stride = a.strides[0] if n > 1 else 3 * item
    return HostPoints(a.ctypes.data, n, stride, a.dtype == np.float64, a)


# --------------------------------------------------------------------- DLPack
# The DLPack C structs (dlpack.h, version 0.x ABI, which every producer still
# emits through __dlpack__() without a max_version argument).
KDL_CPU = 1
KDL_CUDA = 2
KDL_CUDA_HOST = 3
KDL_CUDA_MANAGED = 13
KDL_FLOAT = 2
KDL_UINT = 1


class DLDevice(Structure):
    _fields_ = [("device_type", c_int32), ("device_id", c_int32)]


class DLDataType(Structure):
    _fields_ = [("code", c_uint8), ("bits", c_uint8), ("lanes", c_uint16)]


class DLTensor(Structure):
    _fields_ = [
        ("data", c_void_p),
        ("device", DLDevice),
        ("ndim", c_int32),
        ("dtype", DLDataType),
        ("shape", POINTER(c_int64)),
        ("strides", POINTER(c_int64)),
        ("byte_offset", c_uint64),
    ]


class DLManagedTensor(Structure):
    pass


_DELETER = ctypes.CFUNCTYPE(None, POINTER(DLManagedTensor))
DLManagedTensor._fields_ = [("dl_tensor", DLTensor), ("manager_ctx", c_void_p), ("deleter", _DELETER)]

_api = ctypes.pythonapi
_api.PyCapsule_New.restype = ctypes.py_object
_api.PyCapsule_New.argtypes = [c_void_p, ctypes.c_char_p, c_void_p]
_api.PyCapsule_IsValid.restype = ctypes.c_int
_api.PyCapsule_IsValid.argtypes = [ctypes.py_object, ctypes.c_char_p]
_api.PyCapsule_GetPointer.restype = c_void_p
_api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
_api.PyCapsule_SetName.restype = ctypes.c_int
_api.PyCapsule_SetName.argtypes = [ctypes.py_object, ctypes.c_char_p]
# The capsule destructor gets the capsule being destroyed: raw pointer only.
_raw_is_valid = ctypes.PYFUNCTYPE(ctypes.c_int, c_void_p, ctypes.c_char_p)(("PyCapsule_IsValid", _api))
_raw_get_pointer = ctypes.PYFUNCTYPE(c_void_p, c_void_p, ctypes.c_char_p)(("PyCapsule_GetPointer", _api))

# Exported tensors alive in a consumer (or in an unconsumed capsule), by address.
_exports: dict = {}


@_DELETER
def _export_deleter(managed):  # called by the consumer when it is done
    _exports.pop(ctypes.addressof(managed.contents), None)


@ctypes.CFUNCTYPE(None, c_void_p)
def _capsule_destructor(capsule):  # a capsule that nobody consumed
    if _raw_is_valid(capsule, b"dltensor"):
        _exports.pop(_raw_get_pointer(capsule, b"dltensor"), None)


def to_dlpack(pointer: int, shape: Tuple[int, ...], dtype: np.dtype, device_type: int,
              device_id: int, owner: Any) -> Any:
    """A "dltensor" capsule for C-contiguous memory at pointer, keeping owner
    alive until the consumer calls the deleter."""
    dtype = np.dtype(dtype)
    shape_arr = (c_int64 * len(shape))(*shape)
    m = DLManagedTensor()
    m.dl_tensor.data = pointer or None
    m.dl_tensor.device = DLDevice(device_type, device_id)
    m.dl_tensor.ndim = len(shape)
    m.dl_tensor.dtype = DLDataType(KDL_FLOAT if dtype.kind == "f" else KDL_UINT, dtype.itemsize * 8, 1)
    m.dl_tensor.shape = shape_arr
    m.dl_tensor.strides = None  # C-contiguous
    m.dl_tensor.byte_offset = 0
    m.manager_ctx = None
    m.deleter = _export_deleter
    address = ctypes.addressof(m)
    _exports[address] = (m, shape_arr, owner)
    return _api.PyCapsule_New(address, b"dltensor", ctypes.cast(_capsule_destructor, c_void_p))


class DLPackView(NamedTuple):
    pointer: int
    shape: Tuple[int, ...]
    strides: Optional[Tuple[int, ...]]  # in bytes; None = C-contiguous
    dtype: np.dtype
    device_type: int
    device_id: int


def from_dlpack_capsule(capsule: Any) -> Tuple[DLPackView, Any]:
    """Reads a "dltensor" capsule and marks it used. Returns the view and a
    release function that must be called when the memory is no longer read."""
    if not _api.PyCapsule_IsValid(capsule, b"dltensor"):
        raise ValueError("not an unused DLPack capsule")
    address = _api.PyCapsule_GetPointer(capsule, b"dltensor")
    managed = ctypes.cast(address, POINTER(DLManagedTensor)).contents
    t = managed.dl_tensor
    code, bits, lanes = t.dtype.code, t.dtype.bits, t.dtype.lanes
    if lanes != 1 or code != KDL_FLOAT or bits not in (32, 64):
        kind = {0: "int", 1: "uint", 2: "float", 4: "bfloat"}.get(code, f"code {code}")
        dtype: Any = f"{kind}{bits}x{lanes}"
    else:
        dtype = np.dtype(np.float32 if bits == 32 else np.float64)
    shape = tuple(t.shape[i] for i in range(t.ndim))
    item = bits // 8
    strides = None if not t.strides else tuple(t.strides[i] * item for i in range(t.ndim))
    view = DLPackView((t.data or 0) + t.byte_offset, shape, strides, dtype,
                      t.device.device_type, t.device.device_id)
    _api.PyCapsule_SetName(capsule, b"used_dltensor")
    deleter = managed.deleter

    def release() -> None:
        if deleter:
            deleter(ctypes.cast(address, POINTER(DLManagedTensor)))

    return view, release


# -------------------------------------------------------------- device input


class DevicePoints(NamedTuple):
    pointer: int
    count: int
    byte_stride: int
    double: bool
    stream: Optional[int]  # a CUDA stream to synchronise before nbmc reads
    release: Any  # called after the upload (DLPack deleter), or None


def _device_layout(shape, strides, dtype, what: str) -> Tuple[int, int, bool]:
    if not isinstance(dtype, np.dtype) or dtype not in (np.float32, np.float64):
        raise TypeError(f"{what}: device points must be float32 or float64, not {dtype}")
    if len(shape) != 2 or shape[1] != 3:
        raise ValueError(f"{what}: points must have shape (N, 3), not {tuple(shape)}")
    item = dtype.itemsize
    if strides is None:
        return shape[0], 3 * item, dtype == np.float64
    if shape[0] > 1 and strides[0] < 3 * item or strides[1] != item:
        raise ValueError(f"{what}: each point's x, y, z must be consecutive values at a "
                         f"positive row stride (strides {tuple(strides)} cannot be read in place "
                         f"and nbmc does not copy device memory); pass a C-contiguous array")
    return shape[0], strides[0] if shape[0] > 1 else 3 * item, dtype == np.float64


def is_device_array(obj: Any) -> bool:
    if hasattr(obj, "__cuda_array_interface__"):
        return True
    if hasattr(obj, "__dlpack_device__") and not isinstance(obj, np.ndarray):
        try:
            return obj.__dlpack_device__()[0] in (KDL_CUDA, KDL_CUDA_MANAGED)
        except Exception:  # noqa: BLE001 - not a usable DLPack producer
            return False
    return False


def device_points(obj: Any) -> DevicePoints:
    """Pointer, count and stride of a CUDA array (CuPy, PyTorch, Numba, Warp,
    JAX, ...), read through __cuda_array_interface__ or else DLPack."""
    if hasattr(obj, "__cuda_array_interface__"):
        cai = obj.__cuda_array_interface__
        if cai.get("mask") is not None:
            raise ValueError("__cuda_array_interface__: masked arrays are not supported")
        dtype = np.dtype(cai["typestr"])
        if not dtype.isnative:
            raise TypeError("__cuda_array_interface__: device points must be in native byte order")
        strides = cai.get("strides")
        count, stride, double = _device_layout(tuple(cai["shape"]), strides, dtype,
                                               "__cuda_array_interface__")
        stream = cai.get("stream") if cai.get("version", 0) >= 3 else None
        return DevicePoints(int(cai["data"][0]), count, stride, double, stream, None)
    capsule = obj.__dlpack__()
    view, release = from_dlpack_capsule(capsule)
    try:
        if view.device_type not in (KDL_CUDA, KDL_CUDA_MANAGED):
            raise ValueError(f"DLPack: device type {view.device_type} is not CUDA memory")
        count, stride, double = _device_layout(view.shape, view.strides, view.dtype, "DLPack")
    except Exception:
        release()
        raise
    # __dlpack__() without a stream orders the producer's work before the
    # legacy default stream; synchronise it (stream 0) before nbmc reads.
    return DevicePoints(view.pointer, count, stride, double, 0, release)


# ------------------------------------------------------ CUDA runtime (optional)
_cudart: Any = None


def cudart() -> Optional[ctypes.CDLL]:
    """libcudart through ctypes, or None (only needed to synchronise streams
    of foreign device arrays before nbmc reads them)."""
    global _cudart
    if _cudart is None:
        _cudart = False
        import ctypes.util
        import os
        names = [os.environ.get("NBMC_CUDART"), ctypes.util.find_library("cudart"),
                 "libcudart.so", "libcudart.so.13", "libcudart.so.12", "libcudart.so.11.0",
                 "/usr/local/cuda/lib64/libcudart.so"]
        for name in names:
            if not name:
                continue
            try:
                lib = ctypes.CDLL(name)
            except OSError:
                continue
            lib.cudaStreamSynchronize.argtypes = [c_void_p]
            lib.cudaStreamSynchronize.restype = c_int32
            _cudart = lib
            break
    return _cudart or None


def synchronize(stream: Optional[int]) -> None:
    """Waits for a producer's CUDA stream, when libcudart can be loaded."""
    if stream is None:
        return
    rt = cudart()
    if rt is not None:
        # 1 and 2 are cudaStreamLegacy and cudaStreamPerThread, as in the CUDA API
        rt.cudaStreamSynchronize(c_void_p(stream))


# ------------------------------------------------------------- mesh views


class _HostBuffer:
    """Exposes nbmc-owned host memory to numpy; holds the mesh handle so that
    the memory lives as long as any array made from it."""

    def __init__(self, pointer: int, shape: Tuple[int, ...], dtype: np.dtype, owner: Any) -> None:
        self._owner = owner
        self.__array_interface__ = {
            "shape": shape,
            "typestr": np.dtype(dtype).str,
            "data": (pointer, True),  # read-only: the mesh is immutable
            "version": 3,
        }


def host_view(pointer: int, shape: Tuple[int, ...], dtype: Any, owner: Any) -> np.ndarray:
    """A read-only numpy array over nbmc's memory, without a copy."""
    if not pointer or 0 in shape:
        a = np.empty(shape, dtype=dtype)
        a.flags.writeable = False
        return a
    return np.asarray(_HostBuffer(pointer, shape, dtype, owner))


class DeviceArray:
    """A read-only CUDA array owned by a device mesh. Exposes
    ``__cuda_array_interface__`` (version 3) and ``__dlpack__``, so CuPy,
    PyTorch, Numba or Warp take it without a copy (``cupy.asarray(a)``,
    ``torch.from_dlpack(a)``); :meth:`get` copies it to a numpy array."""

    def __init__(self, pointer: int, shape: Tuple[int, ...], dtype: Any, device_id: int,
                 mesh: Any, which: str) -> None:
        self.ptr = int(pointer or 0)
        self.shape = tuple(shape)
        self.dtype = np.dtype(dtype)
        self.device_id = device_id
        self._mesh = mesh  # the owning _MeshHandle
        self._which = which

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def nbytes(self) -> int:
        return self.size * self.dtype.itemsize

    @property
    def __cuda_array_interface__(self) -> dict:
        return {
            "shape": self.shape,
            "typestr": self.dtype.str,
            "data": (self.ptr, True),
            "strides": None,
            "version": 3,
            # complete when nbmc_context_reconstruct returned: nothing to wait for
            "stream": None,
        }

    def __dlpack_device__(self) -> Tuple[int, int]:
        return (KDL_CUDA, self.device_id)

    def __dlpack__(self, stream: Any = None, **_: Any) -> Any:
        # The data are complete: no synchronisation with the consumer's stream.
        return to_dlpack(self.ptr, self.shape, self.dtype, KDL_CUDA, self.device_id, self)

    def get(self) -> np.ndarray:
        """A host copy (numpy) through nbmc_mesh_copy_to_host."""
        return self._mesh.copy_to_host(self._which)

    def __len__(self) -> int:
        return self.shape[0]

    def __repr__(self) -> str:
        return f"<nbmc.DeviceArray {self._which} shape={self.shape} dtype={self.dtype} cuda:{self.device_id}>"
