# SPDX-License-Identifier: MIT
"""Reconstruct a particle file with nbmc and put the surface into Blender.

Run inside Blender (Scripting workspace, or `blender --python THIS_FILE`),
after editing the paths below. Blender's own Python has numpy; it needs to
find the nbmc package and libnbmc:

  - NBMC_PYTHON_DIR: the repository's python/ folder (or install the package
    into Blender's Python: `<blender>/python/bin/python3 -m pip install
    --no-build-isolation --no-deps ./python` with NBMC_PREFIX set);
  - NBMC_LIBRARY: <repo>/build/install/lib/libnbmc.so (Blender's Python may be
    a different version from Debian's; the package is pure Python, so any
    CPython >= 3.9 works).

For a sequence, call import_frame() per frame (e.g. from a frame-change
handler) with one nbmc.Context kept in the driver namespace. Without this
script: write a .glb with `nbmc reconstruct ... -o surface.glb` and use
File > Import > glTF 2.0.
"""
import os
import sys

import numpy as np

NBMC_PYTHON_DIR = "/path/to/nbmc/python"
os.environ.setdefault("NBMC_LIBRARY", "/path/to/nbmc/build/install/lib/libnbmc.so")
PARTICLES = "/path/to/nbmc/examples/data/double_dam_break_4732.xyz"
PARTICLE_RADIUS = 0.025

if NBMC_PYTHON_DIR not in sys.path:
    sys.path.insert(0, NBMC_PYTHON_DIR)
import nbmc  # noqa: E402


def to_blender(mesh: "nbmc.Mesh", name: str = "nbmc_surface"):
    """Creates (or replaces) a Blender mesh object from an nbmc mesh."""
    import bpy

    v = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
    t = np.ascontiguousarray(mesh.triangles, dtype=np.int32)
    me = bpy.data.meshes.new(name)
    try:  # fast path: bulk copies with foreach_set
        me.vertices.add(len(v))
        me.vertices.foreach_set("co", v.ravel())
        me.loops.add(t.size)
        me.loops.foreach_set("vertex_index", t.ravel())
        me.polygons.add(len(t))
        me.polygons.foreach_set("loop_start", np.arange(0, t.size, 3, dtype=np.int32))
        if bpy.app.version < (4, 0, 0):  # 4.x derives the sizes from loop_start
            me.polygons.foreach_set("loop_total", np.full(len(t), 3, dtype=np.int32))
        me.update(calc_edges=True)
        if me.validate():
            raise RuntimeError("bulk copy gave an invalid mesh")
    except Exception:  # any Blender version: the slower, simplest way
        bpy.data.meshes.remove(me)
        me = bpy.data.meshes.new(name)
        me.from_pydata(v.tolist(), [], t.tolist())
        me.update(calc_edges=True)
    me.polygons.foreach_set("use_smooth", np.ones(len(t), dtype=bool))
    if mesh.normals is not None:  # nbmc's normals from the field gradient
        if bpy.app.version < (4, 1, 0):
            me.use_auto_smooth = True
        me.normals_split_custom_set_from_vertices(np.asarray(mesh.normals).tolist())
    old = bpy.data.objects.get(name)
    if old is not None:
        bpy.data.objects.remove(old, do_unlink=True)
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def import_frame(path: str = PARTICLES, ctx: "nbmc.Context" = None, **params):
    """Reconstructs one particle file and shows it; returns the Blender object."""
    ctx = ctx or nbmc.Context()
    mesh = ctx.reconstruct(path, particle_radius=PARTICLE_RADIUS, **params)
    print(f"nbmc: {mesh} in {mesh.timings['total']:.3f} s")
    return to_blender(mesh)


if __name__ == "__main__":
    import_frame()
