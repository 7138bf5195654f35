// SPDX-License-Identifier: MIT
// Checks of the generated marching-cubes case table (backends/kokkos/mc_tables.hpp,
// produced by scripts/gen_mc_tables.py). Everything is re-derived here from the
// conventions alone (corner/edge numbering, inside = bit set, inside corners
// separated on ambiguous faces, outward winding), so a wrong table fails.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <map>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "../backends/kokkos/mc_tables.hpp"

namespace {

namespace mc = nbmc::Details::mc;

using Vec = std::array<long long, 3>;  // coordinates doubled, so midpoints are integers
using Tri = std::array<int, 3>;

constexpr int kStart[12] = {0, 2, 4, 6, 0, 1, 4, 5, 0, 1, 2, 3};

bool inside(int cs, int corner) { return (cs >> corner) & 1; }
int edgeAxis(int e) { return e / 4; }
int edgeStart(int e) { return kStart[e]; }
int edgeEnd(int e) { return kStart[e] + (1 << edgeAxis(e)); }
bool crossed(int cs, int e) { return inside(cs, edgeStart(e)) != inside(cs, edgeEnd(e)); }

Vec cornerPos2(int c) { return {2 * (c & 1), 2 * ((c >> 1) & 1), 2 * ((c >> 2) & 1)}; }

Vec mid2(int e) {  // doubled midpoint of cube edge e
  Vec a = cornerPos2(edgeStart(e)), b = cornerPos2(edgeEnd(e));
  return {(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2};
}

Vec sub(const Vec& a, const Vec& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
long long dot(const Vec& a, const Vec& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec cross(const Vec& a, const Vec& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

// Face f = 2 * axis + side: the corners whose bit `axis` equals `side`.
bool edgeOnFace(int e, int f) {
  const int axis = f / 2, side = f % 2;
  return ((edgeStart(e) >> axis) & 1) == side && ((edgeEnd(e) >> axis) & 1) == side;
}
bool shareFace(int a, int b) {
  for (int f = 0; f < 6; ++f)
    if (edgeOnFace(a, f) && edgeOnFace(b, f)) return true;
  return false;
}

std::vector<Tri> caseTriangles(int cs) {
  std::vector<Tri> out;
  for (int t = 0; t < mc::kTriangleCount[cs]; ++t)
    out.push_back({mc::kTriangles[cs][3 * t], mc::kTriangles[cs][3 * t + 1],
                   mc::kTriangles[cs][3 * t + 2]});
  return out;
}

// ---------------------------------------------------------------------------
// Global mesh extraction on a block of nx*ny*nz vertices (inside flags given).
struct Mesh {
  int nx, ny, nz;
  std::vector<Tri> tris;  // global edge-point ids: vertex index * 3 + axis
  Vec pos2(int id) const {
    const int axis = id % 3, v = id / 3;
    const int i = v % nx, j = (v / nx) % ny, k = v / (nx * ny);
    Vec p{2LL * i, 2LL * j, 2LL * k};
    p[axis] += 1;
    return p;
  }
  // Bitmask of block boundary planes (bit 2*axis + side) the point lies on.
  int boundaryPlanes(int id) const {
    const Vec p = pos2(id);
    const int n[3] = {nx, ny, nz};
    int m = 0;
    for (int a = 0; a < 3; ++a) {
      if (p[a] == 0) m |= 1 << (2 * a);
      if (p[a] == 2LL * (n[a] - 1)) m |= 1 << (2 * a + 1);
    }
    return m;
  }
};

Mesh extract(int nx, int ny, int nz, const std::vector<std::uint8_t>& in,
             std::set<int>* casesSeen = nullptr) {
  Mesh m{nx, ny, nz, {}};
  auto vid = [&](int i, int j, int k) { return (k * ny + j) * nx + i; };
  for (int k = 0; k + 1 < nz; ++k)
    for (int j = 0; j + 1 < ny; ++j)
      for (int i = 0; i + 1 < nx; ++i) {
        int cs = 0;
        for (int c = 0; c < 8; ++c)
          if (in[vid(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1))]) cs |= 1 << c;
        if (casesSeen) casesSeen->insert(cs);
        for (const Tri& t : caseTriangles(cs)) {
          Tri g;
          for (int q = 0; q < 3; ++q) {
            const int s = edgeStart(t[q]);
            g[q] = vid(i + (s & 1), j + ((s >> 1) & 1), k + ((s >> 2) & 1)) * 3 + edgeAxis(t[q]);
          }
          m.tris.push_back(g);
        }
      }
  return m;
}

// Watertightness / orientation / manifoldness of an extracted block mesh.
// Stores the number of block-boundary mesh edges (0 for a closed surface).
void checkMesh(const Mesh& m, const char* what, int* boundaryEdges = nullptr) {
  SCOPED_TRACE(what);
  std::map<std::pair<int, int>, std::vector<bool>> uses;  // (lo,hi) -> forward?
  for (const Tri& t : m.tris) {
    EXPECT_TRUE(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) << "degenerate triangle";
    for (int q = 0; q < 3; ++q) {
      const int a = t[q], b = t[(q + 1) % 3];
      uses[{std::min(a, b), std::max(a, b)}].push_back(a < b);
    }
  }
  int boundary = 0;
  if (boundaryEdges) *boundaryEdges = -1;
  for (const auto& [edge, dirs] : uses) {
    const bool onBlockBoundary =
        (m.boundaryPlanes(edge.first) & m.boundaryPlanes(edge.second)) != 0;
    if (onBlockBoundary) {
      ++boundary;
      EXPECT_EQ(dirs.size(), 1u) << "block-boundary edge " << edge.first << "-" << edge.second;
    } else {
      ASSERT_EQ(dirs.size(), 2u) << "interior edge " << edge.first << "-" << edge.second
                                 << " not shared by exactly two triangles";
      EXPECT_NE(dirs[0], dirs[1]) << "interior edge " << edge.first << "-" << edge.second
                                  << " used twice in the same direction (orientation flip)";
    }
  }
  if (boundaryEdges) *boundaryEdges = boundary;
  // Vertex manifoldness: the link of each vertex (edge opposite to it in each
  // incident triangle, directed by the triangle's winding) is one cycle for
  // interior vertices and one open path for block-boundary vertices.
  std::map<int, std::vector<std::pair<int, int>>> link;
  for (const Tri& t : m.tris)
    for (int q = 0; q < 3; ++q) link[t[q]].push_back({t[(q + 1) % 3], t[(q + 2) % 3]});
  for (const auto& [v, edges] : link) {
    std::map<int, int> next;
    std::map<int, int> indeg;
    bool ok = true;
    for (const auto& [a, b] : edges) {
      ok = ok && next.emplace(a, b).second;
      ++indeg[b];
    }
    ASSERT_TRUE(ok) << "vertex " << v << ": link vertex with two successors";
    for (const auto& [b, d] : indeg) ASSERT_EQ(d, 1) << "vertex " << v;
    const bool interior = m.boundaryPlanes(v) == 0;
    int start = next.begin()->first;
    if (!interior) {
      int starts = 0;
      for (const auto& [a, b] : next)
        if (!indeg.count(a)) {
          start = a;
          ++starts;
        }
      ASSERT_EQ(starts, 1) << "boundary vertex " << v << " link is not one open path";
    }
    std::size_t walked = 0;
    int cur = start;
    while (walked <= edges.size()) {
      auto it = next.find(cur);
      if (it == next.end()) break;
      ++walked;
      cur = it->second;
      if (interior && cur == start) break;
    }
    EXPECT_EQ(walked, edges.size()) << "vertex " << v << " ("
                                    << (interior ? "interior" : "boundary")
                                    << ") triangle fan is not a single fan";
    if (interior) {
      EXPECT_EQ(cur, start) << "interior vertex " << v << " fan not closed";
    }
  }
}

// Signed volume by the divergence theorem, sum of p0 . (p1 x p2) / 6, computed
// exactly from the doubled coordinates: returns 48 * volume (an integer).
long long signedVolume48(const Mesh& m) {
  long long v48 = 0;
  for (const Tri& t : m.tris) v48 += dot(m.pos2(t[0]), cross(m.pos2(t[1]), m.pos2(t[2])));
  return v48;
}

std::uint32_t bits(std::mt19937& rng, double p) {  // portable Bernoulli(p)
  return static_cast<std::uint32_t>(rng() >> 8) < static_cast<std::uint32_t>(p * (1u << 24));
}

// ---------------------------------------------------------------------------

TEST(McTables, EdgeConventions) {
  for (int e = 0; e < 12; ++e) {
    EXPECT_EQ(mc::kEdgeStart[e], kStart[e]);
    EXPECT_EQ(mc::kEdgeAxis[e], e / 4);
    const int s = kStart[e], a = e / 4;
    EXPECT_EQ((s >> a) & 1, 0) << "edge " << e << " must start at the low corner";
  }
}

TEST(McTables, EdgeMaskAndTriangleCounts) {
  EXPECT_EQ(mc::kTriangleCount[0], 0);
  EXPECT_EQ(mc::kTriangleCount[255], 0);
  int maxCount = 0;
  for (int cs = 0; cs < 256; ++cs) {
    SCOPED_TRACE(cs);
    int mask = 0;
    for (int e = 0; e < 12; ++e)
      if (crossed(cs, e)) mask |= 1 << e;
    EXPECT_EQ(mc::kEdgeMask[cs], mask);
    const int n = mc::kTriangleCount[cs];
    ASSERT_LE(n, mc::kMaxTriangles);
    maxCount = std::max(maxCount, n);
    int used = 0;
    for (int i = 0; i < 3 * mc::kMaxTriangles; ++i) {
      const int e = mc::kTriangles[cs][i];
      if (i < 3 * n) {
        ASSERT_GE(e, 0);
        ASSERT_LT(e, 12);
        EXPECT_TRUE(crossed(cs, e)) << "triangle uses uncrossed edge " << e;
        used |= 1 << e;
      } else {
        EXPECT_EQ(e, -1) << "padding entry " << i;
      }
    }
    EXPECT_EQ(used, mask) << "every crossed edge point must be used";
    for (const Tri& t : caseTriangles(cs))
      EXPECT_TRUE(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) << "degenerate triangle";
  }
  EXPECT_EQ(maxCount, mc::kMaxTriangles) << "kMaxTriangles must be tight";
}

// Inside one cube: sides shared by two triangles are interior diagonals (used in
// opposite directions, not lying in a face); all other sides lie in a cube face.
TEST(McTables, CaseSurfaceBoundaryLiesOnFaces) {
  for (int cs = 0; cs < 256; ++cs) {
    SCOPED_TRACE(cs);
    std::map<std::pair<int, int>, std::vector<bool>> uses;
    for (const Tri& t : caseTriangles(cs))
      for (int q = 0; q < 3; ++q) {
        const int a = t[q], b = t[(q + 1) % 3];
        uses[{std::min(a, b), std::max(a, b)}].push_back(a < b);
      }
    std::map<int, int> boundaryDegree;
    for (const auto& [side, dirs] : uses) {
      ASSERT_LE(dirs.size(), 2u);
      if (dirs.size() == 1) {
        EXPECT_TRUE(shareFace(side.first, side.second))
            << "boundary side " << side.first << "-" << side.second << " crosses the cube";
        ++boundaryDegree[side.first];
        ++boundaryDegree[side.second];
      } else {
        EXPECT_NE(dirs[0], dirs[1]) << "inconsistent winding inside the case";
        EXPECT_FALSE(shareFace(side.first, side.second))
            << "interior diagonal " << side.first << "-" << side.second << " lies in a face";
      }
    }
    // Each crossed edge point lies on exactly two faces, hence on two boundary sides.
    for (int e = 0; e < 12; ++e)
      if (crossed(cs, e)) {
        EXPECT_EQ(boundaryDegree[e], 2) << "edge " << e;
      }
  }
}

// The boundary sides on each face are exactly the segments of the face rule:
// every maximal run of inside corners (walking around the face) is cut off by
// one segment; on ambiguous faces the two inside corners are thus separated.
// Direction: seen from outside through the face, the cut-off inside corners are
// on the segment's right, i.e. cross(n_face, p1 - p0) points away from them.
TEST(McTables, FaceSegmentsFollowAmbiguityRuleAndOrientation) {
  for (int cs = 0; cs < 256; ++cs) {
    SCOPED_TRACE(cs);
    std::set<std::pair<int, int>> directedBoundary;
    std::map<std::pair<int, int>, int> count;
    for (const Tri& t : caseTriangles(cs))
      for (int q = 0; q < 3; ++q) {
        const int a = t[q], b = t[(q + 1) % 3];
        ++count[{std::min(a, b), std::max(a, b)}];
      }
    for (const Tri& t : caseTriangles(cs))
      for (int q = 0; q < 3; ++q) {
        const int a = t[q], b = t[(q + 1) % 3];
        if (count[{std::min(a, b), std::max(a, b)}] == 1) directedBoundary.insert({a, b});
      }
    std::set<std::pair<int, int>> expected;
    for (int axis = 0; axis < 3; ++axis)
      for (int side = 0; side < 2; ++side) {
        const int u = (axis + 1) % 3, v = (axis + 2) % 3;
        // Corner ring around the face (orientation irrelevant for pairing).
        int ring[4];
        const int du[4] = {0, 1, 1, 0}, dv[4] = {0, 0, 1, 1};
        for (int k = 0; k < 4; ++k) ring[k] = (side << axis) | (du[k] << u) | (dv[k] << v);
        auto edgeOf = [](int c0, int c1) {
          for (int e = 0; e < 12; ++e)
            if (std::min(c0, c1) == edgeStart(e) && std::max(c0, c1) == edgeEnd(e)) return e;
          return -1;
        };
        Vec n{0, 0, 0};
        n[axis] = side ? 1 : -1;
        for (int k = 0; k < 4; ++k) {
          if (inside(cs, ring[k]) || !inside(cs, ring[(k + 1) % 4])) continue;
          int m = (k + 1) % 4;
          Vec runSum{0, 0, 0};
          int runLen = 0;
          while (inside(cs, ring[m])) {
            const Vec p = cornerPos2(ring[m]);
            for (int a = 0; a < 3; ++a) runSum[a] += p[a];
            ++runLen;
            m = (m + 1) % 4;
          }
          const int ea = edgeOf(ring[k], ring[(k + 1) % 4]);
          const int eb = edgeOf(ring[(m + 3) % 4], ring[m]);
          // Orientation from the corners cut off: run centroid vs segment midpoint.
          const Vec pa = mid2(ea), pb = mid2(eb);
          Vec toInside;
          for (int a = 0; a < 3; ++a) toInside[a] = 2 * runSum[a] - runLen * (pa[a] + pb[a]);
          const long long s = dot(cross(n, sub(pb, pa)), toInside);
          ASSERT_NE(s, 0);
          expected.insert(s < 0 ? std::make_pair(ea, eb) : std::make_pair(eb, ea));
        }
      }
    EXPECT_EQ(directedBoundary, expected);
  }
}

// Orientation check, per triangle, strict: along a crossed edge the field goes
// from negative (inside corner) to positive (outside corner), so the outward
// normal at that edge point has a positive component along d = outside corner -
// inside corner. We require n . d > 0 (exact integer arithmetic, n =
// (p1-p0)x(p2-p0) with midpoints) for EACH of the triangle's three edges. A
// triangle with reversed winding has n . d < 0 for all three, so any winding
// error fails.
TEST(McTables, TrianglesFaceOutward) {
  for (int cs = 0; cs < 256; ++cs) {
    SCOPED_TRACE(cs);
    for (const Tri& t : caseTriangles(cs)) {
      const Vec nrm = cross(sub(mid2(t[1]), mid2(t[0])), sub(mid2(t[2]), mid2(t[0])));
      for (int q = 0; q < 3; ++q) {
        const int e = t[q];
        Vec d{0, 0, 0};
        d[edgeAxis(e)] = inside(cs, edgeStart(e)) ? 1 : -1;
        EXPECT_GT(dot(nrm, d), 0) << "triangle (" << t[0] << "," << t[1] << "," << t[2]
                                  << ") edge " << e;
      }
    }
  }
}

// Exhaustive: every sign configuration of two cubes sharing a face (12
// vertices), for each of the three face axes.
TEST(McTables, WatertightAcrossEveryFacePairExhaustive) {
  const int dims[3][3] = {{3, 2, 2}, {2, 3, 2}, {2, 2, 3}};
  for (const auto& d : dims)
    for (int cfg = 0; cfg < (1 << 12); ++cfg) {
      std::vector<std::uint8_t> in(12);
      for (int b = 0; b < 12; ++b) in[b] = (cfg >> b) & 1;
      const Mesh m = extract(d[0], d[1], d[2], in);
      checkMesh(m, "face pair");
      if (HasFatalFailure() || HasNonfatalFailure()) {
        ADD_FAILURE() << "dims " << d[0] << "x" << d[1] << "x" << d[2] << " cfg " << cfg;
        return;
      }
    }
}

TEST(McTables, WatertightOnRandomAndCheckerboardBlocks) {
  const int N = 8;
  std::set<int> seen;
  std::vector<std::vector<std::uint8_t>> fields;
  std::mt19937 rng(12345u);
  for (int seed = 0; seed < 48; ++seed) {
    const double p = 0.2 + 0.6 * (seed % 7) / 6.0;
    std::vector<std::uint8_t> in(N * N * N);
    for (auto& x : in) x = bits(rng, p);
    fields.push_back(in);
  }
  // Structured: parity patterns (full checkerboard makes every face ambiguous;
  // two-axis ones make the faces of one axis ambiguous) and their complements.
  for (int pattern = 1; pattern < 8; ++pattern)
    for (int flip = 0; flip < 2; ++flip) {
      std::vector<std::uint8_t> in(N * N * N);
      for (int k = 0; k < N; ++k)
        for (int j = 0; j < N; ++j)
          for (int i = 0; i < N; ++i) {
            const int s = ((pattern & 1) ? i : 0) + ((pattern & 2) ? j : 0) + ((pattern & 4) ? k : 0);
            in[(k * N + j) * N + i] = static_cast<std::uint8_t>((s + flip) & 1);
          }
      fields.push_back(in);
    }
  int idx = 0;
  for (const auto& in : fields) {
    const Mesh m = extract(N, N, N, in, &seen);
    const std::string name = "field " + std::to_string(idx++);
    checkMesh(m, name.c_str());
    if (HasFatalFailure()) return;
  }
  EXPECT_EQ(seen.size(), 256u) << "the fields should exercise every case";
  EXPECT_TRUE(seen.count(0x69) && seen.count(0x96)) << "full checkerboard cases";
}

TEST(McTables, SignedVolumeIsPositiveForClosedSurfaces) {
  const int N = 8;
  auto at = [&](int i, int j, int k) { return (k * N + j) * N + i; };
  // One inside vertex: the surface is the octahedron with vertices at +-1/2
  // along the axes, volume 4/3 * (1/2)^3 = 1/6.
  {
    std::vector<std::uint8_t> in(N * N * N, 0);
    in[at(3, 4, 3)] = 1;
    const Mesh m = extract(N, N, N, in);
    int open = -1;
    checkMesh(m, "single vertex", &open);
    EXPECT_EQ(open, 0);
    EXPECT_EQ(m.tris.size(), 8u);
    EXPECT_EQ(signedVolume48(m), 8) << "volume must be exactly 1/6 = 8/48";
  }
  // A box of inside vertices, then the same box with an outside vertex in it:
  // the cavity surface must be oriented inward (toward the outside vertex), so
  // the volume drops by exactly the octahedron's 1/6.
  {
    std::vector<std::uint8_t> in(N * N * N, 0);
    for (int k = 2; k <= 5; ++k)
      for (int j = 1; j <= 5; ++j)
        for (int i = 2; i <= 6; ++i) in[at(i, j, k)] = 1;
    const Mesh box = extract(N, N, N, in);
    int open = -1;
    checkMesh(box, "box", &open);
    EXPECT_EQ(open, 0);
    const long long vbox = signedVolume48(box);
    EXPECT_GT(vbox, 0);
    in[at(4, 3, 3)] = 0;
    const Mesh holed = extract(N, N, N, in);
    checkMesh(holed, "box with cavity", &open);
    EXPECT_EQ(open, 0);
    EXPECT_EQ(vbox - signedVolume48(holed), 8) << "cavity must remove exactly 1/6";
  }
  // Random blobs strictly inside the block: closed, positive volume, and
  // bounded by the volume of the cells touching inside vertices.
  std::mt19937 rng(777u);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<std::uint8_t> in(N * N * N, 0);
    int count = 0;
    for (int k = 1; k < N - 1; ++k)
      for (int j = 1; j < N - 1; ++j)
        for (int i = 1; i < N - 1; ++i) count += in[at(i, j, k)] = bits(rng, 0.55);
    if (count == 0) continue;
    const Mesh m = extract(N, N, N, in);
    const std::string name = "blob " + std::to_string(trial);
    int open = -1;
    checkMesh(m, name.c_str(), &open);
    EXPECT_EQ(open, 0) << "blob surface must be closed";
    const long long v48 = signedVolume48(m);
    EXPECT_GT(v48, 0) << name;
    EXPECT_LE(v48, 48LL * 8 * count) << name;
  }
}

}  // namespace
