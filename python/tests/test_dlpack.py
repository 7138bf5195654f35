# SPDX-License-Identifier: MIT
"""DLPack and __cuda_array_interface__ plumbing, tested with host memory
(tests/gpu_check.py runs the real device paths on a GPU machine)."""
import gc

import numpy as np
import pytest

import nbmc
from nbmc import _arrays as A


class Exporter:
    """A DLPack producer over a numpy array through nbmc's exporter."""

    def __init__(self, arr, device=(A.KDL_CPU, 0)):
        self.arr = arr
        self.device = device

    def __dlpack_device__(self):
        return self.device

    def __dlpack__(self, stream=None, **kw):
        return A.to_dlpack(self.arr.ctypes.data, self.arr.shape, self.arr.dtype, self.device[0],
                           self.device[1], self.arr)


@pytest.mark.parametrize("dtype", [np.float32, np.uint32, np.float64])
def test_exported_capsule_is_read_by_numpy(dtype):
    a = np.arange(12, dtype=dtype).reshape(4, 3)
    before = len(A._exports)
    b = np.from_dlpack(Exporter(a))
    assert b.ctypes.data == a.ctypes.data and b.dtype == a.dtype and np.array_equal(a, b)
    assert len(A._exports) == before + 1
    del b
    gc.collect()
    assert len(A._exports) == before  # numpy called the deleter


def test_unconsumed_capsule_frees_its_export():
    a = np.zeros((2, 3), np.float32)
    before = len(A._exports)
    cap = Exporter(a).__dlpack__()
    assert len(A._exports) == before + 1
    del cap
    gc.collect()
    assert len(A._exports) == before


def test_reading_a_capsule():
    a = np.arange(30, dtype=np.float64).reshape(10, 3)[::2]
    view, release = A.from_dlpack_capsule(a.__dlpack__())
    assert view.pointer == a.ctypes.data and view.shape == (5, 3)
    assert view.strides == a.strides and view.dtype == np.float64
    assert view.device_type == A.KDL_CPU
    release()


def test_host_mesh_arrays_through_the_exporter(mesh):
    # numpy will not DLPack-export read-only arrays; nbmc's exporter (used by
    # DeviceArray) does, and keeps the mesh alive meanwhile.
    v = np.from_dlpack(Exporter(mesh.vertices))
    assert v.ctypes.data == mesh.vertices.ctypes.data


def test_device_array_interfaces(mesh):
    """DeviceArray over a host pointer: only the descriptions are checked."""
    d = A.DeviceArray(mesh.vertices.ctypes.data, mesh.vertices.shape, np.float32, 0,
                      mesh._h, "vertices")
    cai = d.__cuda_array_interface__
    assert cai["shape"] == mesh.vertices.shape and cai["typestr"] == "<f4"
    assert cai["data"] == (mesh.vertices.ctypes.data, True) and cai["version"] == 3
    assert d.__dlpack_device__() == (A.KDL_CUDA, 0)
    view, release = A.from_dlpack_capsule(d.__dlpack__())
    assert view.device_type == A.KDL_CUDA and view.pointer == mesh.vertices.ctypes.data
    assert view.shape == mesh.vertices.shape and view.strides is None
    release()
    assert np.array_equal(d.get(), mesh.vertices)  # nbmc_mesh_copy_to_host
    assert len(d) == mesh.vertex_count and "cuda:0" in repr(d)


def test_device_inputs_are_recognised_and_released():
    a = np.zeros((4, 3), np.float32)
    fake = Exporter(a, (A.KDL_CUDA, 0))
    assert A.is_device_array(fake) and not A.is_device_array(a)
    d = A.device_points(fake)
    assert (d.pointer, d.count, d.byte_stride, d.double) == (a.ctypes.data, 4, 12, False)
    d.release()
    before = len(A._exports)
    with pytest.raises(nbmc.BackendUnavailable):
        nbmc.Context("serial").set_particles(Exporter(np.zeros((4, 3)), (A.KDL_CUDA, 0)))
    gc.collect()
    assert len(A._exports) == before  # the upload released the producer's tensor
    with pytest.raises(ValueError):
        A.device_points(Exporter(np.zeros((4, 3)), (A.KDL_CPU, 0)))


def test_mesh_to_host_copies(mesh):
    v, n, t = mesh.to_host()
    assert v.ctypes.data != mesh.vertices.ctypes.data
    assert np.array_equal(v, mesh.vertices) and np.array_equal(n, mesh.normals)
    assert np.array_equal(t, mesh.triangles)
