#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
# Writes the hand-made seed inputs of fuzz/fuzz_api.cpp into fuzz/corpus/api/
# (seed-*, and finding*-* for the core bugs the fuzzer found). The encoder
# mirrors the target's input layout: a fixed header (scale, upload,
# parameters, rare events) followed by the particle pieces.
# Keep it in step with LLVMFuzzerTestOneInput when the layout changes.
#   python3 fuzz/api/make_seeds.py [OUT_DIR]
import os
import struct
import sys


def u8(v):
    return bytes([v & 0xFF])


def u16(v):
    return struct.pack("<H", v & 0xFFFF)


def u32(v):
    return struct.pack("<I", v & 0xFFFFFFFF)


def flag(k, yes):  # Input::one_in(k)
    return u8(k - 1 if yes else 0)


def rng(lo, hi, v):  # Input::range(lo, hi)
    return u16(round((v - lo) / (hi - lo) * 65535))


SPACINGS = [1.0, 0.1, 0.025, 3.0, 0.001, 1000.0, 0.5, 7.25]
OFFSETS = [0.0, 10.0, -123.4, 0.0, 1e4, -3e5, 0.0, 1e7]
STRIDE_PACKED, STRIDE_PADDED, STRIDE_FORTRAN, STRIDE_SMALL = 0, 5, 6, 7


def header(spacing=0, offset=0, f32=False, stride_kind=STRIDE_PACKED, stride_extra=0, stride_small=0,
           zero_count=False, null_pointer=False, absolute=False, cell=0.5, R=4.0, band=2.0, surf=2.0, iso=1.0,
           zb05=False, dense=False, t_low=0.4, t_high=3.5, color=0.75, nbr=25, normals=True, default_thresholds=True,
           bbox=None, bbox_away=False, corrupt=None, budget_log2=None, cancel_call=None, far=None, bad=None,
           perm_seed=12345):
    b = flag(8, False) + rng(-9.2103, 9.2103, 0.0) + u8(spacing) + u8(offset)
    b += flag(3, f32) + u8(stride_kind) + u8(stride_extra) + u8(stride_small)
    b += flag(64, zero_count) + flag(64, null_pointer)
    b += flag(4, absolute)
    thin = band < 1.0
    b += rng(0.3, 2.0, cell) + rng(1.5, 6.0, R) + flag(6, thin) + (rng(0.5, 1.0, band) if thin else rng(1.0, 3.0, band))
    b += rng(1.0, 4.0, surf) + rng(0.3, 1.6, iso)
    b += flag(2, zb05) + flag(4, dense)
    b += rng(0.05, 1.5, t_low) + rng(0.01, 5.0, t_high - t_low) + rng(0.0, 2.0, color) + u8(nbr)
    b += flag(4, not normals) + u8(0 if default_thresholds else 255)
    b += flag(6, bbox is not None) + flag(6, bbox_away)
    for a in range(3):
        lo, size = bbox[a] if bbox else (0.0, 1.0)
        b += rng(-0.3, 1.0, lo) + rng(0.05, 1.3, size)
    kind, alt, extra = corrupt if corrupt else (0, 0, 0)
    b += flag(8, corrupt is not None) + u8(kind) + u8(alt) + u8(extra) + u16(0)
    b += flag(16, budget_log2 is not None) + u8((budget_log2 or 10) - 10)
    b += flag(16, cancel_call is not None) + u8(cancel_call or 0)
    b += flag(12, far is not None) + u8(far or 0)
    index, axis, what = bad if bad else (0, 0, 0)
    b += flag(14, bad is not None) + u32(index) + u8(axis) + u8(what)
    b += u32(perm_seed)
    return b


def pieces(*ps):
    return u8(len(ps) - 1) + b"".join(ps)


def sph(threshold=0.6, corrupt_threshold=False):
    """The draws appended after the particle pieces: NBMC_METHOD_SPH."""
    return flag(5, True) + rng(0.05, 0.95, threshold) + u8(0 if corrupt_threshold else 1)


