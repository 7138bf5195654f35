#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Writes the sample particle files in tests/data/ with other tools than nbmc:
h5py (HDF5 layouts) and VTK's own Python writers (legacy VTK, VTU, VTP).
Run once by hand (Debian: python3-h5py python3-vtk9 python3-numpy):

    /usr/bin/python3 tests/data/generate.py

Every file holds the same N = 20 particles (test_io_formats.cpp recomputes
them):  x = 0.1 i,  y = 0.5 + 0.01 i^2,  z = -1 + 0.05 i,
velocity = (i, -i, 0.5 i),  density = 1000 + i,  for i = 0 .. 19.
H5Part step s (s = 0, 1, 2) adds s to x and has TimeValue 0.25 s.

The BGEO samples are the only ones not written by another program: no
Debian package writes Houdini classic geometry, so small_points.bgeo is
encoded here from the format description (the same layout partio writes);
the real partio files of ../shared/data/raw are read by the tests as well.
"""
import gzip
import os
import struct

import h5py
import numpy as np
import vtk
from vtk.util import numpy_support

HERE = os.path.dirname(os.path.abspath(__file__))
N = 20
i = np.arange(N, dtype=np.float64)
X = 0.1 * i
Y = 0.5 + 0.01 * i * i
Z = -1.0 + 0.05 * i
VEL = np.stack([i, -i, 0.5 * i], axis=1)
RHO = 1000.0 + i


def path(name):
    return os.path.join(HERE, name)


# ------------------------------------------------------------------ HDF5
def h5part():
    # H5Part as H5Part/H5hut and SPH-EXA write it: Step#<n> groups with 1-D
    # datasets and a TimeValue attribute. Step 1 is float32, chunked and
    # deflate-compressed; step 2 float64 contiguous without velocity.
    with h5py.File(path("h5part_steps.h5part"), "w") as f:
        for s in range(3):
            g = f.create_group("Step#%d" % s)
            g.attrs["TimeValue"] = 0.25 * s
            if s == 1:
                kw = dict(dtype=np.float32, chunks=(8,), compression="gzip", compression_opts=4)
            else:
                kw = dict(dtype=np.float64)
            g.create_dataset("x", data=X + s, **kw)
            g.create_dataset("y", data=Y, **kw)
            g.create_dataset("z", data=Z, **kw)
            if s != 2:
                g.create_dataset("vx", data=VEL[:, 0], **kw)
                g.create_dataset("vy", data=VEL[:, 1], **kw)
                g.create_dataset("vz", data=VEL[:, 2], **kw)
            g.create_dataset("rho", data=RHO, **kw)
            g.create_dataset("id", data=np.arange(N, dtype=np.int64))
    # SPH-EXA style: same layout, .h5 extension, time as "time" attribute
    with h5py.File(path("sphexa_dump.h5"), "w") as f:
        g = f.create_group("Step#0")
        g.attrs["time"] = 1.5
        g.attrs["iteration"] = 7
        for name, data in (("x", X), ("y", Y), ("z", Z), ("vx", VEL[:, 0]), ("vy", VEL[:, 1]),
                           ("vz", VEL[:, 2]), ("rho", RHO), ("h", np.full(N, 0.02))):
            g.create_dataset(name, data=data.astype(np.float64))


def pysph():
    with h5py.File(path("pysph_output.hdf5"), "w") as f:
        sd = f.create_group("solver_data")
        sd.attrs["t"] = 0.125
        sd.attrs["dt"] = 1e-4
        sd.attrs["count"] = 1250
        p = f.create_group("particles")
        for name, shift in (("boundary", 10.0), ("fluid", 0.0)):
            a = p.create_group(name).create_group("arrays")
            a.create_dataset("x", data=X + shift)
            a.create_dataset("y", data=Y)
            a.create_dataset("z", data=Z)
            a.create_dataset("u", data=VEL[:, 0])
            a.create_dataset("v", data=VEL[:, 1])
            a.create_dataset("w", data=VEL[:, 2])
            a.create_dataset("rho", data=RHO)
            a.create_dataset("tag", data=np.zeros(N, dtype=np.int32))


def gadget():
    with h5py.File(path("gadget_snapshot.hdf5"), "w") as f:
        h = f.create_group("Header")
        h.attrs["NumPart_ThisFile"] = np.array([N, 0, 0, 0, 0, 0], dtype=np.uint32)
        h.attrs["NumPart_Total"] = np.array([N, 0, 0, 0, 0, 0], dtype=np.uint32)
        h.attrs["Time"] = 0.75
        h.attrs["BoxSize"] = 10.0
        p = f.create_group("PartType0")
        pos = np.stack([X, Y, Z], axis=1).astype(np.float32)
        p.create_dataset("Coordinates", data=pos, chunks=(5, 3), compression="gzip")
        p.create_dataset("Velocities", data=VEL.astype(np.float32), chunks=(5, 3), compression="gzip")
        p.create_dataset("Density", data=RHO.astype(np.float32))
        p.create_dataset("ParticleIDs", data=np.arange(N, dtype=np.uint64))
        p1 = f.create_group("PartType1")
        p1.create_dataset("Coordinates", data=pos[:5].astype(np.float64))


def generic():
    with h5py.File(path("generic.h5"), "w") as f:
        f.create_dataset("data/positions", data=np.stack([X, Y, Z], axis=1))
        g = f.create_group("cloud")
        g.create_dataset("x", data=X.astype(np.float32))
        g.create_dataset("y", data=Y.astype(np.float32))
        g.create_dataset("z", data=Z.astype(np.float32))
        g.create_dataset("density", data=RHO.astype(np.float32))
        f.create_dataset("not_positions", data=np.zeros((N, 2)))


def lying():
    # Datasets that declare 2^31 values but store none (chunked, no chunk
    # written: HDF5 would return fill values): the reader must refuse them
    # instead of allocating 16 GiB.
    with h5py.File(path("hdf5_unwritten.h5part"), "w") as f:
        g = f.create_group("Step#0")
        for name in ("x", "y", "z"):
            g.create_dataset(name, shape=(2 ** 31,), dtype=np.float64, chunks=(4096,))
    # Wrongly typed and mismatched datasets, one problem per step.
    with h5py.File(path("hdf5_wrong.h5part"), "w") as f:
        g = f.create_group("Step#0")  # x is text
        g.create_dataset("x", data=np.array([b"a", b"b"], dtype="S1"))
        g.create_dataset("y", data=np.zeros(2))
        g.create_dataset("z", data=np.zeros(2))
        g = f.create_group("Step#1")  # y is 2-D
        g.create_dataset("x", data=np.zeros(4))
        g.create_dataset("y", data=np.zeros((2, 2)))
        g.create_dataset("z", data=np.zeros(4))
        g = f.create_group("Step#2")  # z is shorter
        g.create_dataset("x", data=np.zeros(4))
        g.create_dataset("y", data=np.zeros(4))
        g.create_dataset("z", data=np.zeros(3))
        g = f.create_group("Step#3")  # z is missing
        g.create_dataset("x", data=np.zeros(4))
        g.create_dataset("y", data=np.zeros(4))


# ------------------------------------------------------------------- VTK
def poly(double=False, cells=True):
    pts = vtk.vtkPoints()
    pts.SetDataTypeToDouble() if double else pts.SetDataTypeToFloat()
    for k in range(N):
        pts.InsertNextPoint(X[k], Y[k], Z[k])
    pd = vtk.vtkPolyData()
    pd.SetPoints(pts)
    if cells:
        verts = vtk.vtkCellArray()
        for k in range(N):
            verts.InsertNextCell(1)
            verts.InsertCellPoint(k)
        pd.SetVerts(verts)
    vel = numpy_support.numpy_to_vtk(VEL.astype(np.float32), deep=True)
    vel.SetName("velocity")
    rho = numpy_support.numpy_to_vtk(RHO.astype(np.float64), deep=True)
    rho.SetName("density")
    pd.GetPointData().AddArray(vel)
    pd.GetPointData().AddArray(rho)
    return pd


def ugrid(double=False):
    pd = poly(double, cells=False)
    ug = vtk.vtkUnstructuredGrid()
    ug.SetPoints(pd.GetPoints())
    ug.Allocate(N)
    for k in range(N):
        ug.InsertNextCell(vtk.VTK_VERTEX, 1, [k])
    ug.GetPointData().ShallowCopy(pd.GetPointData())
    return ug


def legacy():
    cases = [
        ("legacy_poly_ascii.vtk", vtk.vtkPolyDataWriter, poly(), False, 42),
        ("legacy_poly_binary.vtk", vtk.vtkPolyDataWriter, poly(double=True), True, 42),
        ("legacy_ugrid_binary.vtk", vtk.vtkUnstructuredGridWriter, ugrid(), True, 42),
        ("legacy51_poly_ascii.vtk", vtk.vtkPolyDataWriter, poly(), False, 51),
        ("legacy51_ugrid_binary.vtk", vtk.vtkUnstructuredGridWriter, ugrid(double=True), True, 51),
    ]
    for name, cls, data, binary, version in cases:
        w = cls()
        w.SetFileName(path(name))
        w.SetInputData(data)
        if binary:
            w.SetFileTypeToBinary()
        else:
            w.SetFileTypeToASCII()
        if version == 42:
            w.SetFileVersion(42)
        w.Write()


def xml():
    cases = [
        # name, writer, data, mode, compressed, header64, encode appended
        ("appended_raw.vtu", "u", "appended", False, False, False),
        ("appended_raw_zlib.vtu", "u", "appended", True, False, False),
        ("appended_raw_zlib64.vtu", "u", "appended", True, True, False),
        ("appended_base64_zlib.vtu", "u", "appended", True, False, True),
        ("appended_base64.vtu", "u", "appended", False, True, True),
        ("inline_binary.vtu", "u", "binary", False, False, False),
        ("inline_binary_zlib64.vtu", "u", "binary", True, True, False),
        ("ascii.vtu", "u", "ascii", False, False, False),
        ("appended_raw_zlib.vtp", "p", "appended", True, False, False),
    ]
    for name, kind, mode, compressed, header64, encode in cases:
        if kind == "u":
            w = vtk.vtkXMLUnstructuredGridWriter()
            w.SetInputData(ugrid(double=name.startswith("inline_binary_zlib")))
        else:
            w = vtk.vtkXMLPolyDataWriter()
            w.SetInputData(poly())
        w.SetFileName(path(name))
        {"appended": w.SetDataModeToAppended, "binary": w.SetDataModeToBinary,
         "ascii": w.SetDataModeToAscii}[mode]()
        if compressed:
            w.SetCompressorTypeToZLib()
            w.SetBlockSize(64)  # several blocks for 20 particles
        else:
            w.SetCompressorTypeToNone()
        if header64:
            w.SetHeaderTypeToUInt64()
        else:
            w.SetHeaderTypeToUInt32()
        if mode == "appended":
            w.SetEncodeAppendedData(1 if encode else 0)
        w.Write()


# ------------------------------------------------------------------ BGEO
def bgeo():
    out = bytearray()
    out += b"Bgeo" + b"V" + struct.pack(">i", 5)
    # points, prims, point groups, prim groups, point/vertex/prim/detail attributes
    out += struct.pack(">8i", N, 0, 0, 0, 3, 0, 0, 0)

    def attr(name, size, htype, default):
        b = struct.pack(">H", len(name)) + name.encode() + struct.pack(">Hi", size, htype)
        return b + default

    out += attr("id", 1, 1, struct.pack(">i", 0))
    out += attr("velocity", 3, 5, struct.pack(">3f", 0, 0, 0))
    out += attr("density", 1, 0, struct.pack(">f", 0))
    for k in range(N):
        out += struct.pack(">4f", X[k], Y[k], Z[k], 1.0)
        out += struct.pack(">i", k)
        out += struct.pack(">3f", *VEL[k])
        out += struct.pack(">f", RHO[k])
    out += b"\x00\xff"
    with open(path("small_points.bgeo"), "wb") as f:
        f.write(out)
    with gzip.open(path("small_points.bgeo.gz"), "wb") as f:
        f.write(out)


if __name__ == "__main__":
    h5part()
    pysph()
    gadget()
    generic()
    lying()
    legacy()
    xml()
    bgeo()
    print("written to", HERE)
