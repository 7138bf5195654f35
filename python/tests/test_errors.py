# SPDX-License-Identifier: MIT
"""Every status the library can be made to return here, with its exception
class, its code and the library's message; the Python-side checks too."""
import pickle

import numpy as np
import pytest

import nbmc
from nbmc import _capi as C
from conftest import DATA, REPO, RADIUS


class FakeDeviceArray:
    """Claims device memory; a host context must refuse it before reading."""

    def __init__(self, typestr="<f4", shape=(4, 3), strides=None):
        self.__cuda_array_interface__ = {"shape": shape, "typestr": typestr, "strides": strides,
                                         "data": (0xDEAD000, False), "version": 3}


def bad(kind, status, fn, *words):
    with pytest.raises(kind) as info:
        fn()
    e = info.value
    assert isinstance(e, nbmc.Error)
    assert e.status == status
    assert e.status_name == C.text(C.lib.nbmc_status_string(status))
    for w in words:
        assert w in e.message, e.message
    assert e.message in str(e)
    return e


@pytest.fixture
def frame():
    return np.fromfile(DATA, dtype="<f4").reshape(-1, 3)


def test_invalid_argument(tmp_path, frame):
    bad(nbmc.InvalidArgument, 1, lambda: nbmc.Context(99), "backend")
    bad(nbmc.InvalidArgument, 1, lambda: nbmc.Context(threads=-1), "num_threads")
    bad(nbmc.InvalidArgument, 1, lambda: nbmc.Context().load_particles(DATA, format="nope"), "nope")
    m = nbmc.reconstruct(frame, particle_radius=RADIUS, cell_size=1, threads=1)
    bad(nbmc.InvalidArgument, 1, lambda: m.write(tmp_path / "m.ply", format="stl"), "stl")
    bad(nbmc.InvalidArgument, 1, lambda: setattr(nbmc.Context(), "mesh_memory", 7))
    assert not (tmp_path / "m.ply").exists()


def test_invalid_particles(frame):
    frame[17, 1] = np.nan
    e = bad(nbmc.InvalidParticles, 2, lambda: nbmc.reconstruct(frame, spacing=0.05), "17")
    assert isinstance(e, ValueError)
    frame[17, 1] = np.inf
    bad(nbmc.InvalidParticles, 2, lambda: nbmc.reconstruct(frame.astype(np.float64), spacing=0.05))
    frame[17, 1] = 2e15
    bad(nbmc.InvalidParticles, 2, lambda: nbmc.reconstruct(frame.astype(np.float64), spacing=0.05))


def test_no_particles(tmp_path):
    bad(nbmc.NoParticles, 3, lambda: nbmc.reconstruct(np.zeros((0, 3)), spacing=1))
    bad(nbmc.NoParticles, 3, lambda: nbmc.Context().reconstruct(spacing=1))
    bad(nbmc.NoParticles, 3, lambda: nbmc.Context().stats)
    empty = tmp_path / "empty.xyz"
    empty.write_bytes(b"")
    bad(nbmc.NoParticles, 3, lambda: nbmc.read_particles(empty))


def test_invalid_parameter(frame):
    for kw, word in [(dict(spacing=-1), "spacing"), (dict(spacing=0.05, t_low=4, t_high=3), "t_"),
                     (dict(spacing=0.05, iso_radius=5), "iso_radius"),
                     (dict(spacing=0.05, cell_size=-1), "cell_size"),
                     (dict(spacing=0.05, method=7), "method"),
                     (dict(spacing=0.05, method="sph", iso_threshold=1.2), "iso_threshold"),
                     (dict(spacing=0.05, method="sph", iso_threshold=float("nan")), "iso_threshold"),
                     (dict(spacing=0.05, method="yt10", aniso_kr=0.5), "aniso_kr"),
                     (dict(spacing=0.05, method="yt10", aniso_kn=2), "aniso_kn"),
                     (dict(spacing=0.05, method="yt10", aniso_lambda=-1), "aniso_lambda"),
                     (dict(spacing=0.05, method="yt10", aniso_neighbours=-1), "aniso_neighbours"),
                     (dict(spacing=0.05, bbox=(0, 0, 0, -1, 1, 1)), "")]:
        e = bad(nbmc.InvalidParameter, 4, lambda: nbmc.reconstruct(frame, **kw), word)
        assert isinstance(e, ValueError)


def test_domain_too_large():
    far = np.array([[0.0, 0.0, 0.0], [1e14, 1e14, 1e14]])
    bad(nbmc.DomainTooLarge, 5, lambda: nbmc.reconstruct(far, spacing=1e-3), "cell size")