def yt10(threshold=0.6, kr=4.0, ks=1.0, kn=0.5, lam=0.3, neps=25, corrupt=7, defaults=False):
    """The draws appended after the SPH ones: NBMC_METHOD_YT10 (no SPH)."""
    return (flag(5, False) + rng(0.05, 0.95, 0.6) + u8(1) +
            flag(5, True) + rng(0.05, 0.95, threshold) + rng(1.0, 8.0, kr) + rng(0.3, 3.0, ks) +
            rng(0.05, 1.5, kn) + u16(round(lam * 65535)) + u8(neps) + u8(corrupt) + flag(3, defaults))


def centre(c):
    return b"".join(rng(-6, 6, x) for x in c)


def ball(c, radius, jitter=None, seed=1):
    return u8(0) + centre(c) + rng(0.2, 4.5, radius) + flag(3, jitter is not None) + rng(0, 0.3, jitter or 0) + u32(seed)


def box(c, nx, ny, nz):
    return u8(1) + centre(c) + u8(nx - 1) + u8(ny - 1) + u8(nz - 1)


def cloud(c, n, size, seed=7):
    return u8(2) + centre(c) + u8(n - 1) + rng(0.2, 8, size) + u32(seed)


def points(pts):
    return u8(3) + centre((0, 0, 0)) + u8(len(pts) - 1) + b"".join(u16(round(x * 4096) + 32768) for p in pts for x in p)


def duplicates(n, pick=0, same=True):
    return u8(4) + centre((0, 0, 0)) + u8(n - 1) + u32(pick) + flag(2, same)


def sheet(c, nx, ny, nz):
    return u8(5) + centre(c) + u8(nx - 1) + u8(ny - 1) + u8(nz - 1)


