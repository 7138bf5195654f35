# SPDX-License-Identifier: MIT
"""Every mesh writer (bytes equal the CLI's, contents read back), every
particle reader on files made here, and {} sequences."""
import json
import struct
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import nbmc
from conftest import DATA, RADIUS, run_cli

WRITERS = ["ply", "obj", "vtk", "vtu", "glb"]


@pytest.fixture(scope="module")
def frame():
    return np.fromfile(DATA, dtype="<f4").reshape(-1, 3)


@pytest.fixture(scope="module")
def coarse(frame):
    """A cheap mesh for the reader tests (cell size r)."""
    return nbmc.reconstruct(frame, particle_radius=RADIUS, cell_size=1, threads=1)


def parse_obj(path):
    v, vn, f = [], [], []
    for line in path.read_text().splitlines():
        w = line.split()
        if not w or w[0].startswith("#"):
            continue
        if w[0] == "v":
            v.append(w[1:4])
        elif w[0] == "vn":
            vn.append(w[1:4])
        elif w[0] == "f":
            f.append([int(x.split("//")[0]) - 1 for x in w[1:4]])
    return np.array(v, np.float32), np.array(vn, np.float32), np.array(f, np.uint32)


def parse_vtk(path):
    raw = path.read_bytes()
    at = raw.index(b"POINTS ")
    eol = raw.index(b"\n", at)
    n = int(raw[at:eol].split()[1])
    pts = np.frombuffer(raw, ">f4", 3 * n, eol + 1).reshape(n, 3)
    at = raw.index(b"POLYGONS ")
    eol = raw.index(b"\n", at)
    return pts, raw[at:eol].split()


def parse_vtu(path):
    raw = path.read_bytes()
    start = raw.index(b"<AppendedData")
    base = raw.index(b"_", start) + 1
    root = ET.fromstring(raw[:start].decode() + "</VTKFile>")
    piece = root.find("UnstructuredGrid/Piece")
    n = int(piece.get("NumberOfPoints"))

    def array(name, dtype, count):
        el = next(e for e in root.iter("DataArray") if e.get("Name") == name)
        off = base + int(el.get("offset"))
        size = struct.unpack("<Q", raw[off:off + 8])[0]
        assert size == count * np.dtype(dtype).itemsize
        return np.frombuffer(raw, dtype, count, off + 8)

    t = int(piece.get("NumberOfCells"))
    return (array("Points", "<f4", 3 * n).reshape(n, 3), array("Normals", "<f4", 3 * n).reshape(n, 3),
            array("connectivity", "<i8", 3 * t).reshape(t, 3))


def parse_glb(path):
    raw = path.read_bytes()
    magic, version, length = struct.unpack("<4sII", raw[:12])
    assert magic == b"glTF" and version == 2 and length == len(raw)
    jlen, jtype = struct.unpack("<II", raw[12:20])
    doc = json.loads(raw[20:20 + jlen])
    blen, btype = struct.unpack("<II", raw[20 + jlen:28 + jlen])
    assert jtype == 0x4E4F534A and btype == 0x004E4942
    binary = raw[28 + jlen:28 + jlen + blen]
    prim = doc["meshes"][0]["primitives"][0]

    def accessor(i, dtype, width):
        a = doc["accessors"][i]
        view = doc["bufferViews"][a["bufferView"]]
        off = view.get("byteOffset", 0) + a.get("byteOffset", 0)
        return np.frombuffer(binary, dtype, a["count"] * width, off).reshape(-1, 3)

    return (accessor(prim["attributes"]["POSITION"], "<f4", 3),
            accessor(prim["attributes"]["NORMAL"], "<f4", 3), accessor(prim["indices"], "<u4", 1))


@pytest.mark.parametrize("fmt", WRITERS)
def test_writer_equals_cli_and_reads_back(mesh, tmp_path, fmt):
    cli = tmp_path / f"cli.{fmt}"
    run_cli(DATA, "--particle-radius", RADIUS, "-o", cli)
    py = tmp_path / f"py.{fmt}"
    mesh.write(py)
    assert py.read_bytes() == cli.read_bytes()
    other = tmp_path / "by_name.bin"
    mesh.write(other, format=fmt)  # the format argument instead of the extension
    assert other.read_bytes() == cli.read_bytes()
    v, n, t = mesh.vertices, mesh.normals, mesh.triangles
    if fmt == "obj":
        ov, on, of = parse_obj(py)
        assert np.array_equal(ov, v) and np.allclose(on, n, atol=1e-6) and np.array_equal(of, t)
    elif fmt == "vtk":
        pv, polygons = parse_vtk(py)
        assert np.array_equal(pv, v) and int(polygons[1]) == mesh.triangle_count
    elif fmt == "vtu":
        pv, pn, pc = parse_vtu(py)
        assert np.array_equal(pv, v) and np.array_equal(pn, n) and np.array_equal(pc, t)
    elif fmt == "glb":
        gv, gn, gt = parse_glb(py)
        assert np.array_equal(gv, v) and np.allclose(gn, n, atol=1e-6) and np.array_equal(gt, t)
    if fmt in ("ply", "vtk", "vtu"):  # nbmc's particle readers take its own mesh files
        assert nbmc.read_particles(py).count == mesh.vertex_count


