#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Opens nbmc's HDF5 + XDMF meshes with ParaView's XDMF readers.

    check_xdmf.py NBMC_BINARY STEPS.h5part SPACING

Writes the steps 0, 1, 2 of an H5Part file (with the particle attribute
"rho" interpolated to the vertices) into one .h5 file with a temporal .xdmf
collection, and the same frames as .vtp; opens the .xdmf with every XDMF reader available (ParaView's
vtkXdmfReader and vtkXdmf3Reader) and checks the time steps, and that points,
triangles, normals and the attribute equal those of the .vtp read with VTK's
XML reader, value for value. A single mesh (.h5 without frames) is checked the
same way. Exits 77 (ctest: skipped) when no XDMF reader can be imported.
"""
import os
import shutil
import subprocess
import sys
import tempfile

SKIP = 77


def import_readers():
    """(name, class) of the XDMF readers and the VTK XML PolyData reader."""
    readers = []
    xml = None
    # ParaView's Python (Debian: python3-paraview) ships the XDMF readers.
    for mod, cls in (("vtkIOXdmf2", "vtkXdmfReader"), ("vtkIOXdmf3", "vtkXdmf3Reader")):
        for pkg in ("paraview.modules", "vtkmodules"):
            try:
                m = __import__(pkg + "." + mod, fromlist=[cls])
                readers.append((cls, getattr(m, cls)))
                break
            except (ImportError, AttributeError):
                continue
    for pkg in ("paraview.modules", "vtkmodules"):
        try:
            m = __import__(pkg + ".vtkIOXML", fromlist=["vtkXMLPolyDataReader"])
            xml = m.vtkXMLPolyDataReader
            break
        except (ImportError, AttributeError):
            continue
    return readers, xml


def numpy_of(array):
    for pkg in ("paraview.modules", "vtkmodules"):
        try:
            m = __import__(pkg + ".util.numpy_support", fromlist=["vtk_to_numpy"])
            return m.vtk_to_numpy(array).copy()  # owns its memory
        except ImportError:
            continue
    raise ImportError("no vtk numpy_support")


def first_leaf(data):
    """The dataset itself, or the first leaf of a composite dataset."""
    if data is None or not data.IsA("vtkCompositeDataSet"):
        return data
    it = data.NewIterator()
    it.InitTraversal()
    return None if it.IsDoneWithTraversal() else it.GetCurrentDataObject()


def mesh_arrays(data):
    """Points, triangle connectivity and point data of a mesh as numpy arrays."""
    cells = data.GetPolys() if data.IsA("vtkPolyData") else data.GetCells()
    if data.IsA("vtkUnstructuredGrid"):
        types = set(data.GetCellType(i) for i in range(data.GetNumberOfCells()))
        assert types <= {5}, "cells other than triangles: %s" % types
    out = {"points": numpy_of(data.GetPoints().GetData()),
           "connectivity": numpy_of(cells.GetConnectivityArray()).astype("int64")}
    pd = data.GetPointData()
    for i in range(pd.GetNumberOfArrays()):
        out["pd:" + pd.GetArrayName(i)] = numpy_of(pd.GetArray(i))
    return out


def same(a, b, what):
    import numpy
    if set(a) != set(b):
        raise AssertionError("%s: arrays differ: %s vs %s" % (what, sorted(a), sorted(b)))
    for k in a:
        x, y = numpy.asarray(a[k]), numpy.asarray(b[k])
        if k == "pd:rho":  # float64 in the .h5, Float32 in the .vtp
            x, y = x.astype("float32"), y.astype("float32")
        if x.shape != y.shape or not numpy.array_equal(x.astype(y.dtype), y):
            raise AssertionError("%s: %s differs (shapes %s, %s)" % (what, k, x.shape, y.shape))


def read_xdmf(cls, path, time=None):
    r = cls()
    r.SetFileName(path)
    r.UpdateInformation()
    info = r.GetOutputInformation(0)
    key = None
    for pkg in ("paraview.modules", "vtkmodules"):
        try:
            key = __import__(pkg + ".vtkCommonExecutionModel",
                             fromlist=["vtkStreamingDemandDrivenPipeline"]).vtkStreamingDemandDrivenPipeline
            break
        except ImportError:
            continue
    steps = list(info.Get(key.TIME_STEPS())) if info.Has(key.TIME_STEPS()) else []
    if time is None:
        r.Update()
    else:
        r.UpdateTimeStep(time)
    # Copied while the reader lives: vtkXdmf3Reader's arrays point into
    # memory the reader frees with itself.
    data = first_leaf(r.GetOutputDataObject(0))
    if data is None or data.GetNumberOfPoints() == 0:
        return steps, None
    return steps, mesh_arrays(data)


def main():
    if len(sys.argv) != 4:
        print(__doc__)
        return 2
    nbmc, frames, spacing = sys.argv[1], os.path.abspath(sys.argv[2]), sys.argv[3]
    try:
        readers, xml = import_readers()
        import numpy
    except ImportError as e:
        print("skipped: %s" % e)
        return SKIP
    if not readers or xml is None:
        print("skipped: no XDMF reader in this Python (install python3-paraview)")
        return SKIP
    tmp = tempfile.mkdtemp(prefix="nbmc_xdmf_")
    try:
        run = [nbmc, "reconstruct", frames, "--spacing", spacing, "--attributes", "rho", "-q", "-o"]
        for out in ("out/s_{}.h5", "out/v_{}.vtp"):
            subprocess.run(run + [out, "--frames", "0:2"], cwd=tmp, check=True)
        subprocess.run(run + ["one.h5", "--frames", "1:1"], cwd=tmp, check=True)

        def vtp(i):
            r = xml()
            r.SetFileName(os.path.join(tmp, "out", "v_%d.vtp" % i))
            r.Update()
            return mesh_arrays(r.GetOutput())

        for name, cls in readers:
            steps, _ = read_xdmf(cls, os.path.join(tmp, "out", "s.xdmf"))
            if [float(t) for t in steps] != [0.0, 1.0, 2.0]:
                raise AssertionError("%s: time steps %s, expected [0, 1, 2]" % (name, steps))
            for i in (0, 1, 2):
                _, data = read_xdmf(cls, os.path.join(tmp, "out", "s.xdmf"), float(i))
                if data is None:
                    raise AssertionError("%s: frame %d is empty" % (name, i))
                same(data, vtp(i), "%s frame %d" % (name, i))
            _, data = read_xdmf(cls, os.path.join(tmp, "one.xdmf"))
            if data is None:
                raise AssertionError("%s: the single mesh is empty" % name)
            same(data, vtp(1), "%s single mesh" % name)
            print("%s: 3 time steps and the single mesh equal the .vtp meshes (%d points in step 1)"
                  % (name, len(data["points"])))
        return 0
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
