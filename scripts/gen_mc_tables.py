#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Generate backends/kokkos/mc_tables.hpp, the marching-cubes case table.

The table is derived here from first principles (nothing is copied from
published tables):

  1. For each of the 6 cube faces, the crossed edges of the face are paired
     into segments by walking the face boundary: every maximal run of INSIDE
     corners is cut off by one segment. On an ambiguous face (inside/outside
     alternating diagonally) this separates the two inside corners, and the
     decision depends only on that face's 4 corner signs, so two cubes sharing
     a face always produce the same segments.
  2. Each segment is directed so that, seen from outside the cube through that
     face, the inside corners it cuts off lie on its right (cross(n_face, d)
     points away from them). A neighbouring cube sees the face from the other
     side and so gets the same segment with the opposite direction.
  3. Every crossed edge lies on exactly two faces and is the end of one
     segment and the start of another, so the directed segments chain into
     closed loops.
  4. Each loop is triangulated by dynamic programming over polygon
     triangulations (vertices at the edge midpoints). A diagonal may not join
     two edge points that share a cube face (it would lie in that face and
     could be duplicated by the neighbouring cube), and every triangle must
     face outward along each of its three edges (normal . (outside corner -
     inside corner) > 0). Among the admissible triangulations the one that
     maximises the minimum triangle angle is taken; ties go to the first
     split in loop order. The polygon's winding is kept, which makes every
     triangle normal (p1-p0)x(p2-p0) point toward the outside corners.

