# SPDX-License-Identifier: MIT
"""Meshes equal the CLI's bit for bit; inputs of every layout; views; stats."""
import gc
import threading

import numpy as np
import pytest

import nbmc
from nbmc import _arrays
from conftest import DATA, RADIUS, read_ply, run_cli


def same_mesh(a, b):
    assert a.vertex_count == b.vertex_count and a.triangle_count == b.triangle_count
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.triangles, b.triangles)
    if a.normals is None:
        assert b.normals is None
    else:
        assert np.array_equal(a.normals, b.normals)


def test_equals_cli_bit_for_bit(mesh, cli_ply, tmp_path):
    v, n, t = read_ply(cli_ply)
    assert mesh.vertex_count > 1000
    assert np.array_equal(mesh.vertices, v)
    assert np.array_equal(mesh.normals, n)
    assert np.array_equal(mesh.triangles, t)
    out = tmp_path / "py.ply"
    mesh.write(out)
    assert out.read_bytes() == cli_ply.read_bytes()


@pytest.mark.parametrize("cli, kw", [
    (["--cell-size", "1", "--method", "zb05", "--no-normals"],
     dict(cell_size=1, method="zb05", normals=False)),
    (["--method", "sph", "--influence-radius", "2", "--iso-threshold", "0.5"],
     dict(method="sph", influence_radius=2, iso_threshold=0.5)),
    (["--method", "yt10", "--aniso-kr", "3", "--aniso-ks", "0.9", "--aniso-kn", "0.6",
      "--aniso-neighbours", "20", "--aniso-lambda", "0.5", "--iso-threshold", "0.5"],
     dict(method="yt10", aniso_kr=3, aniso_ks=0.9, aniso_kn=0.6, aniso_neighbours=20,
          aniso_lambda=0.5, iso_threshold=0.5)),
    (["--isolated", "drop", "--min-cluster", "20"], dict(isolated="drop", min_cluster=20)),
    (["--smooth", "5", "--smooth-weights", "feature", "--decimate", "0.3"],
     dict(smooth=5, smooth_weights="feature", decimate=0.3)),
    (["--cell-size", "0.75", "--influence-radius", "3", "--surface-radius", "1.5",
      "--t-low", "0.5", "--neighbour-threshold", "20", "--bbox", "-1", "0", "-1", "0", "0.6", "0"],
     dict(cell_size=0.75, influence_radius=3, surface_radius=1.5, t_low=0.5,
          neighbour_threshold=20, bbox=(-1, 0, -1, 0, 0.6, 0))),
])
def test_equals_cli_with_parameters(points, tmp_path, cli, kw):
    out = tmp_path / "cli.ply"
    run_cli(DATA, "--spacing", 2 * RADIUS, *cli, "-o", out)
    m = nbmc.reconstruct(points, spacing=2 * RADIUS, threads=1, **kw)
    v, n, t = read_ply(out)
    assert np.array_equal(m.vertices, v) and np.array_equal(m.triangles, t)
    assert (m.normals is None) == (n is None)
    if n is not None:
        assert np.array_equal(m.normals, n)
    py = tmp_path / "py.ply"
    m.write(py)
    assert py.read_bytes() == out.read_bytes()


def test_file_path_and_particles_input(mesh):
    same_mesh(mesh, nbmc.reconstruct(str(DATA), particle_radius=RADIUS, threads=1))
    same_mesh(mesh, nbmc.reconstruct(DATA, particle_radius=RADIUS, threads=1, format="xyz"))
    p = nbmc.read_particles(DATA, threads=1)
    same_mesh(mesh, p.reconstruct(particle_radius=RADIUS))
    same_mesh(mesh, nbmc.reconstruct(p, particle_radius=RADIUS, threads=1))