def test_backend_unavailable(frame):
    if "cuda" not in nbmc.backends():
        bad(nbmc.BackendUnavailable, 7, lambda: nbmc.Context("cuda"), "cuda")
    ctx = nbmc.Context("serial")
    bad(nbmc.BackendUnavailable, 7, lambda: setattr(ctx, "mesh_memory", "device"), "CUDA")
    bad(nbmc.BackendUnavailable, 7, lambda: ctx.set_particles(FakeDeviceArray()), "CUDA")
    bad(nbmc.BackendUnavailable, 7, lambda: ctx.set_particles(FakeDeviceArray("<f8")), "CUDA")
    assert ctx.reconstruct(frame, spacing=0.05, cell_size=1).triangle_count > 0  # still usable


def test_io_errors(tmp_path, frame):
    e = bad(nbmc.FileError, 8, lambda: nbmc.read_particles(tmp_path / "missing.xyz"), "missing.xyz")
    assert isinstance(e, OSError)
    assert "[Errno" not in str(e)
    m = nbmc.reconstruct(frame, spacing=0.05, cell_size=1, threads=1)
    bad(nbmc.FileError, 8, lambda: m.write(tmp_path / "no" / "such" / "dir.ply"), "dir.ply")


def test_memory_budget(frame):
    ctx = nbmc.Context(threads=1, memory_budget=1000)
    e = bad(nbmc.MemoryBudgetExceeded, 10, lambda: ctx.reconstruct(frame, spacing=0.05), "budget")
    assert isinstance(e, MemoryError)
    ctx.memory_budget = None  # removed: the same context now works
    assert ctx.reconstruct(spacing=0.05, cell_size=1).triangle_count > 0


def test_cancelled(frame):
    e = bad(nbmc.Cancelled, 11, lambda: nbmc.reconstruct(frame, spacing=0.05,
                                                         progress=lambda s, f: True))
    assert not isinstance(e, ValueError)


def test_format_errors(tmp_path):
    p = tmp_path / "broken.ply"
    p.write_text("ply\nformat ascii 1.0\nelement vertex 2\nend_header\n")
    e = bad(nbmc.FormatError, 12, lambda: nbmc.read_particles(p), "broken.ply")
    assert isinstance(e, ValueError)
    bad(nbmc.FormatError, 12, lambda: nbmc.read_particles(REPO / "README.md"), "README.md")
    bad(nbmc.FormatError, 12, lambda: nbmc.reconstruct(REPO / "README.md", spacing=1))
    h = tmp_path / "garbage.h5"
    h.write_bytes(b"not hdf5 at all" * 10)
    with pytest.raises((nbmc.FormatError, nbmc.FileError)):
        nbmc.read_particles(h)


def test_every_status_has_a_class():
    classes = {nbmc.InvalidArgument: ValueError, nbmc.InvalidParticles: ValueError,
               nbmc.NoParticles: ValueError, nbmc.InvalidParameter: ValueError,
               nbmc.DomainTooLarge: ValueError, nbmc.OutOfMemory: MemoryError,
               nbmc.BackendUnavailable: RuntimeError, nbmc.FileError: OSError,
               nbmc.InternalError: RuntimeError, nbmc.MemoryBudgetExceeded: MemoryError,
               nbmc.Cancelled: nbmc.Error, nbmc.FormatError: ValueError}
    from nbmc._errors import error_for
    for status in range(1, 13):
        e = error_for(status, "msg")
        assert type(e) in classes and isinstance(e, classes[type(e)])
        assert e.status == status and e.message == "msg"
        again = pickle.loads(pickle.dumps(e))
        assert type(again) is type(e) and again.status == status and again.message == "msg"
    assert len({type(error_for(s, "")) for s in range(1, 13)}) == 12
    unknown = error_for(99, "")
    assert type(unknown) is nbmc.Error and unknown.status_name == "unknown status"


def test_python_side_checks():
    with pytest.raises(ValueError):  # strides nbmc cannot read and must not copy on the device
        nbmc.Context().set_particles(FakeDeviceArray(strides=(4, 12)))
    with pytest.raises(TypeError):
        nbmc.Context().set_particles(FakeDeviceArray("<i4"))
    with pytest.raises(ValueError):
        nbmc.Context().set_particles(FakeDeviceArray(shape=(4, 2)))
    with pytest.raises(ValueError):
        nbmc.Context("gpu")
    c = nbmc.Context()
    c.close()
    c.close()
    with pytest.raises(ValueError, match="closed"):
        c.set_particles(np.zeros((1, 3)))