def test_write_replaces_only_on_success(mesh, tmp_path):
    out = tmp_path / "m.ply"
    out.write_bytes(b"old")
    with pytest.raises(nbmc.InvalidArgument):
        mesh.write(out, format="nope")
    assert out.read_bytes() == b"old"
    mesh.write(out)
    assert out.read_bytes()[:3] == b"ply"


# ---------------------------------------------------------------- readers
def write_ply_ascii(path, p):
    head = ("ply\nformat ascii 1.0\ncomment made by test_io\nelement vertex %d\n"
            "property float x\nproperty float y\nproperty float z\nproperty float rho\nend_header\n")
    rows = "\n".join(f"{x!r} {y!r} {z!r} 1000.0" for x, y, z in p.astype(float).tolist())
    path.write_text(head % len(p) + rows + "\n")


def write_ply_binary(path, p):
    head = ("ply\nformat binary_big_endian 1.0\nelement vertex %d\nproperty double x\n"
            "property double y\nproperty double z\nend_header\n") % len(p)
    path.write_bytes(head.encode() + p.astype(">f8").tobytes())


def write_vtk(path, p):
    path.write_text("# vtk DataFile Version 3.0\nparticles\nASCII\nDATASET POLYDATA\n"
                    f"POINTS {len(p)} double\n" +
                    "\n".join(" ".join(repr(c) for c in r) for r in p.astype(float).tolist()) + "\n")


def write_vtk_xml(path, p, kind):
    pts = " ".join(repr(c) for c in p.astype(float).ravel().tolist())
    extra = 'NumberOfCells="0"' if kind == "UnstructuredGrid" else 'NumberOfPolys="0"'
    path.write_text(
        f'<?xml version="1.0"?>\n<VTKFile type="{kind}" version="0.1" byte_order="LittleEndian">'
        f'<{kind}><Piece NumberOfPoints="{len(p)}" {extra}><Points>'
        f'<DataArray type="Float64" NumberOfComponents="3" format="ascii">{pts}</DataArray>'
        f"</Points></Piece></{kind}></VTKFile>\n")


def write_bgeo(path, p, gz=False):
    """Houdini classic geometry, version 5 (big-endian), with a vector attribute 'v'."""
    import gzip
    n = len(p)
    head = b"BgeoV" + struct.pack(">9i", 5, n, 0, 0, 0, 1, 0, 0, 0)
    attr = struct.pack(">H", 1) + b"v" + struct.pack(">Hi3f", 3, 5, 0, 0, 0)
    rec = np.zeros((n, 7), ">f4")
    rec[:, :3] = p
    rec[:, 3] = 1.0  # w
    rec[:, 4:] = 0.5  # v
    data = head + attr + rec.tobytes()
    path.write_bytes(gzip.compress(data) if gz else data)


def h5py_or_skip():
    return pytest.importorskip("h5py")


def write_h5part(path, p):
    h5py = h5py_or_skip()
    with h5py.File(path, "w") as f:
        for step, q in enumerate([p, p[:100]]):  # the first step is read
            g = f.create_group(f"Step#{step}")
            g.attrs["TimeValue"] = 0.1 * step
            for i, c in enumerate("xyz"):
                g[c] = q[:, i].astype(np.float64)
            g["vx"] = np.zeros(len(q))


def write_pysph(path, p):
    h5py = h5py_or_skip()
    with h5py.File(path, "w") as f:
        a = f.create_group("particles/fluid/arrays")
        for i, c in enumerate("xyz"):
            a[c] = p[:, i]
        a["rho"] = np.ones(len(p))
        f.create_group("particles/boundary/arrays")["x"] = np.zeros(3)


def write_gadget(path, p):
    h5py = h5py_or_skip()
    with h5py.File(path, "w") as f:
        f["PartType0/Coordinates"] = p.astype(np.float64)
        f["PartType0/Density"] = np.ones(len(p), np.float32)
        f.create_group("Header").attrs["Time"] = 1.5


def write_object(path, p):
    h5py = h5py_or_skip()
    with h5py.File(path, "w") as f:
        f.create_dataset("run/positions", data=p, chunks=(1000, 3), compression="gzip")
        f["run/other"] = np.zeros((5, 3))


