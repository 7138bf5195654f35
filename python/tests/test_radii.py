# SPDX-License-Identifier: MIT
"""Per-particle radii: Context.set_radii, reconstruct(radii=...), and the
rules of their lifetime."""
import numpy as np
import pytest

import nbmc
from conftest import RADIUS

SPACING = 2 * RADIUS


def closed(mesh):
    """Every directed edge once, and its opposite once."""
    t = np.asarray(mesh.triangles, dtype=np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    key = e[:, 0] * (mesh.vertex_count + 1) + e[:, 1]
    rev = e[:, 1] * (mesh.vertex_count + 1) + e[:, 0]
    return len(np.unique(key)) == len(key) and np.array_equal(np.sort(key), np.sort(rev))


def test_equal_radii_are_the_mesh_without_radii(points):
    plain = nbmc.reconstruct(points, SPACING, threads=1)
    equal = nbmc.reconstruct(points, SPACING, threads=1, radii=np.full(len(points), SPACING))
    assert np.array_equal(plain.vertices, equal.vertices)
    assert np.array_equal(plain.triangles, equal.triangles)


def test_two_sizes_and_lifetime(points):
    small = np.where(points[:, 0] < 0.5, 0.5 * SPACING, SPACING).astype(np.float32)
    with nbmc.Context(threads=1) as ctx:
        with pytest.raises(nbmc.NoParticles):
            ctx.set_radii(np.ones(3))
        plain = ctx.reconstruct(points, SPACING)
        mixed = ctx.reconstruct(None, SPACING, radii=small)
        assert mixed.triangle_count != plain.triangle_count
        assert closed(mixed)
        # The radii stay for the next reconstruction, until removed.
        again = ctx.reconstruct(None, SPACING)
        assert np.array_equal(again.vertices, mixed.vertices)
        ctx.set_radii(None)
        assert np.array_equal(ctx.reconstruct(None, SPACING).vertices, plain.vertices)
        # An upload removes them.
        ctx.set_radii(small)
        ctx.set_particles(points)
        assert np.array_equal(ctx.reconstruct(None, SPACING).vertices, plain.vertices)
        # Errors: length, shape, values.
        with pytest.raises(ValueError):
            ctx.set_radii(small[1:])
        with pytest.raises(ValueError):
            ctx.set_radii(np.ones((len(points), 2)))
        bad = small.copy()
        bad[5] = -1
        with pytest.raises(nbmc.InvalidParameter, match="particle 5"):
            ctx.set_radii(bad)
        bad[5] = np.nan
        with pytest.raises(nbmc.InvalidParameter, match="particle 5"):
            ctx.set_radii(bad)
        ctx.set_radii(np.full(len(points), 1))  # integers: converted
