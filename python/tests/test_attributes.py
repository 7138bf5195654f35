# SPDX-License-Identifier: MIT
"""Particle attributes: Context.set_attribute, reconstruct(attributes=...),
Mesh.attributes, and the rules of their lifetime."""
import numpy as np
import pytest

import nbmc
from conftest import RADIUS


def kernel_mean(points, values, x, R):
    """The documented interpolation, computed the slow way for one vertex."""
    d2 = ((points.astype(np.float64) - x.astype(np.float64)) ** 2).sum(axis=1) / (R * R)
    w = np.where(d2 < 1, (1 - d2) ** 3, 0.0)
    if w.sum() == 0:
        return values[np.argmin(d2)]
    return (w[:, None] * values.reshape(len(points), -1)).sum(axis=0) / w.sum()


def test_attributes_are_interpolated(points):
    height = points[:, 1].astype(np.float64)
    vel = np.stack([np.ones(len(points)), 2 * points[:, 0], np.full(len(points), -3.0)], axis=1)
    with nbmc.Context(threads=1) as ctx:
        mesh = ctx.reconstruct(points, particle_radius=RADIUS,
                               attributes={"height": height, "vel": vel.astype(np.float32)})
    attrs = mesh.attributes
    assert list(attrs) == ["height", "vel"]
    assert attrs["height"].shape == (mesh.vertex_count,) and attrs["height"].dtype == np.float32
    assert attrs["vel"].shape == (mesh.vertex_count, 3)
    assert not attrs["height"].flags.writeable
    R = 4 * 2 * RADIUS  # influence radius 4 spacings
    for i in range(0, mesh.vertex_count, max(1, mesh.vertex_count // 50)):
        want = kernel_mean(points, height, mesh.vertices[i], R)
        assert attrs["height"][i] == pytest.approx(float(want[0]), rel=1e-5, abs=1e-6)
    assert np.allclose(attrs["vel"][:, 0], 1) and np.allclose(attrs["vel"][:, 2], -3)


def test_lifetime_and_errors(points):
    with nbmc.Context(threads=1) as ctx:
        with pytest.raises(nbmc.NoParticles):
            ctx.set_attribute("a", np.zeros(3))
        ctx.set_particles(points)
        with pytest.raises(ValueError):
            ctx.set_attribute("a", np.zeros(len(points) - 1))
        with pytest.raises(ValueError):
            ctx.set_attribute("a", np.zeros((len(points), 2)))
        bad = np.zeros(len(points))
        bad[5] = np.nan
        with pytest.raises(nbmc.InvalidParticles, match="particle 5"):
            ctx.set_attribute("a", bad)
        ctx.set_attribute("a", np.arange(len(points)))  # integers: converted
        ctx.set_attribute("b", np.ones(len(points), dtype=np.float32))
        ctx.remove_attribute("a")
        assert list(ctx.reconstruct(None, particle_radius=RADIUS).attributes) == ["b"]
        ctx.set_particles(points)  # an upload removes them all
        assert ctx.reconstruct(None, particle_radius=RADIUS).attributes == {}
    with pytest.raises(NotImplementedError):
        nbmc.reconstruct(points, particle_radius=RADIUS, attributes=["vel"])
