# SPDX-License-Identifier: MIT
"""Progress callbacks, cancellation through them, and Ctrl-C."""
import os
import signal
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest

import nbmc
from conftest import DATA, HERE, RADIUS


@pytest.fixture(scope="module")
def frame():
    return np.fromfile(DATA, dtype="<f4").reshape(-1, 3)


def test_progress_reports_every_stage_in_order(frame):
    seen = []
    m = nbmc.reconstruct(frame, particle_radius=RADIUS, threads=1,
                         progress=lambda stage, f: seen.append((stage, f)))
    stages = [s for s, _ in seen]
    assert set(stages) <= set(nbmc.STAGES)
    order = [nbmc.STAGES.index(s) for s in stages]
    assert order == sorted(order) and stages[-1] == "output"
    assert all(0.0 <= f <= 1.0 for _, f in seen)
    assert m.triangle_count > 0


@pytest.mark.parametrize("stop_at", ["upload", "field", "triangulation"])
def test_callback_cancels_and_context_stays_usable(frame, stop_at):
    ctx = nbmc.Context(threads=1)
    ctx.progress = lambda stage, f: stage == stop_at
    with pytest.raises(nbmc.Cancelled) as info:
        ctx.reconstruct(frame, particle_radius=RADIUS)
    assert info.value.status == 11
    ctx.progress = None
    assert ctx.reconstruct(particle_radius=RADIUS, cell_size=1).triangle_count > 0


def test_exception_in_callback_cancels_and_propagates(frame):
    class Stop(Exception):
        pass

    def progress(stage, f):
        if stage == "band":
            raise Stop(stage)

    ctx = nbmc.Context(threads=1, progress=progress)
    with pytest.raises(Stop, match="band"):
        ctx.reconstruct(frame, particle_radius=RADIUS)
    ctx.progress = None
    assert ctx.reconstruct(particle_radius=RADIUS, cell_size=1).triangle_count > 0


def test_cancel_from_another_thread(frame):
    """Off the main thread the call runs directly; the callback still cancels."""
    out = {}

    def work():
        try:
            nbmc.reconstruct(frame, particle_radius=RADIUS, threads=1, progress=lambda s, f: s == "field")
        except nbmc.Cancelled as e:
            out["e"] = e

    t = threading.Thread(target=work)
    t.start()
    t.join()
    assert isinstance(out.get("e"), nbmc.Cancelled)


CTRL_C = textwrap.dedent("""
    import signal, sys, time
    import numpy as np
    # Ctrl-C as in an interactive session: a runner that starts the tests in
    # the background (a shell's `&`) passes SIGINT on as ignored, and Python
    # then installs no handler of its own.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.path.insert(0, {pkg!r})
    import nbmc
    points = np.fromfile({data!r}, dtype="<f4").reshape(-1, 3)
    calls = []
    def progress(stage, fraction):
        calls.append(stage)
        if len(calls) == 2:
            print("started", flush=True)
        time.sleep(0.3)  # a slow reconstruction, so that Ctrl-C lands in the middle
    ctx = nbmc.Context(threads=1, progress=progress)
    try:
        ctx.reconstruct(points, particle_radius={radius})
        print("finished", flush=True)
    except KeyboardInterrupt:
        print("interrupted at", calls[-1], len(calls), flush=True)
    ctx.progress = None
    print("again", ctx.reconstruct(particle_radius={radius}).triangle_count, flush=True)
""")


def test_ctrl_c_cancels_cleanly(tmp_path):
    script = tmp_path / "ctrl_c.py"
    script.write_text(CTRL_C.format(pkg=str(HERE.parent), data=str(DATA), radius=RADIUS))
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "started"
        os.kill(p.pid, signal.SIGINT)
        out, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    lines = out.splitlines()
    assert lines[0].startswith("interrupted at"), out
    assert int(lines[0].split()[-1]) < 9  # stopped before the last stages
    expected = nbmc.reconstruct(np.fromfile(DATA, "<f4").reshape(-1, 3), particle_radius=RADIUS,
                                threads=1).triangle_count
    assert lines[1] == f"again {expected}"


def test_gil_is_released_while_nbmc_works(frame):
    """Python keeps running on another thread during a reconstruction."""
    import time
    inside = []

    def progress(stage, f):
        inside.append((stage, f, time.perf_counter()))

    t = threading.Thread(target=lambda: nbmc.reconstruct(frame, particle_radius=RADIUS, threads=1,
                                                         progress=progress))
    ticks = []
    t.start()
    while t.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.0005)
    t.join()
    start = next(ts for s, f, ts in inside if s == "field")
    end = next(ts for s, f, ts in inside if s == "triangulation")
    during = [x for x in ticks if start < x < end]
    assert end - start > 0.01 and len(during) >= 5, (end - start, len(during))