def layouts(points):
    """The example frame in many layouts, with whether it can be read in place."""
    p32 = np.array(points)
    p64 = p32.astype(np.float64)
    rec = np.zeros(len(p32), dtype=[("id", "<i4"), ("pos", "<f4", 3), ("vel", "<f4", 3)])
    rec["pos"] = p32
    big = np.zeros((len(p32), 7), dtype=np.float64)
    big[:, 2:5] = p64
    twice = np.repeat(p32, 2, axis=0)  # rows 0, 2, 4, ... are the frame
    fortran_3n = np.asfortranarray(p64.T)  # pos(3, n) of a Fortran code
    return {
        "float32": (p32, True),
        "float64": (p64, True),
        "read-only": (points, True),
        "structured field (stride 28)": (rec["pos"], True),
        "columns 2:5 of (N, 7) float64": (big[:, 2:5], True),
        "every other row": (twice[::2], True),
        "transpose of Fortran pos(3, n)": (fortran_3n.T, True),
        "Fortran-ordered (N, 3)": (np.asfortranarray(p64), False),
        "reversed rows": (p32[::-1][::-1], True),
        "big-endian": (p64.astype(">f8"), False),
        "list of lists": (p64.tolist(), False),
    }


@pytest.mark.parametrize("name", list(layouts(np.zeros((2, 3), np.float32))))
def test_input_layouts(points, mesh, name):
    arr, in_place = layouts(points)[name]
    h = _arrays.host_points(arr)
    if in_place:
        assert h.pointer == arr.ctypes.data, "copied although the layout can be read in place"
    same_mesh(mesh, nbmc.reconstruct(arr, particle_radius=RADIUS, threads=1))


def test_integer_and_float16_are_converted():
    grid = np.stack(np.meshgrid(*[np.arange(6)] * 3, indexing="ij"), -1).reshape(-1, 3)
    a = nbmc.reconstruct(grid.astype(np.int32), spacing=1, threads=1)
    b = nbmc.reconstruct(grid.astype(np.float64), spacing=1, threads=1)
    c = nbmc.reconstruct(grid.astype(np.float16), spacing=1, threads=1)
    same_mesh(a, b)
    same_mesh(a, c)
    assert a.triangle_count > 0


@pytest.mark.parametrize("bad", [np.zeros((5, 2)), np.zeros(9), np.zeros((2, 3, 1)), np.array([["a"] * 3])])
def test_bad_shapes_and_types(bad):
    with pytest.raises((ValueError, TypeError)):
        nbmc.reconstruct(bad, spacing=1)


def test_views_are_zero_copy_readonly_and_keep_the_mesh(points):
    m = nbmc.reconstruct(points, particle_radius=RADIUS, threads=1)
    v, t, n = m.vertices, m.triangles, m.normals
    assert v.shape == (m.vertex_count, 3) and v.dtype == np.float32
    assert t.shape == (m.triangle_count, 3) and t.dtype == np.uint32
    assert n.shape == v.shape
    assert not v.flags.writeable and not t.flags.writeable
    assert v.flags.c_contiguous and t.flags.c_contiguous
    assert m.vertices is v  # cached
    first = v.copy()
    del m
    gc.collect()
    # The views keep the mesh alive; allocate a lot to reuse freed memory if they did not.
    junk = [nbmc.reconstruct(points, particle_radius=RADIUS, threads=1, cell_size=1) for _ in range(3)]
    assert np.array_equal(v, first) and len(junk) == 3
    assert int(t.max()) == len(v) - 1
    assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-4)


def test_mesh_is_closed_and_oriented(mesh):
    t = mesh.triangles.astype(np.int64)
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    fwd = set(map(tuple, edges))
    assert len(fwd) == len(edges)  # no directed edge twice
    assert all((b, a) in fwd for a, b in fwd)  # every edge has its opposite


def test_stats_and_timings(mesh, points):
    s = mesh.stats
    assert s.particle_count == len(points)
    assert s.vertex_count == mesh.vertex_count and s.triangle_count == mesh.triangle_count
    assert 0 < s.surface_particle_count <= s.particle_count
    assert s.cell_size == pytest.approx(2 * RADIUS * nbmc.defaults()["cell_size"])
    assert list(s.stage_seconds) == list(nbmc.STAGES)
    assert list(mesh.timings) == list(nbmc.STAGES) + ["total"]
    assert mesh.timings["total"] >= mesh.timings["field"] >= 0
    assert s.grid_vertex_count == s.grid_dims[0] * s.grid_dims[1] * s.grid_dims[2]
    assert mesh.attributes == {}
    assert "37788 vertices" in repr(mesh) or "vertices" in repr(mesh)