Usage:  python3 scripts/gen_mc_tables.py [output]   (default:
backends/kokkos/mc_tables.hpp next to this script's repository root). The
output is deterministic.
"""

import os
import sys

EDGE_START = [0, 2, 4, 6, 0, 1, 4, 5, 0, 1, 2, 3]
EDGE_AXIS = [e // 4 for e in range(12)]


def corner_pos(c):
    return (c & 1, (c >> 1) & 1, (c >> 2) & 1)


def edge_end(e):
    return EDGE_START[e] + (1 << EDGE_AXIS[e])


def edge_mid(e):
    a = corner_pos(EDGE_START[e])
    b = corner_pos(edge_end(e))
    return tuple(0.5 * (a[i] + b[i]) for i in range(3))


def edge_between(c0, c1):
    lo, hi = min(c0, c1), max(c0, c1)
    for e in range(12):
        if EDGE_START[e] == lo and edge_end(e) == hi:
            return e
    raise ValueError("corners %d and %d are not joined by an edge" % (c0, c1))


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0])


def faces():
    """Yield (outward normal, corners in cyclic order, edges between them)."""
    out = []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for side in (0, 1):
            normal = [0, 0, 0]
            normal[axis] = 1 if side else -1
            ring = []
            for (du, dv) in ((0, 0), (1, 0), (1, 1), (0, 1)):
                ring.append((side << axis) | (du << u) | (dv << v))
            edges = [edge_between(ring[k], ring[(k + 1) % 4]) for k in range(4)]
            out.append((tuple(normal), ring, edges))
    return out


FACES = faces()
# Edge ids lying on a common face (used to forbid in-face diagonals).
SHARE_FACE = [[False] * 12 for _ in range(12)]
for _n, _ring, _edges in FACES:
    for _a in _edges:
        for _b in _edges:
            SHARE_FACE[_a][_b] = True


def inside(case, c):
    return (case >> c) & 1 == 1


def face_segments(case):
    """Directed segments (edge_from, edge_to) of all faces of a case."""
    segs = []
    for normal, ring, edges in FACES:
        ins = [inside(case, c) for c in ring]
        for k in range(4):
            if ins[k] or not ins[(k + 1) % 4]:
                continue
            # Entering a run of inside corners through edges[k]; the run ends
            # at the first crossed edge that leaves it.
            run = []
            m = (k + 1) % 4
            while ins[m]:
                run.append(ring[m])
                m = (m + 1) % 4
            m = (m - 1) % 4  # edge m joins ring[m] (inside) to ring[m+1]
            a, b = edges[k], edges[m]
            pa, pb = edge_mid(a), edge_mid(b)
            mid = tuple(0.5 * (pa[i] + pb[i]) for i in range(3))
            cen = tuple(sum(corner_pos(c)[i] for c in run) / len(run) for i in range(3))
            toward_inside = sub(cen, mid)
            s = dot(cross(normal, sub(pb, pa)), toward_inside)
            assert s != 0
            segs.append((a, b) if s < 0 else (b, a))
    return segs


def loops_of(case):
    segs = face_segments(case)
    nxt = {}
    indeg = {}
    for a, b in segs:
        assert a not in nxt, "edge %d starts two segments in case %d" % (a, case)
        nxt[a] = b
        indeg[b] = indeg.get(b, 0) + 1
    assert all(v == 1 for v in indeg.values())
    assert set(nxt) == set(indeg)
    loops = []
    seen = set()
    for start in sorted(nxt):
        if start in seen:
            continue
        loop = [start]
        seen.add(start)
        e = nxt[start]
        while e != start:
            loop.append(e)
            seen.add(e)
            e = nxt[e]
        loops.append(loop)
    return loops


def edge_out_dir(case, e):
    """Unit vector from the inside corner to the outside corner of crossed edge e."""
    d = [0, 0, 0]
    # Start corner inside => the outside corner is at the end (+axis).
    d[EDGE_AXIS[e]] = 1 if inside(case, EDGE_START[e]) else -1
    return tuple(d)


def tri_normal(t):
    p0, p1, p2 = (edge_mid(e) for e in t)
    return cross(sub(p1, p0), sub(p2, p0))


def tri_outward(case, t):
    n = tri_normal(t)
    return all(dot(n, edge_out_dir(case, e)) > 0 for e in t)


def tri_min_angle_cos(t):
    """Largest cosine among the triangle's angles (smaller is better)."""
    p = [edge_mid(e) for e in t]
    worst = -1.0
    for i in range(3):
        a = sub(p[(i + 1) % 3], p[i])
        b = sub(p[(i + 2) % 3], p[i])
        c = dot(a, b) / (dot(a, a) * dot(b, b)) ** 0.5
        worst = max(worst, c)
    # Round so that ties between mirror-symmetric choices are exact ties.
    return round(worst, 9)


def triangulate(case, loop):
    n = len(loop)
    if n == 3:
        t = (loop[0], loop[1], loop[2])
        assert tri_outward(case, t)
        return [t]
    INF = float("inf")

    def chord_ok(i, j):
        if (j - i) % n in (1, n - 1):
            return True  # loop side
        return not SHARE_FACE[loop[i]][loop[j]]

    # best[i][j]: (max-cos of the worst triangle, choice k) for sub-polygon
    # loop[i..j]; lower cost is better.
    best = [[None] * n for _ in range(n)]
    for i in range(n - 1):
        best[i][i + 1] = (-INF, None)
    for length in range(2, n):
        for i in range(0, n - length):
            j = i + length
            cand = None
            if chord_ok(i, j):
                for k in range(i + 1, j):
                    if best[i][k] is None or best[k][j] is None:
                        continue
                    if best[i][k][0] == INF or best[k][j][0] == INF:
                        continue
                    t = (loop[i], loop[k], loop[j])
                    if not tri_outward(case, t):
                        continue
                    cost = max(tri_min_angle_cos(t), best[i][k][0], best[k][j][0])
                    if cand is None or cost < cand[0]:
                        cand = (cost, k)
            best[i][j] = cand if cand is not None else (INF, None)
    if best[0][n - 1][0] == INF:
        raise RuntimeError("no admissible triangulation for case %d loop %s" % (case, loop))
    tris = []

    def emit(i, j):
        if j - i < 2:
            return
        k = best[i][j][1]
        emit(i, k)
        tris.append((loop[i], loop[k], loop[j]))
        emit(k, j)

    emit(0, n - 1)
    return tris


def build():
    table = []
    loop_counts = []
    for case in range(256):
        tris = []
        loops = loops_of(case)
        for loop in loops:
            tris.extend(triangulate(case, loop))
        table.append(tris)
        loop_counts.append(len(loops))
    return table, loop_counts


def edge_mask(case):
    m = 0
    for e in range(12):
        if inside(case, EDGE_START[e]) != inside(case, edge_end(e)):
            m |= 1 << e
    return m


def fmt_rows(values, per_line, width):
    items = [("%d" % v).rjust(width) for v in values]
    lines = []
    for i in range(0, len(items), per_line):
        lines.append("    " + ", ".join(items[i:i + per_line]) + ",")
    return "\n".join(lines)


def render(table, loop_counts):
    kmax = max(len(t) for t in table)
    multi = sum(1 for c in loop_counts if c > 1)
    out = []
    w = out.append
    w("// SPDX-License-Identifier: MIT")
    w("// GENERATED FILE - do not edit by hand.")
    w("// Generated by scripts/gen_mc_tables.py; regenerate with")
    w("//   python3 scripts/gen_mc_tables.py")
    w("// from the repository root (output is deterministic).")
    w("//")
    w("// Marching-cubes case table.")
    w("//  - Corner c (0..7) sits at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1).")
    w("//  - Edge e runs along axis kEdgeAxis[e] = e / 4 from corner kEdgeStart[e]")
    w("//    to corner kEdgeStart[e] + (1 << axis): edges 0..3 along +x from corners")
    w("//    0,2,4,6; edges 4..7 along +y from 0,1,4,5; edges 8..11 along +z from")
    w("//    0,1,2,3.")
    w("//  - Case index: bit c set <=> corner c is INSIDE (value < iso, negative field).")
    w("//  - kTriangles[case] lists kTriangleCount[case] triangles as edge ids")
    w("//    (padding -1). With edge points at the edge midpoints, the normal")
    w("//    (p1-p0)x(p2-p0) points OUTSIDE (toward positive field); more precisely")
    w("//    it has a positive component along (outside corner - inside corner) of")
    w("//    each of the triangle's three edges.")
    w("//  - Ambiguous faces (diagonal inside/outside pattern): the two inside")
    w("//    corners are separated. Each face is decided from its own 4 corners")
    w("//    only, so neighbouring cubes agree and the mesh is watertight.")
    w("//  - Each loop of face segments is triangulated by maximising the minimum")
    w("//    angle (midpoint positions) with no diagonal lying in a cube face.")
    w("//  kMaxTriangles = %d; %d cases have more than one loop." % (kmax, multi))
    w("#pragma once")
    w("")
    w("#include <cstdint>")
    w("")
    w("namespace nbmc {")
    w("namespace Details {")
    w("namespace mc {")
    w("")
    w("inline constexpr int kMaxTriangles = %d;" % kmax)
    w("")
    w("inline constexpr std::int8_t kEdgeStart[12] = {%s};" % ", ".join(str(v) for v in EDGE_START))
    w("inline constexpr std::int8_t kEdgeAxis[12] = {%s};" % ", ".join(str(v) for v in EDGE_AXIS))
    w("")
    w("// Bit e set if edge e is crossed (its two corners differ).")
    w("inline constexpr std::uint16_t kEdgeMask[256] = {")
    w(fmt_rows([edge_mask(c) for c in range(256)], 12, 4))
    w("};")
    w("")
    w("inline constexpr std::uint8_t kTriangleCount[256] = {")
    w(fmt_rows([len(t) for t in table], 16, 1))
    w("};")
    w("")
    w("inline constexpr std::int8_t kTriangles[256][3 * kMaxTriangles] = {")
    for case, tris in enumerate(table):
        flat = [e for t in tris for e in t]
        flat += [-1] * (3 * kmax - len(flat))
        w("    {%s},  // %3d" % (", ".join(("%d" % v).rjust(2) for v in flat), case))
    w("};")
    w("")
    w("}  // namespace mc")
    w("}  // namespace Details")
    w("}  // namespace nbmc")
    return "\n".join(out) + "\n"


def main(argv):
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    path = argv[1] if len(argv) > 1 else os.path.join(root, "backends", "kokkos", "mc_tables.hpp")
    table, loop_counts = build()
    text = render(table, loop_counts)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w", newline="\n") as f:
        f.write(text)
    kmax = max(len(t) for t in table)
    multi = sum(1 for c in loop_counts if c > 1)
    print("wrote %s: kMaxTriangles=%d, cases with >1 loop: %d, max loop count: %d, longest loop: %d"
          % (path, kmax, multi, max(loop_counts),
             max((len(l) for c in range(256) for l in loops_of(c)), default=0)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