SEEDS = {
    # A lattice sphere with the defaults: the ordinary case.
    "sphere-ssp07": header() + pieces(ball((0, 0, 0), 3.0)),
    # ZB05 on the dense grid, float upload with an unaligned 15-byte stride.
    "sphere-zb05-dense-f32-stride15": header(f32=True, stride_kind=STRIDE_PADDED, stride_extra=3, zb05=True,
                                             dense=True, cell=1.0) + pieces(ball((1, 0, -1), 2.5, jitter=0.2)),
    # A box of particles in absolute units, spacing 0.025 at offset 10.
    "box-absolute": header(spacing=2, offset=1, absolute=True, cell=0.6) + pieces(box((-2, -1, 0), 6, 4, 3)),
    # A random cloud plus 30 particles at one point, Fortran-like stride.
    "cloud-duplicates-fortran": header(stride_kind=STRIDE_FORTRAN, stride_extra=1, cell=0.8) +
                                pieces(cloud((-2, -2, -2), 150, 5.0), duplicates(30)),
    # A two-layer sheet cut by a bounding box.
    "sheet-bbox": header(cell=0.6, bbox=[(0.1, 0.8), (0.0, 1.0), (-0.3, 1.3)]) + pieces(sheet((-4, -4, 0), 10, 10, 2)),
    # One NaN coordinate: INVALID_PARTICLES naming the particle, then NO_PARTICLES.
    "nan-particle": header(bad=(5, 1, 0)) + pieces(ball((0, 0, 0), 1.5)),
    # iso_radius >= influence_radius: INVALID_PARAMETER.
    "invalid-iso": header(corrupt=(6, 0, 0)) + pieces(ball((0, 0, 0), 2.0)),
    # A 16 KiB memory budget: MEMORY_BUDGET, the same on every run.
    "budget-16k": header(budget_log2=14) + pieces(ball((0, 0, 0), 2.5)),
    # The progress callback cancels on its fourth call.
    "cancel-4th-call": header(cancel_call=3) + pieces(ball((0, 0, 0), 2.0)),
    # A particle 1e8 spacings away: DOMAIN_TOO_LARGE.
    "far-1e8": header(far=4) + pieces(ball((0, 0, 0), 2.0)),
    # A particle 1e3 spacings away: two components on a sparse band.
    "far-1e3": header(far=1, cell=0.6) + pieces(ball((0, 0, 0), 2.0), points([(0.5, 0.5, 0.5)])),
    # A few points placed by hand, some almost coincident; ZB05, no normals.
    "points-zb05": header(zb05=True, normals=False, iso=0.8, R=3.0) +
                   pieces(points([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (0.001, 0, 0), (3, 3, 3)])),
    # NBMC_METHOD_SPH (the draws after the pieces): a lattice ball; a sheet
    # cut by a box (particles kept within 2R); R = 1.5 on the dense grid; a
    # threshold of 1 and a NaN one (INVALID_PARAMETER).
    "sph-ball": header() + pieces(ball((0, 0, 0), 3.0)) + sph(0.6),
    "sph-sheet-bbox": header(cell=0.6, bbox=[(0.1, 0.8), (0.0, 1.0), (-0.3, 1.3)]) +
                      pieces(sheet((-4, -4, 0), 10, 10, 2)) + sph(0.5),
    "sph-dense-small-kernel": header(R=1.5, surf=2.0, iso=0.5, dense=True, cell=0.8) +
                              pieces(cloud((-2, -2, -2), 150, 5.0), ball((3, 3, 3), 1.0)) + sph(0.3),
    "sph-threshold-one": header(corrupt=(6, 0, 0)) + pieces(ball((0, 0, 0), 2.0)) + sph(0.6, True),
    "sph-threshold-nan": header(corrupt=(6, 1, 0)) + pieces(ball((0, 0, 0), 2.0)) + sph(0.6, True),
    # NBMC_METHOD_YT10 (the draws after the SPH ones): a lattice ball with
    # the defaults; a one-particle-thick sheet cut by a box (particles kept
    # within 2R); a cloud with 30 coincident particles on the dense grid with
    # every parameter at an end of its range; k_n and lambda just out of
    # range (INVALID_PARAMETER).
    "yt10-ball": header() + pieces(ball((0, 0, 0), 3.0)) + yt10(defaults=True),
    "yt10-sheet-bbox": header(cell=0.6, bbox=[(0.1, 0.8), (0.0, 1.0), (-0.3, 1.3)]) +
                       pieces(sheet((-4, -4, 0), 10, 10, 1)) + yt10(0.5),
    "yt10-dense-extremes": header(dense=True, cell=0.8) +
                           pieces(cloud((-2, -2, -2), 150, 5.0), duplicates(30)) +
                           yt10(0.3, kr=8.0, ks=3.0, kn=1.5, lam=1.0, neps=0),
    "yt10-kn-invalid": header(corrupt=(6, 0, 0)) + pieces(ball((0, 0, 0), 2.0)) + yt10(corrupt=2),
    "yt10-lambda-invalid": header(corrupt=(6, 1, 0)) + pieces(ball((0, 0, 0), 2.0)) + yt10(corrupt=3),
    # Regression inputs for the core findings of the fuzzer (fuzz/README_api.md),
    # fixed or documented in eedcfb7.
    # 1: cancelled on the 8th progress call (stage 5 done) under a 32 KiB
    #    budget: the mesh's bytes stayed counted, the second run hit the budget.
    "finding1-budget-cancel-accounting": header(budget_log2=15, cancel_call=7) + pieces(ball((0, 0, 0), 4.0)),
    # 2: vertices in the grid margin outside the bounding box (now documented).
    "finding2-bbox-margin": header(cell=0.7, bbox=[(0.2, 0.5), (-0.2, 0.8), (-0.3, 1.3)]) +
                            pieces(sheet((-4, -4, 0), 10, 10, 2)),
    # 3: surface_radius 4 > 2 * influence_radius 1.5: INVALID_PARAMETER
    #    (was undocumented and raised late, from the surface stage).
    "finding3-surface-radius": header(R=1.5, surf=4.0, iso=0.5) + pieces(ball((0, 0, 0), 2.0)),
    # 5: with a box, a particle more than pad + R/2 below it (but within R)
    #    got a negative neighbour-cell coordinate converted to uint32_t:
    #    undefined behaviour (UBSan: neighbourhood.hpp, "outside the range of
    #    representable values of type 'unsigned int'"); now clamped.
    "finding5-bbox-negative-cell": header(R=6.0, band=1.0, cell=0.5, iso=0.5,
                                          bbox=[(5.5 / 6.5, 0.2), (0.0, 1.0), (0.0, 1.0)]) +
                                   pieces(points([(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1),
                                                  (-5.5, 0, 0)])),
}


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "corpus", "api")
    os.makedirs(out, exist_ok=True)
    for name, data in SEEDS.items():
        prefix = "" if name.startswith("finding") else "seed-"
        with open(os.path.join(out, prefix + name), "wb") as f:
            f.write(data)
    print(f"wrote {len(SEEDS)} seeds to {out}")


if __name__ == "__main__":
    main()