def test_context_reuse_and_stats(points, mesh):
    with nbmc.Context("serial", threads=1) as ctx:
        assert ctx.backend == "serial"
        with pytest.raises(nbmc.NoParticles):
            ctx.stats
        assert ctx.set_particles(points) == len(points)
        a = ctx.reconstruct(spacing=2 * RADIUS)
        b = ctx.reconstruct(None, 2 * RADIUS)  # the same particles again
        c = ctx.reconstruct(points[: len(points) // 2], spacing=2 * RADIUS)
        assert ctx.stats.particle_count == len(points) // 2
        assert c.triangle_count != a.triangle_count
    same_mesh(a, mesh)  # serial gives the OpenMP mesh, bit for bit
    same_mesh(a, b)
    assert a.vertex_count > 0  # meshes outlive their context
    with pytest.raises(ValueError):
        ctx.reconstruct(spacing=1)


def test_absolute_lengths_match_relative(points, mesh):
    r = 2 * RADIUS
    d = nbmc.defaults()
    m = nbmc.reconstruct(points, spacing=r, length_unit="absolute", threads=1,
                         **{k: d[k] * r for k in ("cell_size", "influence_radius", "band_width",
                                                 "surface_radius", "iso_radius", "max_distance")})
    assert m.triangle_count == pytest.approx(mesh.triangle_count, rel=0.01)


def test_threads_give_the_same_mesh(points, mesh):
    results = [None, None]

    def work(i):
        results[i] = nbmc.reconstruct(points, particle_radius=RADIUS, threads=1)

    ts = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    for r in results:
        same_mesh(r, mesh)


def test_empty_mesh(tmp_path):
    m = nbmc.reconstruct(np.zeros((1, 3)), spacing=1, iso_radius=0.1, cell_size=10)
    assert m.vertex_count == 0 or m.vertices.shape == (m.vertex_count, 3)
    if m.vertex_count == 0:
        assert m.vertices.shape == (0, 3) and m.triangles.shape == (0, 3)
        m.write(tmp_path / "empty.ply")


def test_one_particle_is_a_sphere():
    m = nbmc.reconstruct(np.array([[1.0, 2.0, 3.0]]), spacing=1)
    assert m.triangle_count > 0
    r = np.linalg.norm(m.vertices - np.array([1, 2, 3], np.float32), axis=1)
    assert r.max() < 1.5


def test_decimate_and_spheres():
    g = np.arange(-6, 7, dtype=np.float64)
    ball = np.stack(np.meshgrid(g, g, g), -1).reshape(-1, 3)
    ball = ball[np.linalg.norm(ball, axis=1) <= 6]
    lone = np.array([[20.0, 0, 0], [0, 20.0, 0]])
    pts = np.concatenate([ball, lone])
    full = nbmc.reconstruct(pts, spacing=1)
    m = nbmc.reconstruct(pts, spacing=1, decimate=0.25, isolated="sphere")
    assert m.stats.pre_decimation_triangle_count < full.triangle_count  # the lone particles made none
    assert m.triangle_count <= 0.25 * m.stats.pre_decimation_triangle_count + 1
    assert m.spheres.shape == (2, 4) and m.spheres.dtype == np.float32
    assert np.array_equal(m.spheres[:, :3], lone.astype(np.float32))
    assert np.allclose(m.spheres[:, 3], 1.0)
    assert full.spheres.shape == (0, 4)
    with pytest.raises(nbmc.Error):
        nbmc.reconstruct(pts, spacing=1, decimate=0)


def test_cleanup_counts():
    rng = np.random.default_rng(3)
    g = np.arange(-6, 7, dtype=np.float64)
    ball = np.stack(np.meshgrid(g, g, g), -1).reshape(-1, 3)
    ball = ball[np.linalg.norm(ball, axis=1) <= 6]
    ball = ball + rng.uniform(-0.3, 0.3, ball.shape)
    raw = nbmc.reconstruct(ball, spacing=1, cleanup=False)
    s0 = raw.stats
    assert (s0.cleanup_bad_triangles_before, s0.cleanup_moves, s0.cleanup_flips, s0.cleanup_collapses) == (0, 0, 0, 0)
    assert s0.raw_triangle_count == raw.triangle_count
    m = nbmc.reconstruct(ball, spacing=1)
    s = m.stats
    assert s.raw_triangle_count == raw.triangle_count
    assert s.cleanup_bad_triangles_before > 0
    assert s.cleanup_bad_triangles_after <= s.cleanup_bad_triangles_before
    assert s.cleanup_moves + s.cleanup_flips + s.cleanup_collapses > 0
    assert s.raw_triangle_count - s.triangle_count == (
        2 * s.cleanup_collapses + 6 * s.cleanup_cuts + s.cleanup_removed_component_triangles)


def test_defaults_and_signature():
    d = nbmc.defaults()
    assert d["method"] == "ssp07" and d["field"] == "narrow-band" and d["length_unit"] == "spacing"
    import inspect
    sig = inspect.signature(nbmc.reconstruct)
    for k, v in d.items():
        assert sig.parameters[k].default == v
    assert str(d["cell_size"]) in nbmc.reconstruct.__doc__


def test_spacing_is_required(points):
    with pytest.raises(TypeError):
        nbmc.reconstruct(points)
    with pytest.raises(TypeError):
        nbmc.reconstruct(points, spacing=1, particle_radius=0.5)
    with pytest.raises(TypeError):
        nbmc.Context().reconstruct(points, spacing=1, no_such_option=3)
    with pytest.raises(ValueError):
        nbmc.reconstruct(points, spacing=1, method="marching-squares")
    with pytest.raises(NotImplementedError):
        nbmc.reconstruct(points, spacing=1, attributes=["vel"])


def test_memory_budget_parsing():
    from nbmc._core import parse_bytes
    assert parse_bytes("4G") == 4 << 30 and parse_bytes("512M") == 512 << 20
    assert parse_bytes(1000) == 1000 and parse_bytes(None) == 0 and parse_bytes("2KiB") == 2048
    with pytest.raises(ValueError):
        parse_bytes("lots")
    ctx = nbmc.Context(memory_budget="1G")
    assert ctx.memory_budget == 1 << 30


def test_subdomains_give_the_same_mesh(points):
    pts = points
    whole = nbmc.reconstruct(pts, 0.05, backend="openmp")
    with nbmc.Context("openmp", subdomains=(2, 2, 1)) as ctx:
        split = ctx.reconstruct(pts, 0.05)
        info = ctx.subdomain_stats()
    assert info["count"] == 4 and len(info["per_subdomain"]) == 4
    assert sum(e["particles"] for e in info["per_subdomain"]) == len(pts)
    assert np.array_equal(whole.vertices, split.vertices)
    assert np.array_equal(whole.triangles, split.triangles)
    with nbmc.Context("serial") as ctx:
        with pytest.raises(nbmc.Error):
            ctx.subdomains = (0, 1, 1)
        with pytest.raises(ValueError):
            ctx.subdomains = "sometimes"
        ctx.subdomains = "auto"
        assert ctx.subdomains == "auto"


def _sphere(offset, r=0.01, radius=0.1):
    g = np.arange(-radius - r, radius + 1.5 * r, r)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    p = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    return p[(p * p).sum(axis=1) <= radius * radius * (1 + 1e-9)] + offset


def test_double_positions_far_from_the_origin():
    # 1e7 in each coordinate: a float32 resolves 1.0 there, the sphere's
    # radius is 0.1. The float64 vertices keep its shape.
    assert nbmc.defaults()["double_positions"] is False
    near = nbmc.reconstruct(_sphere(0.0), 0.01, backend="serial")
    far = nbmc.reconstruct(_sphere(1e7), 0.01, double_positions=True, backend="serial")
    assert not near.double_positions and near.vertices.dtype == np.float32
    assert far.double_positions and far.vertices.dtype == np.float64
    assert far.vertices.shape == (far.vertex_count, 3) and not far.vertices.flags.writeable
    rn = np.linalg.norm(near.vertices.astype(np.float64), axis=1)
    rf = np.linalg.norm(far.vertices - 1e7, axis=1)
    assert abs(rf.mean() - rn.mean()) < 1e-4 and np.ptp(rf) < 0.01
    # In float32 the vertices collapse onto a few points (the clean-up then
    # removes what is left of the surface).
    flt = nbmc.reconstruct(_sphere(1e7), 0.01, backend="serial")
    assert flt.vertices.dtype == np.float32
    radii = np.linalg.norm(flt.vertices.astype(np.float64) - 1e7, axis=1)
    assert flt.vertex_count < far.vertex_count / 2 or np.ptp(radii) > 0.05
