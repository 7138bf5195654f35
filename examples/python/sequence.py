# SPDX-License-Identifier: MIT
# %% [markdown]
# # A sequence of frames with nbmc, and where the time goes
#
# Notebook-style script (cells marked `# %%`, runs as a plain script too):
#
#     python3 examples/python/sequence.py [--out DIR] [--frames N]
#
# It makes a small sequence from the example frame (the dam-break particles
# falling and spreading), reconstructs it with one `nbmc.Context` (buffers are
# reused between frames), writes the meshes, prints the per-stage times and,
# if matplotlib is installed, plots them to DIR/stage_times.png.

# %%
import argparse
import tempfile
from pathlib import Path

import numpy as np

import nbmc

REPO = Path(__file__).resolve().parents[2]
FRAME = REPO / "examples" / "data" / "double_dam_break_4732.xyz"
RADIUS = 0.025  # particle radius of the example frame; the spacing is twice that

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--out", type=Path, default=None, help="output folder (default: a temporary one)")
parser.add_argument("--frames", type=int, default=6, help="number of frames to make")
args, _ = parser.parse_known_args()  # tolerate a notebook kernel's own arguments
out = args.out or Path(tempfile.mkdtemp(prefix="nbmc-sequence-"))
(out / "particles").mkdir(parents=True, exist_ok=True)
(out / "meshes").mkdir(parents=True, exist_ok=True)
print(f"nbmc {nbmc.__version__} ({nbmc.library_version_string()}); writing to {out}")

# %% [markdown]
# ## A toy sequence
# Not a simulation: the columns fall under gravity and spread on the floor
# (y = 0), enough to give every frame a different surface.

# %%
p0 = np.fromfile(FRAME, dtype="<f4").reshape(-1, 3)
floor = p0[:, 1].min()
rng = np.random.default_rng(1)
jitter = rng.normal(scale=0.002, size=p0.shape).astype(np.float32)
for i in range(args.frames):
    t = 0.05 * i
    p = p0.copy()
    p[:, 1] = np.maximum(floor, p[:, 1] - 4.9 * t * t)  # fall
    spread = 1 + 0.6 * t * np.clip((0.3 - (p[:, 1] - floor)) / 0.3, 0, 1)  # spread near the floor
    p[:, 0] *= spread
    p[:, 2] *= spread
    (p + i * jitter).astype("<f4").tofile(out / "particles" / f"fluid_{i:03d}.xyz")

# %% [markdown]
# ## Reconstruct every frame with one context
# `nbmc.frames` lists the files of a `{}` pattern in numeric order, like the
# CLI. `Ctrl-C` stops cleanly between stages.

# %%
pattern = str(out / "particles" / "fluid_{}.xyz")
timings = []
with nbmc.Context() as ctx:
    backend = ctx.backend
    print(f"backend: {backend}")
    for frame, mesh in ctx.reconstruct_frames(pattern, particle_radius=RADIUS):
        mesh.write(frame.output(str(out / "meshes" / "surface_{}.ply")))
        timings.append((frame.number, mesh.timings, mesh.stats))
        print(f"frame {frame.number:3d}: {mesh.stats.particle_count} particles -> "
              f"{mesh.vertex_count} vertices, {mesh.triangle_count} triangles "
              f"in {mesh.timings['total'] * 1000:.1f} ms")

# %% [markdown]
# ## Per-stage times

# %%
stages = list(nbmc.STAGES)
table = np.array([[t[s] for s in stages] for _, t, _ in timings]) * 1000  # ms
print("\nms per stage" + "".join(f"{s[:12]:>14}" for s in stages))
for (n, _, _), row in zip(timings, table):
    print(f"frame {n:6d}" + "".join(f"{v:14.2f}" for v in row))
print("mean        " + "".join(f"{v:14.2f}" for v in table.mean(axis=0)))

# %%
try:
    import matplotlib
    matplotlib.use("Agg")  # files only; in a notebook, drop this line to see the plot inline
    import matplotlib.pyplot as plt
except ImportError:
    plt = None
    print("matplotlib is not installed: no plot")
if plt is not None:
    fig, ax = plt.subplots(figsize=(8, 4))
    bottom = np.zeros(len(timings))
    frames_x = [n for n, _, _ in timings]
    for j, s in enumerate(stages):
        ax.bar(frames_x, table[:, j], bottom=bottom, label=s)
        bottom += table[:, j]
    ax.set_xticks(frames_x)
    ax.set_xlabel("frame")
    ax.set_ylabel("time [ms]")
    ax.set_title(f"nbmc per-stage times ({backend} backend, one context)")
    ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1))
    fig.tight_layout()
    fig.savefig(out / "stage_times.png", dpi=120)
    print(f"plot: {out / 'stage_times.png'}")