READERS = {
    # name: (file name, writer, format argument, object suffix)
    "xyz": ("p.xyz", lambda path, p: p.astype("<f4").tofile(path), None, ""),
    "ply ascii": ("p.ply", write_ply_ascii, None, ""),
    "ply binary big-endian double": ("p.ply", write_ply_binary, None, ""),
    "vtk legacy ascii": ("p.vtk", write_vtk, None, ""),
    "vtu ascii": ("p.vtu", lambda path, p: write_vtk_xml(path, p, "UnstructuredGrid"), None, ""),
    "vtp ascii": ("p.vtp", lambda path, p: write_vtk_xml(path, p, "PolyData"), None, ""),
    "bgeo": ("p.bgeo", write_bgeo, None, ""),
    "bgeo gzip": ("p.bgeo.gz", lambda path, p: write_bgeo(path, p, gz=True), None, ""),
    "bgeo gzip without .gz": ("p.bgeo", lambda path, p: write_bgeo(path, p, gz=True), None, ""),
    "xyz under another name": ("p.bin", lambda path, p: p.astype("<f4").tofile(path), "xyz", ""),
    "h5part (first step)": ("p.h5part", write_h5part, None, ""),
    "h5part detected in .h5": ("p.h5", write_h5part, None, ""),
    "pysph": ("p.hdf5", write_pysph, "pysph", ""),
    "pysph detected": ("p.hdf5", write_pysph, None, ""),
    "gadget": ("snap.hdf5", write_gadget, "gadget", ""),
    "swift detected": ("snap.hdf5", write_gadget, None, ""),
    "hdf5 object (N x 3 dataset)": ("d.h5", write_object, None, ":/run/positions"),
}


@pytest.mark.parametrize("name", list(READERS))
def test_readers(frame, coarse, tmp_path, name):
    fname, writer, fmt, obj = READERS[name]
    path = tmp_path / fname
    writer(path, frame)
    p = nbmc.read_particles(str(path) + obj, fmt, threads=1)
    assert p.count == len(frame) and len(p) == len(frame)
    m = p.reconstruct(particle_radius=RADIUS, cell_size=1)
    assert np.array_equal(m.vertices, coarse.vertices)
    assert np.array_equal(m.triangles, coarse.triangles)
    with nbmc.Context(threads=1) as ctx:
        assert ctx.load_particles(str(path) + obj, fmt) == len(frame)
        assert ctx.particle_count == len(frame)


def test_particles_handle_rereads_after_replacement(frame, coarse, tmp_path):
    path = tmp_path / "p.xyz"
    frame.tofile(path)
    p = nbmc.read_particles(path, threads=1)
    p.context.set_particles(frame[:10])
    m = p.reconstruct(particle_radius=RADIUS, cell_size=1)
    assert np.array_equal(m.vertices, coarse.vertices)
    assert "4732" in repr(p)


def test_read_particles_has_no_attributes_yet(tmp_path):
    with pytest.raises(NotImplementedError):
        nbmc.read_particles(DATA, attributes=["rho"])


# -------------------------------------------------------------- sequences
def test_frames_numeric_order_and_filter(tmp_path, frame):
    folder = tmp_path / "frames"
    folder.mkdir()
    for label in ["2", "10", "007", "1"]:
        frame[: 500 * int(label)].tofile(folder / f"fluid_{label}.xyz")
    for other in ["fluid_.xyz", "fluid_x1.xyz", "fluid_3.xyz.bak", "other_4.xyz"]:
        (folder / other).write_bytes(b"")
    pattern = str(folder / "fluid_{}.xyz")
    found = list(nbmc.frames(pattern))
    assert [f.number for f in found] == [1, 2, 7, 10]
    assert [f.label for f in found] == ["1", "2", "007", "10"]
    assert found[2].path == str(folder / "fluid_007.xyz")
    assert found[2].output("out/s_{}.ply") == "out/s_007.ply"
    assert [f.number for f in nbmc.frames(pattern, numbers=range(2, 11, 5))] == [2, 7]
    with nbmc.Context(threads=1) as ctx:
        counts = [(f.number, ctx.stats.particle_count, m.triangle_count > 0)
                  for f, m in ctx.reconstruct_frames(pattern, particle_radius=RADIUS, cell_size=1)]
    assert counts == [(1, 500, True), (2, 1000, True), (7, 3500, True), (10, 4732, True)]


def test_frames_bad_patterns(tmp_path):
    with pytest.raises(ValueError):
        list(nbmc.frames(tmp_path / "no_braces.xyz"))
    with pytest.raises(ValueError):
        list(nbmc.frames(tmp_path / "{}" / "f_{}.xyz"))
    with pytest.raises(ValueError):
        list(nbmc.frames(str(tmp_path / "{}") + "/f.xyz"))
    with pytest.raises(FileNotFoundError):
        list(nbmc.frames(tmp_path / "missing" / "f_{}.xyz"))
    assert list(nbmc.frames(tmp_path / "f_{}.xyz")) == []
