#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""GPU check of the Python package: device inputs and device meshes.

Run on a machine with an NVIDIA GPU and a CUDA build of libnbmc:

    NBMC_LIBRARY=<repo>/build-cuda/install/lib/libnbmc.so python3 python/tests/gpu_check.py

It needs only the library, numpy and ctypes: device memory is allocated with
libcudart through ctypes (NBMC_CUDART=/path/to/libcudart.so if it is not
found), wrapped in a minimal __cuda_array_interface__ object. When CuPy or
PyTorch are installed, their arrays are checked too (CAI and DLPack).
Prints one line per check; exits 0 if all pass, 1 if any fails, 2 if the
library has no usable CUDA backend (nothing to check).
"""
import ctypes
import sys
import tempfile
import traceback
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
import nbmc  # noqa: E402
from nbmc import _arrays  # noqa: E402

DATA = HERE.parent.parent / "examples" / "data" / "double_dam_break_4732.xyz"
RADIUS = 0.025
H2D, D2H = 1, 2
failures = []


def check(name):
    def run(fn):
        try:
            fn()
            print(f"PASS {name}", flush=True)
        except Exception:  # noqa: BLE001 - report and go on
            failures.append(name)
            print(f"FAIL {name}\n{traceback.format_exc()}", flush=True)
        return fn
    return run


rt = _arrays.cudart()
if rt is None:
    print("gpu_check: cannot load libcudart (set NBMC_CUDART)")
    sys.exit(2)
rt.cudaMalloc.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_size_t]
rt.cudaMemcpy.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
rt.cudaFree.argtypes = [ctypes.c_void_p]
rt.cudaDeviceSynchronize.argtypes = []
for f in ("cudaMalloc", "cudaMemcpy", "cudaFree", "cudaDeviceSynchronize"):
    getattr(rt, f).restype = ctypes.c_int


def cuda(status):
    if status != 0:
        raise RuntimeError(f"CUDA error {status}")


class CudaBuffer:
    """Device memory holding a copy of a numpy array, with the CUDA array
    interface of a (possibly strided) view of it."""

    def __init__(self, host, view_shape=None, view_strides=None):
        host = np.ascontiguousarray(host)
        self.host = host
        p = ctypes.c_void_p()
        cuda(rt.cudaMalloc(ctypes.byref(p), max(host.nbytes, 1)))
        self.ptr = p.value
        cuda(rt.cudaMemcpy(self.ptr, host.ctypes.data, host.nbytes, H2D))
        self.__cuda_array_interface__ = {
            "shape": view_shape or host.shape, "typestr": host.dtype.str,
            "strides": view_strides, "data": (self.ptr, False), "version": 3, "stream": 1}

    def __del__(self):
        rt.cudaFree(self.ptr)


def from_device(cai):
    """numpy copy of a C-contiguous device array described by cai."""
    out = np.empty(cai["shape"], np.dtype(cai["typestr"]))
    cuda(rt.cudaMemcpy(out.ctypes.data, cai["data"][0], out.nbytes, D2H))
    return out


def same(a, b):
    assert a.vertex_count == b.vertex_count > 0, (a, b)
    va, na, ta = a.to_host()
    vb, nb, tb = b.to_host()
    assert np.array_equal(va, vb) and np.array_equal(ta, tb) and np.array_equal(na, nb)


print(nbmc.library_version_string(), "from", nbmc.library_path)
if not nbmc.backend_available("cuda"):
    print("gpu_check: this libnbmc has no usable CUDA backend; nothing to check")
    sys.exit(2)

points = np.fromfile(DATA, "<f4").reshape(-1, 3)
ctx = nbmc.Context("cuda")
ref = ctx.reconstruct(points, particle_radius=RADIUS)  # host upload, host mesh
print(f"reference: {ref}, backend {ctx.backend}")


@check("CAI float32 device input equals the host upload")
def _():
    buf = CudaBuffer(points)
    same(ctx.reconstruct(buf, particle_radius=RADIUS), ref)


@check("CAI float64 device input")
def _():
    same(ctx.reconstruct(CudaBuffer(points.astype(np.float64)), particle_radius=RADIUS), ref)


@check("CAI strided device input (N, 4) float32, columns 0:3, stride 16 bytes")
def _():
    wide = np.zeros((len(points), 4), np.float32)
    wide[:, :3] = points
    buf = CudaBuffer(wide, view_shape=(len(points), 3), view_strides=(16, 4))
    same(ctx.reconstruct(buf, particle_radius=RADIUS), ref)


@check("module-level reconstruct with a device input")
def _():
    same(nbmc.reconstruct(CudaBuffer(points), particle_radius=RADIUS, backend="cuda"), ref)


@check("a host pointer given as device memory is refused")
def _():
    class HostAsDevice:
        __cuda_array_interface__ = {"shape": points.shape, "typestr": "<f4", "strides": None,
                                    "data": (points.ctypes.data, True), "version": 3}
    try:
        ctx.set_particles(HostAsDevice())
    except nbmc.InvalidArgument as e:
        print("   ", e)
    else:
        raise AssertionError("no error")


@check("device mesh: DeviceArray views, CAI, get(), to_host(), write()")
def _():
    dctx = nbmc.Context("cuda", mesh_memory="device")
    m = dctx.reconstruct(points, particle_radius=RADIUS)
    assert m.memory == "device"
    v, n, t = m.vertices, m.normals, m.triangles
    assert isinstance(v, nbmc.DeviceArray) and v.shape == (ref.vertex_count, 3)
    assert np.array_equal(from_device(v.__cuda_array_interface__), ref.vertices)
    assert np.array_equal(from_device(t.__cuda_array_interface__), ref.triangles)
    assert np.array_equal(from_device(n.__cuda_array_interface__), ref.normals)
    assert np.array_equal(v.get(), ref.vertices) and np.array_equal(t.get(), ref.triangles)
    same(m, ref)
    with tempfile.TemporaryDirectory() as d:
        m.write(Path(d) / "dev.ply")
        ref.write(Path(d) / "host.ply")
        assert (Path(d) / "dev.ply").read_bytes() == (Path(d) / "host.ply").read_bytes()
    del m, dctx  # the arrays keep the mesh alive
    assert np.array_equal(v.get(), ref.vertices)


@check("device mesh from device input (nothing through the host)")
def _():
    dctx = nbmc.Context("cuda", mesh_memory="device")
    m = dctx.reconstruct(CudaBuffer(points), particle_radius=RADIUS)
    same(m, ref)


try:
    import cupy
except Exception:  # noqa: BLE001
    cupy = None
if cupy is not None:
    @check("CuPy: input array and cupy.asarray(mesh.vertices)")
    def _():
        same(ctx.reconstruct(cupy.asarray(points), particle_radius=RADIUS), ref)
        same(ctx.reconstruct(cupy.asarray(points, dtype=cupy.float64)[:, :3], particle_radius=RADIUS), ref)
        m = nbmc.reconstruct(points, particle_radius=RADIUS, backend="cuda", mesh_memory="device")
        assert np.array_equal(cupy.asnumpy(cupy.asarray(m.vertices)), ref.vertices)
        assert np.array_equal(cupy.asnumpy(cupy.from_dlpack(m.triangles)), ref.triangles)
else:
    print("SKIP CuPy (not installed)")

try:
    import torch
except Exception:  # noqa: BLE001
    torch = None
if torch is not None and torch.cuda.is_available():
    @check("PyTorch: CUDA tensor input (CAI and DLPack) and torch.from_dlpack(mesh)")
    def _():
        t = torch.from_numpy(points).cuda()
        same(ctx.reconstruct(t, particle_radius=RADIUS), ref)

        class OnlyDLPack:  # forces the DLPack path
            def __init__(self, x):
                self.x = x

            def __dlpack__(self, stream=None, **kw):
                return self.x.__dlpack__(stream=stream)

            def __dlpack_device__(self):
                return self.x.__dlpack_device__()

        same(ctx.reconstruct(OnlyDLPack(t.double()), particle_radius=RADIUS), ref)
        m = nbmc.reconstruct(points, particle_radius=RADIUS, backend="cuda", mesh_memory="device")
        tv = torch.from_dlpack(m.vertices)
        assert tv.is_cuda and np.array_equal(tv.cpu().numpy(), ref.vertices)
        del m
        assert np.array_equal(tv.cpu().numpy(), ref.vertices)  # the tensor keeps the mesh
else:
    print("SKIP PyTorch (not installed or no CUDA)")

print(f"{len(failures)} failed" if failures else "all passed")
sys.exit(1 if failures else 0)
