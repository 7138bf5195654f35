// SPDX-License-Identifier: MIT
// Scalar field drivers, written once for every method (field_*.hpp):
//  - gather_field: each band vertex gathers the particles within R (paper
//    Sec. 4.1, "parallelization"). Work is tiled by 4x4x4 sub-block (one band
//    word): the occupied neighbour cells around the sub-block are looked up
//    once and shared by its up to 64 vertices; each vertex skips cells whose
//    box is farther than R. Used for the narrow band and the dense baseline.
//  - scatter_field: the paper's serial scatter baseline over a dense grid.
// Inner particles contribute like all others (no double layers, Fig. 2).
#pragma once

#include "common.hpp"
#include "field_common.hpp"
#include "grid.hpp"
#include "narrow_band.hpp"
#include "neighbourhood.hpp"

#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <string>

namespace nbmc {
namespace Details {

constexpr int kMaxTileCells = 1024;

// Which device gather runs for a whole band: 2 = one thread per band
// vertex, the threads numbered in band order (default;
// gather_vertices_direct); 1 = one thread per vertex slot of the words
// (NBMC_GPU_GATHER=slots); 0 = the team-tiled shared-memory kernel
// (NBMC_GPU_GATHER=team). The band growth's gathers (a few new vertices per
// listed word) always run one thread per slot. Measured on an H200, 1.65 M
// frame at r/2 (bench/RESULTS.md, session 20): field 14 ms (vertices), 16-17
// ms (slots); two warp-cooperative kernels (cells looked up once per warp,
// commits 6329e94 and 1dfe7e6) were slower (20-21 ms: 110-150 registers);
// on an H100 earlier: direct 54 ms, team 66 s -- the particles and the cell
// map fit in L2, and the team kernel's serial staging costs a lot.
inline int device_gather_kind() {
  static const int kind = [] {
    const char* e = std::getenv("NBMC_GPU_GATHER");
    if (e && std::string(e) == "team") return 0;
    if (e && std::string(e) == "slots") return 1;
    return 2;
  }();
  return kind;
}

// Neighbour-cell range covering [xmin - R, xmax + R] on every axis.
template <class MemSpace>
KOKKOS_INLINE_FUNCTION void cell_span(const NeighbourView<MemSpace>& nb, const float xmin[3], const float xmax[3],
                                      float R, std::int64_t lo[3], std::int64_t hi[3]) {
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::int64_t(Kokkos::Experimental::floor((xmin[a] - R) * nb.inv_nb_cell));
    hi[a] = std::int64_t(Kokkos::Experimental::floor((xmax[a] + R) * nb.inv_nb_cell));
    if (lo[a] < 0) lo[a] = 0;
    if (hi[a] > nb.nb_dims[a] - 1) hi[a] = nb.nb_dims[a] - 1;
  }
}

// Distance from coordinate v to the interval [lo, lo + S] (0 inside): one
// axis of box_distance2, and of the gathers' row cuts, which must test
// cells with the same float operations.
KOKKOS_INLINE_FUNCTION float box_gap(float lo, float S, float v) {
  const float below = lo - v, above = v - (lo + S);
  return below > 0 ? below : (above > 0 ? above : 0.f);
}

// Squared distance from point x to the box [lo, lo + S]^3.
KOKKOS_INLINE_FUNCTION float box_distance2(const float lo[3], float S, const float x[3]) {
  float dist2 = 0;
  for (int a = 0; a < 3; ++a) {
    const float d = box_gap(lo[a], S, x[a]);
    dist2 += d * d;
  }
  return dist2;
}

// Host tile evaluation, bit for bit the per-vertex order of
// eval_vertex_direct (the GPU's), vectorised across vertices instead of
// across particles. The occupied neighbour cells of the tile's span are
// looked up once. The tile's vertices go in groups of kHostLanes lanes; for
// each group and each cell (in the span's z, y, x order, which restricted to
// one vertex's own span is that vertex's order), a lane takes part exactly
// when its vertex visits the cell: the cell lies in the vertex's own
// cell_span and box_distance2 < R^2, from the same float expressions. Every
// particle of a cell some lane visits is broadcast and added lane-wise with
// the operations of Method::accumulate; lanes that do not visit the cell add
// an exact 0 (k = 0), which leaves their sums unchanged (an accumulator is
// never -0: it starts at +0 and a sum is -0 only when both terms are).
// Returns false if the span has more than kMaxTileCells cells.
#if !defined(__CUDA_ARCH__)
template <int L>
struct TileScratch {
  std::uint32_t begin[kMaxTileCells], end[kMaxTileCells];
  std::uint16_t off[kMaxTileCells][3];  // cell coordinates minus the span's lower corner
  // Per axis and cell coordinate of the span (axis a at base[a] + offset), the
  // term d * d of box_distance2 for each lane's vertex, +inf where the cell
  // is outside the vertex's own cell_span (the span's sides add up to at
  // most kMaxTileCells + 2 when their product is at most kMaxTileCells).
  typename HostSimd<L>::F gap2[kMaxTileCells + 2];
};

// The calling thread's scratch for the tile kernels (every method and lane
// count shares it; no call nests in another): a block on the heap, made on
// the thread's first tile, freed when the thread ends. A static thread_local
// TileScratch per kernel instantiation (as until session 23) made 1.2 MiB
// of thread-local storage, which glibc allocates and clears for every new
// thread of the process, and the host post-processing starts its threads
// per parallel loop (core/parallel.hpp): with 16 threads the clean-up took
// twice as long on the H100 machine's host.
inline void* host_tile_scratch(std::size_t bytes) {
  struct Block {
    void* p = nullptr;
    std::size_t n = 0;
    ~Block() { ::operator delete(p, std::align_val_t(64)); }
  };
  static thread_local Block b;
  if (b.n < bytes) {
    ::operator delete(b.p, std::align_val_t(64));
    b.p = nullptr;
    b.n = 0;
    b.p = ::operator new(bytes, std::align_val_t(64));
    b.n = bytes;
  }
  return b.p;
}
#endif

// Bits of a band word (bit = x + 4y + 16z) in the order the host groups
// them: 2x2 squares in x and y, so that a group's vertices visit nearly the
// same cells (a group of 8 lanes is a 4x2 half layer, one of 16 a 4x4 layer;
// groups of 2x2 columns, 2x2x2 and 2x2x4, measured no faster on the dev box:
// bench/RESULTS.md, "16-lane host field").
KOKKOS_INLINE_FUNCTION int tile_order(int o) {
  const int z = o >> 4, yq = (o >> 3) & 1, xq = (o >> 2) & 1, y = (o >> 1) & 1, x = o & 1;
  return (2 * xq + x) + 4 * (2 * yq + y) + 16 * z;
}

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // 32- and 64-byte vectors never cross a call that is not inlined
#endif
// The lane kernel of the host tiles, for any points: points 0..n_points-1
// (point(i, x) gives point i), in groups of L lanes, each point's sums in
// the order of eval_vertex_direct; sink(i, a, count) receives point i's
// Method::N sums and how many particles contributed. lo, hi: a cell span
// that contains every point's own cell_span. Host code only.
#if !defined(__CUDA_ARCH__)
template <class Method, int L, class MemSpace, class PointFn, class SinkFn>
inline bool eval_points_host_lanes(const NeighbourView<MemSpace>& nb, const std::int64_t lo[3],
                                   const std::int64_t hi[3], float S, const FieldConstants& fc, int n_points,
                                   PointFn&& point, SinkFn&& sink) {
  using HostVecF = typename HostSimd<L>::F;
  using HostVecI = typename HostSimd<L>::I;
  const std::int64_t span[3] = {hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1};
  if (span[0] * span[1] * span[2] > kMaxTileCells) return false;
  static_assert(alignof(TileScratch<L>) <= 64, "host_tile_scratch aligns to 64 bytes");
  TileScratch<L>& t = *new (host_tile_scratch(sizeof(TileScratch<L>))) TileScratch<L>;  // no initialisation
  int n_cells = 0;
  for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
    for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
      for (std::int64_t x = lo[0]; x <= hi[0]; ++x) {
        std::uint32_t b, e;
        if (!nb.cell_range(x, y, z, b, e)) continue;
        t.begin[n_cells] = b;
        t.end[n_cells] = e;
        t.off[n_cells][0] = std::uint16_t(x - lo[0]);
        t.off[n_cells][1] = std::uint16_t(y - lo[1]);
        t.off[n_cells][2] = std::uint16_t(z - lo[2]);
        ++n_cells;
      }
  const int base[3] = {0, int(span[0]), int(span[0] + span[1])};
  const float R2 = fc.R * fc.R;
  const float inf = std::numeric_limits<float>::infinity();
  const HostVecF one = lanes_of<HostVecF>(1.f), inv_R2 = lanes_of<HostVecF>(fc.inv_R2), R2v = lanes_of<HostVecF>(R2);
  const HostVecF zero = lanes_of<HostVecF>(0.f);
  const HostVecI izero = (HostVecI)zero;
  const float* X = nb.pos.data();
  const float* Y = X + nb.n;
  const float* Z = Y + nb.n;
  const float* PD = nb.pdata.data();  // methods with particle data only
  const float* Qt = nb.support.data();  // radii methods only: 1/R_j^2
  for (int g0 = 0; g0 < n_points; g0 += L) {
    const int m = n_points - g0 < L ? n_points - g0 : L;  // lanes in use; the others repeat lane 0, all masked
    HostVecF vx, vy, vz;
    for (int l = 0; l < L; ++l) {
      float x[3];
      point(g0 + (l < m ? l : 0), x);
      vx[l] = x[0];
      vy[l] = x[1];
      vz[l] = x[2];
      std::int64_t vlo[3], vhi[3];
      cell_span(nb, x, x, fc.R, vlo, vhi);
      for (int a = 0; a < 3; ++a)
        for (std::int64_t o = 0; o < span[a]; ++o) {
          const std::int64_t cc = lo[a] + o;
          float d2 = inf;
          if (l < m && cc >= vlo[a] && cc <= vhi[a]) {
            const float d = box_gap(float(cc) * S, S, x[a]);  // as in eval_vertex_direct
            d2 = d * d;
          }
          t.gap2[base[a] + o][l] = d2;
        }
    }
    // The lanes' x range. A cell's particles are sorted by x: those before
    // the first and after the last that can reach a lane form two runs, which
    // are skipped. They would add k = 0 in every lane, leaving every sum as it
    // is; a skipped particle has ((X - xmin)^2) * inv_R2 >= 1 (or the same
    // with xmax), computed with the lanes' own float operations, and every
    // lane's s2 is at least that (rounding is monotone), so s2 >= 1 there
    // (with radii too: a particle's own 1/R_j^2 is at least inv_R2).
    float xmin = vx[0], xmax = vx[0];
    for (int l = 1; l < L; ++l) {
      xmin = vx[l] < xmin ? vx[l] : xmin;
      xmax = vx[l] > xmax ? vx[l] : xmax;
    }
    const float inv_R2s = fc.inv_R2;
    auto beyond = [&](float d) { return (d * d) * inv_R2s >= 1.f; };
    HostVecF acc[Method::N];
    for (int q = 0; q < Method::N; ++q) acc[q] = zero;
    HostVecI count = izero;
    for (int q = 0; q < n_cells; ++q) {
      // box_distance2: ((0 + d0^2) + d1^2) + d2^2, and 0 + d0^2 == d0^2
      const HostVecF d2 = (t.gap2[t.off[q][0]] + t.gap2[base[1] + t.off[q][1]]) + t.gap2[base[2] + t.off[q][2]];
      const HostVecI visit = d2 < R2v;
      if (!host_any_of<HostVecI>(visit)) continue;
      std::uint32_t pb = t.begin[q], pe = t.end[q];
      while (pb < pe && X[pb] < xmin && beyond(X[pb] - xmin)) ++pb;
      while (pe > pb && X[pe - 1] > xmax && beyond(X[pe - 1] - xmax)) --pe;
      for (std::uint32_t p = pb; p < pe; ++p) {
        const HostVecF dx = lanes_of<HostVecF>(X[p]) - vx;
        const HostVecF dy = lanes_of<HostVecF>(Y[p]) - vy;
        const HostVecF dz = lanes_of<HostVecF>(Z[p]) - vz;
        HostVecF q = inv_R2;
        if constexpr (Method::radii) q = lanes_of<HostVecF>(Qt[p]);
        const HostVecF s2 = scaled_distance2(dx, dy, dz, q);
        const HostVecI inside = (s2 < one) & visit;  // -1 where the particle contributes
        const HostVecF k = (HostVecF)((HostVecI)(one - s2) & inside);
        count -= inside;
        Method::add(acc, dx, dy, dz, k, Method::P ? PD + std::size_t(Method::P) * p : nullptr, q);
      }
    }
    if constexpr (std::is_invocable<SinkFn&, int, int, const HostVecF*, const HostVecI&>::value) {
      sink(g0, m, static_cast<const HostVecF*>(acc), count);  // the group's sums at once
    } else {
      for (int l = 0; l < m; ++l) {
        float a[Method::N];
        for (int q = 0; q < Method::N; ++q) a[q] = acc[q][l];
        sink(g0 + l, a, std::uint32_t(count[l]));
      }
    }
  }
  return true;
}

// Whether Method has value_t, its value computed on lanes.
template <class M, class = void>
struct HasLaneValue : std::false_type {};
template <class M>
struct HasLaneValue<M, decltype(void(M::lane_value))> : std::true_type {};

// Method::value of every lane of a group's sums (acc: Method::N vectors of
// L lanes) into out[0..L): with GCC, where Method has value_t, 8 lanes at a
// time (16 as two halves: the 64-byte vectors' comparisons are slow under
// AVX-512F alone, session 22), each lane the scalar value's bits; otherwise
// lane by lane. Inside the tile kernels only (8 lanes under AVX2 + FMA, 16
// under AVX-512F + FMA).
template <class Method, int L>
inline void value_lanes(const typename HostSimd<L>::F* acc, const FieldConstants& fc, float* out) {
#if defined(NBMC_HOST_SIMD8) && defined(__GNUC__) && !defined(__clang__)
  if constexpr (HasLaneValue<Method>::value && (L == 8 || L == 16)) {
    using V = typename HostSimd<8>::F;
    for (int h = 0; h < L / 8; ++h) {
      V a[Method::N];
      for (int q = 0; q < Method::N; ++q) std::memcpy(&a[q], reinterpret_cast<const char*>(&acc[q]) + 32 * h, 32);
      const V v = Method::template value_t<V>(a, fc);
      std::memcpy(out + 8 * h, &v, 32);
    }
    return;
  }
#endif
  for (int l = 0; l < L; ++l) {
    float a[Method::N];
    for (int q = 0; q < Method::N; ++q) a[q] = acc[q][l];
    out[l] = Method::value(a, fc);
  }
}
#endif

// One band word's vertices (a 4x4x4 tile) with eval_points_host_lanes,
// bit for bit the per-vertex order of eval_vertex_direct (the GPU's).
template <class Method, int L, class MemSpace>
KOKKOS_INLINE_FUNCTION bool eval_tile_host_lanes(const NeighbourView<MemSpace>& nb, const std::int64_t lo[3],
                                                 const std::int64_t hi[3], float S, const FieldConstants& fc,
                                                 std::uint64_t word, std::uint64_t full, std::size_t w,
                                                 const BandView<MemSpace>& band, float c,
                                                 const Kokkos::View<float*, MemSpace>& phi, std::uint64_t& evals) {
#if defined(__CUDA_ARCH__)
  (void)nb; (void)lo; (void)hi; (void)S; (void)fc; (void)word; (void)full; (void)w; (void)band; (void)c; (void)phi;
  (void)evals;
  return false;  // device code uses gather_words_direct / gather_words_team
#else
  int bits[64], n_bits = 0;
  for (int o = 0; o < 64; ++o)
    if ((word >> tile_order(o)) & 1) bits[n_bits++] = tile_order(o);
  return eval_points_host_lanes<Method, L>(
      nb, lo, hi, S, fc, n_bits,
      [&](int i, float x[3]) {
        std::int64_t vi, vj, vk;
        band.vertex(w, bits[i], vi, vj, vk);
        x[0] = float(vi) * c;
        x[1] = float(vj) * c;
        x[2] = float(vk) * c;
      },
      [&](int g0, int m, const typename HostSimd<L>::F* acc, const typename HostSimd<L>::I& count) {
        float v[L];
        value_lanes<Method, L>(acc, fc, v);
        for (int l = 0; l < m; ++l) {
          evals += std::uint32_t(count[l]);
          const int bit = bits[g0 + l];
          phi(band.word_offset(w) + popcount64(full & ((std::uint64_t(1) << bit) - 1))) = v[l];
        }
      });
#endif
}

// The host's 8 and 16 lanes, chosen at run time (host_simd_lanes below):
// f(L), L a std::integral_constant<int, 8> or <int, 16>, called inside a
// function compiled for AVX2 with FMA or for AVX-512F with FMA (flatten: f
// and everything it calls are inlined into that one function, so no other
// code is compiled for those targets; FMA for the 8-lane helpers that the
// 16-lane code calls too, value_lanes). The band tiles, YT10's cell pass and
// the surface particles' sums go through with_host_lanes (SPH's cell pass
// keeps its own wrappers, sph_density.hpp says why).
// AVX-512F has 32 zmm registers: SSP07's 14 or 15 accumulators, the lanes'
// coordinates and the temporaries fit (GCC 12 keeps all but the lanes' x in
// registers, reloaded once per particle, where the 16 ymm registers of the
// AVX2 loop spilled 9 or 13 per particle; measured with SSP07's former 17 or
// 18 accumulators).
#if defined(NBMC_HOST_SIMD8)  // field_common.hpp: GCC, or any compiler with -mavx2
#define NBMC_HOST_AVX2 1
template <class F>
__attribute__((target("avx2,fma"), flatten)) auto host_lanes_avx2(const F& f) {
  return f(std::integral_constant<int, 8>());
}
#endif
#if defined(NBMC_HOST_SIMD16)  // field_common.hpp: GCC, or any compiler with -mavx512f
#define NBMC_HOST_AVX512 1
template <class F>
__attribute__((target("avx512f,fma"), flatten)) auto host_lanes_avx512(const F& f) {
  return f(std::integral_constant<int, 16>());
}
#endif

// Lanes of the host field kernel: 16 where the CPU has AVX-512F (and FMA), else 8
// where it has AVX2, else 4. NBMC_HOST_SIMD=4|8|16 asks for a width; a
// width the CPU (or the build) lacks gives the widest one below it. The
// results are the same for every width.
inline int host_simd_lanes() {
  int best = 4;
#if defined(NBMC_HOST_AVX2)
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) best = 8;
#endif
#if defined(NBMC_HOST_AVX512)
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("fma")) best = 16;
#endif
  const char* e = std::getenv("NBMC_HOST_SIMD");
  const int asked = e ? std::atoi(e) : 0;
  if (asked == 4 || asked == 8 || asked == 16) return asked < best ? asked : best;
  return best;
}

// f(L) with L = lanes (16, 8 or 4, as host_simd_lanes gives), the 8 and 16
// compiled for their targets (host_lanes_avx2, host_lanes_avx512).
template <class F>
KOKKOS_INLINE_FUNCTION auto with_host_lanes(int lanes, const F& f) {
#if defined(NBMC_HOST_AVX512)
  if (lanes == 16) return host_lanes_avx512(f);
#endif
#if defined(NBMC_HOST_AVX2)
  if (lanes == 8) return host_lanes_avx2(f);
#endif
  (void)lanes;
  return f(std::integral_constant<int, 4>());
}

// A group of 16 is a 4x4 layer of the tile (tile_order), whose vertices visit
// nearly the same cells.
template <class Method, class MemSpace>
KOKKOS_INLINE_FUNCTION bool eval_tile_host(const NeighbourView<MemSpace>& nb, const std::int64_t lo[3],
                                           const std::int64_t hi[3], float S, const FieldConstants& fc,
                                           std::uint64_t word, std::uint64_t full, std::size_t w,
                                           const BandView<MemSpace>& band, float c,
                                           const Kokkos::View<float*, MemSpace>& phi, std::uint64_t& evals,
                                           int lanes) {
  return with_host_lanes(lanes, [&nb, lo, hi, S, &fc, word, full, w, &band, c, &phi, &evals](auto L) {
    return eval_tile_host_lanes<Method, decltype(L)::value>(nb, lo, hi, S, fc, word, full, w, band, c, phi, evals);
  });
}

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

// The sums of Method's accumulators at x (acc, N floats, starting from +0)
// visiting the neighbour cells directly, in the order every backend uses:
// cells in z, y, x order, skipping those whose box is R or farther, their
// particles in sorted order. Returns how many particles contribute.
// Path: which way the rows are cut, decided at run time (0: the sub-cells
// where the neighbourhood has them) or fixed by the caller (1: the
// sub-cells, which must exist; 2: walking the rows' ends), so that a GPU
// kernel holds one of them only (with both in one kernel the walking one
// ran about 50 % slower on an H100: bench/RESULTS.md, session 27).
constexpr int kRowsAuto = 0, kRowsSubCells = 1, kRowsWalk = 2;
template <class Method, int Path = kRowsAuto, class MemSpace>
KOKKOS_INLINE_FUNCTION std::uint32_t sum_vertex_direct(const NeighbourView<MemSpace>& nb, const float x[3], float S,
                                                       const FieldConstants& fc, float* acc) {
  for (int q = 0; q < Method::N; ++q) acc[q] = 0.f;
  std::uint32_t evals = 0;
  std::int64_t lo[3], hi[3];
  cell_span(nb, x, x, fc.R, lo, hi);
  const float* X = nb.pos.data();
  const SoaPositions soa{X, X + nb.n, X + 2 * nb.n};
  const float* pd = Method::P ? nb.pdata.data() : nullptr;
  const float* q = Method::radii ? nb.support.data() : nullptr;
  const float inv_R2 = fc.inv_R2, R2 = fc.R * fc.R;
  if constexpr (Path != kRowsWalk) if (Path == kRowsSubCells || nb.has_sub_cells()) {
    // Each row is cut to the chord of the ball at the row's distance in y
    // and z, to the sub-cell, from the table (NeighbourView::sub_range): no
    // walk over particles, and fewer particles visited than the whole row
    // within R in x. The cut is conservative: what it leaves out of the
    // row's cells within R (the same cells as below) lies farther than R
    // with margins far above float rounding, so it would add k = 0 (exactly
    // +0) with s2 = scaled_distance2(dx, dy, dz, q_j), q_j >= inv_R2. The same
    // particles in the same order contribute as in the walk below. Cell and
    // sub-cell coordinates fit 32 bits here (build_dense_cells).
    const float ax = x[0] < 0 ? -x[0] : x[0], ay = x[1] < 0 ? -x[1] : x[1], az = x[2] < 0 ? -x[2] : x[2];
    const float tol = ((ax + ay) + (az + fc.R)) * 0x1p-18f;
    const float R2m = R2 * (1.f + 0x1p-14f);
    const float inv_w = 1.f / nb.sub_width;
    // The gap from coordinate v to cell cc's box on one axis: box_distance2's term.
    auto gap = [&](int cc, float v) { return box_gap(float(cc) * S, S, v); };
    const int lo0 = int(lo[0]), hi0 = int(hi[0]);
    for (int z = int(lo[2]); z <= int(hi[2]); ++z) {
      const float gz = gap(z, x[2]), gzz = gz * gz;
      const float gzt = gz - tol > 0 ? gz - tol : 0.f;
      const float c2z = R2m - gzt * gzt;
      if (!(c2z > 0)) continue;
      for (int y = int(lo[1]); y <= int(hi[1]); ++y) {
        const float gy = gap(y, x[1]), gyy = gy * gy;
        const float gyt = gy - tol > 0 ? gy - tol : 0.f;
        const float c2 = c2z - gyt * gyt;
        if (!(c2 > 0)) continue;
        const float c = Kokkos::Experimental::sqrt(c2) + tol;
        // Sub-cells m0..m1 hold every particle of the row with |x - x0| <= c:
        // sub_edge(m0) <= x0 - c and sub_edge(m1 + 1) > x0 + c.
        const float xa = x[0] - c, xb = x[0] + c;
        int m0 = int(Kokkos::Experimental::floor(xa * inv_w));
        int m1 = int(Kokkos::Experimental::floor(xb * inv_w));
        if (nb.sub_edge(m0) > xa) --m0;
        if (!(nb.sub_edge(m1 + 1) > xb)) ++m1;
        if (m0 < 4 * lo0) m0 = 4 * lo0;
        if (m1 > 4 * hi0 + 3) m1 = 4 * hi0 + 3;
        if (m0 > m1) continue;
        // ... within the row's cells within R (box_distance2 < R^2, as
        // below: the same float operations).
        int x0 = m0 >> 2, x1 = m1 >> 2;
        auto near = [&](int xx) {
          const float gx = gap(xx, x[0]);
          return (gx * gx + gyy) + gzz < R2;
        };
        while (x0 <= x1 && !near(x0)) ++x0;
        while (x1 >= x0 && !near(x1)) --x1;
        if (x0 > x1) continue;
        if (m0 < 4 * x0) m0 = 4 * x0;
        if (m1 > 4 * x1 + 3) m1 = 4 * x1 + 3;
        std::uint32_t b, e;
        nb.sub_range(m0, m1, y, z, b, e);
        if (b >= e) continue;
        if (nb.pos4.extent(0) != 0)
          evals += Method::accumulate(acc, Aos4Positions{nb.pos4.data()}, pd, q, b, e, x[0], x[1], x[2], fc.inv_R2);
        else
          evals += Method::accumulate(acc, soa, pd, q, b, e, x[0], x[1], x[2], fc.inv_R2);
      }
    }
    return evals;
  }
  if constexpr (Path == kRowsSubCells) return evals;
  // A cell's (or a row's) particles are sorted by x: the runs before the
  // first and after the last that can reach x are skipped. They would add
  // k = 0 (exactly +0 to every sum): a skipped particle has
  // ((X - x0)^2) * inv_R2 >= 1 with the float operations of s2, and
  // s2 = scaled_distance2(dx, dy, dz, q_j) is at least that (rounding is
  // monotone; q_j >= inv_R2 with radii).
  auto beyond = [&](float d) { return (d * d) * inv_R2 >= 1.f; };
  auto add = [&](std::uint32_t b, std::uint32_t e) {
    while (b < e && X[b] < x[0] && beyond(X[b] - x[0])) ++b;
    while (e > b && X[e - 1] > x[0] && beyond(X[e - 1] - x[0])) --e;
    evals += Method::accumulate(acc, soa, pd, q, b, e, x[0], x[1], x[2], fc.inv_R2);
  };
  const bool rows = nb.dense_start.extent(0) != 0;
  for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
    for (std::int64_t y = lo[1]; y <= hi[1]; ++y) {
      // The distance first: a cell that is too far needs no lookup. The
      // cells of a row within R are one run around x (box_distance2 grows
      // with the x gap).
      std::int64_t x0 = lo[0], x1 = hi[0];
      auto near = [&](std::int64_t xx) {
        const float clo[3] = {float(xx) * S, float(y) * S, float(z) * S};
        return box_distance2(clo, S, x) < R2;
      };
      while (x0 <= x1 && !near(x0)) ++x0;
      while (x1 >= x0 && !near(x1)) --x1;
      if (x0 > x1) continue;
      if (rows) {
        // With the dense table, the row's cells x0..x1 are one range of
        // particles sorted by x (cells in x order, each sorted by x): the
        // same particles in the same order as cell by cell, the runs out of
        // reach trimmed at the row's two ends instead of at every cell's.
        std::uint32_t b, e;
        nb.row_range(x0, x1, y, z, b, e);
        add(b, e);
      } else {
        for (std::int64_t xx = x0; xx <= x1; ++xx) {
          std::uint32_t b, e;
          if (nb.cell_range(xx, y, z, b, e)) add(b, e);
        }
      }
    }
  return evals;
}

// Method's sums at the particles of ranges r (r.b[i]..r.e[i], i < r.n:
// ParticleRanges, particle_reach.hpp), each as a point (the passes before the
// SPH and YT10 fields: SphWeights, Yt10Kernels): chunks of 64 particles
// sharing one cell span, L at a time as the lanes of eval_points_host_lanes,
// or one by one with sum_vertex_direct where the cells are too coarse for the
// lanes; bit for bit a device thread's sum_vertex_direct either way.
// sink(j, a, count) receives particle j's Method::N sums and how many
// particles contributed. Host code only.
template <class Method, int L, class MemSpace, class Ranges, class SinkFn>
KOKKOS_INLINE_FUNCTION void sum_particles_host_lanes(const NeighbourView<MemSpace>& nb, float S,
                                                     const FieldConstants& fc, const Ranges& r, SinkFn&& sink) {
#if defined(__CUDA_ARCH__)
  (void)nb; (void)S; (void)fc; (void)r; (void)sink;
#else
  const float* X = nb.pos.data();
  const float* Y = X + nb.n;
  const float* Z = Y + nb.n;
  std::uint32_t idx[64];
  int range = 0;
  std::uint32_t next = r.n > 0 ? r.b[0] : 0;
  for (;;) {
    int m = 0;  // the chunk: the next (up to) 64 particles of the ranges
    while (m < 64 && range < r.n) {
      if (next < r.e[range]) {
        idx[m++] = next++;
      } else if (++range < r.n) {
        next = r.b[range];
      }
    }
    if (m == 0) return;
    float xmin[3] = {X[idx[0]], Y[idx[0]], Z[idx[0]]}, xmax[3] = {xmin[0], xmin[1], xmin[2]};
    for (int i = 1; i < m; ++i) {
      const float x[3] = {X[idx[i]], Y[idx[i]], Z[idx[i]]};
      for (int a = 0; a < 3; ++a) {
        xmin[a] = x[a] < xmin[a] ? x[a] : xmin[a];
        xmax[a] = x[a] > xmax[a] ? x[a] : xmax[a];
      }
    }
    std::int64_t lo[3], hi[3];
    cell_span(nb, xmin, xmax, fc.R, lo, hi);  // contains each particle's own span (monotone in x)
    const bool tiled = eval_points_host_lanes<Method, L>(
        nb, lo, hi, S, fc, m,
        [&](int i, float x[3]) {
          x[0] = X[idx[i]];
          x[1] = Y[idx[i]];
          x[2] = Z[idx[i]];
        },
        [&](int i, const float* a, std::uint32_t count) { sink(idx[i], a, count); });
    if (!tiled)  // very coarse cells: one particle at a time
      for (int i = 0; i < m; ++i) {
        const float x[3] = {X[idx[i]], Y[idx[i]], Z[idx[i]]};
        float a[Method::N];
        const std::uint32_t count = sum_vertex_direct<Method>(nb, x, S, fc, a);
        sink(idx[i], a, count);
      }
  }
#endif
}

// Field value at x visiting the neighbour cells directly (no cell list):
// the device gather, and the host's fallback for cells so coarse that a
// tile's cell list would not fit.
template <class Method, int Path = kRowsAuto, class MemSpace>
KOKKOS_INLINE_FUNCTION float eval_vertex_direct(const NeighbourView<MemSpace>& nb, const float x[3], float S,
                                                const FieldConstants& fc, std::uint64_t& evals) {
  float acc[Method::N];
  evals += sum_vertex_direct<Method, Path>(nb, x, S, fc, acc);
  return Method::value(acc, fc);
}

// Which words a gather evaluates: all (empty list: words [0, n_words), all
// their vertices), or, after the band grew, the listed words and in each only
// the vertices of `bits` (the new ones; the others were copied by
// carry_values).
template <class MemSpace>
struct WordList {
  Kokkos::View<const std::uint64_t*, MemSpace> words, bits;
  KOKKOS_INLINE_FUNCTION bool listed() const { return words.extent(0) != 0; }
  KOKKOS_INLINE_FUNCTION std::size_t word(std::size_t q) const { return listed() ? std::size_t(words(q)) : q; }
  KOKKOS_INLINE_FUNCTION std::uint64_t todo(std::size_t q, std::uint64_t full) const { return listed() ? bits(q) : full; }
};

// Where the band grew (band contains old; old block b is block old_to_new(b)
// of band), copies the values of old's vertices to their places in band:
// one work item per old word, a straight copy where the word did not change.
template <class ExecSpace>
void carry_values(const ExecSpace& space, const BandView<typename ExecSpace::memory_space>& old,
                  std::size_t old_words, const Kokkos::View<const float*, typename ExecSpace::memory_space>& old_phi,
                  const BandView<typename ExecSpace::memory_space>& band,
                  const Kokkos::View<float*, typename ExecSpace::memory_space>& phi,
                  const Kokkos::View<const std::uint64_t*, typename ExecSpace::memory_space>& old_to_new) {
  // The four views it reads, not the two band views: a functor of 512 bytes
  // or more would go through CUDA constant memory (Kokkos 3.4), whose
  // launches wait for each other.
  const Kokkos::View<const std::uint64_t*, typename ExecSpace::memory_space> owords = old.words,
                                                                            ooffs = old.word_offset,
                                                                            nwords = band.words,
                                                                            noffs = band.word_offset;
  Kokkos::parallel_for(
      "nbmc::scalar_field::carry_values", Kokkos::RangePolicy<ExecSpace>(space, 0, old_words),
      KOKKOS_LAMBDA(const std::size_t w) {
        const std::uint64_t oword = owords(w);
        if (!oword) return;
        const std::size_t nw = std::size_t(old_to_new(w >> 3)) * 8 + (w & 7);
        const std::uint64_t nword = nwords(nw);
        const std::size_t o0 = ooffs(w), n0 = noffs(nw);
        if (oword == nword) {
          const int n = popcount64(oword);
          for (int q = 0; q < n; ++q) phi(n0 + q) = old_phi(o0 + q);
          return;
        }
        std::uint64_t rest = oword;
        int q = 0;
        while (rest) {
          const int bit = ctz64(rest);
          rest &= rest - 1;
          phi(n0 + popcount64(nword & ((std::uint64_t(1) << bit) - 1))) = old_phi(o0 + q);
          ++q;
        }
      });
  // No fence: the gather that fills the new vertices runs after it on the
  // same execution space instance (band_growth.hpp).
}

// Host gather: one work item per band word (4x4x4 tile), vectorised across
// the tile's vertices (eval_tile_host); the same values as eval_vertex_direct.
template <class Method, class ExecSpace>
std::uint64_t gather_words_host(const ExecSpace& space, const NeighbourView<typename ExecSpace::memory_space>& nb,
                                const BandView<typename ExecSpace::memory_space>& band, std::size_t w0,
                                std::size_t w1, const Grid& g, const FieldConstants& fc,
                                const Kokkos::View<float*, typename ExecSpace::memory_space>& phi,
                                const WordList<typename ExecSpace::memory_space>& list) {
  const float c = float(g.cell), S = float(g.nb_cell);
  const int lanes = host_simd_lanes();
  std::uint64_t evals = 0;
  Kokkos::parallel_reduce(
      "nbmc::scalar_field::gather", Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, w0, w1),
      KOKKOS_LAMBDA(const std::size_t q, std::uint64_t& acc_evals) {
        const std::size_t w = list.word(q);
        const std::uint64_t full = band.words(w);
        std::uint64_t word = list.todo(q, full);
        if (!word) return;
        std::int64_t i0, j0, k0;
        band.vertex(w, 0, i0, j0, k0);
        // The tile's span contains every vertex's own span (the float
        // operations of cell_span are monotone in x).
        const float tmin[3] = {float(i0) * c, float(j0) * c, float(k0) * c};
        const float tmax[3] = {float(i0 + 3) * c, float(j0 + 3) * c, float(k0 + 3) * c};
        std::int64_t lo[3], hi[3];
        cell_span(nb, tmin, tmax, fc.R, lo, hi);
        if (eval_tile_host<Method>(nb, lo, hi, S, fc, word, full, w, band, c, phi, acc_evals, lanes)) return;
        while (word) {  // very coarse cells: per vertex
          const int bit = ctz64(word);
          word &= word - 1;
          std::int64_t i, j, k;
          band.vertex(w, bit, i, j, k);
          const float x[3] = {float(i) * c, float(j) * c, float(k) * c};
          phi(band.word_offset(w) + popcount64(full & ((std::uint64_t(1) << bit) - 1))) =
              eval_vertex_direct<Method>(nb, x, S, fc, acc_evals);
        }
      },
      evals);
  space.fence();
  return evals;
}

// Device gather (the paper's future work, "data tiling"): one team of 64
// threads per band word; the team looks up the tile's neighbour cells, then
// stages the candidate particles through shared memory in chunks, and each
// thread accumulates its own vertex. The summation order (cells in order,
// particles in sorted order) is fixed, so results are deterministic.
constexpr int kTeamChunk = 512;

template <class Method, class ExecSpace>
std::uint64_t gather_words_team(const ExecSpace& space, const NeighbourView<typename ExecSpace::memory_space>& nb,
                                const BandView<typename ExecSpace::memory_space>& band, std::size_t w0,
                                std::size_t w1, const Grid& g, const FieldConstants& fc,
                                const Kokkos::View<float*, typename ExecSpace::memory_space>& phi,
                                const WordList<typename ExecSpace::memory_space>& list) {
  using MemSpace = typename ExecSpace::memory_space;
  using Policy = Kokkos::TeamPolicy<ExecSpace>;
  using Member = typename Policy::member_type;
  using Scratch = typename ExecSpace::scratch_memory_space;
  using U32 = Kokkos::View<std::uint32_t*, Scratch, Kokkos::MemoryUnmanaged>;
  using F32 = Kokkos::View<float*, Scratch, Kokkos::MemoryUnmanaged>;
  const float c = float(g.cell), S = float(g.nb_cell);
  // x, y, z (and the particle data, and 1/R_j^2 with radii) of each staged particle
  constexpr int kSupport = 3 + Method::P;
  constexpr int kStaged = 3 + Method::P + (Method::radii ? 1 : 0);
  const std::size_t shmem = 3 * U32::shmem_size(kMaxTileCells + 1) + F32::shmem_size(kStaged * kTeamChunk);
  Kokkos::View<std::uint64_t, MemSpace> counter("nbmc::scalar_field::evals");
  Policy policy(space, int(w1 - w0), 64);
  Kokkos::parallel_for(
      "nbmc::scalar_field::gather_team", policy.set_scratch_size(0, Kokkos::PerTeam(shmem)),
      KOKKOS_LAMBDA(const Member& team) {
        const std::size_t w = list.word(w0 + std::size_t(team.league_rank()));
        const int t = team.team_rank();
        const std::uint64_t full = band.words(w);
        const std::uint64_t word = list.todo(w0 + std::size_t(team.league_rank()), full);
        if (!word) return;
        std::int64_t i0, j0, k0;
        band.vertex(w, 0, i0, j0, k0);
        const bool mine = (word >> t) & 1;
        std::int64_t i, j, k;
        band.vertex(w, t, i, j, k);
        const float x[3] = {float(i) * c, float(j) * c, float(k) * c};
        const std::size_t out = band.word_offset(w) + popcount64(full & ((std::uint64_t(1) << t) - 1));
        const float tmin[3] = {float(i0) * c, float(j0) * c, float(k0) * c};
        const float tmax[3] = {float(i0 + 3) * c, float(j0 + 3) * c, float(k0 + 3) * c};
        std::int64_t lo[3], hi[3];
        cell_span(nb, tmin, tmax, fc.R, lo, hi);
        const std::int64_t nx = hi[0] - lo[0] + 1, ny = hi[1] - lo[1] + 1, nz = hi[2] - lo[2] + 1;
        const std::int64_t n_span = nx * ny * nz;
        std::uint64_t evals = 0;
        if (n_span > kMaxTileCells) {  // very coarse cells: per vertex, no tile
          if (mine) phi(out) = eval_vertex_direct<Method>(nb, x, S, fc, evals);
          if (evals) Kokkos::atomic_add(&counter(), evals);
          return;
        }
        U32 begin(team.team_scratch(0), kMaxTileCells + 1), count(team.team_scratch(0), kMaxTileCells + 1),
            start(team.team_scratch(0), kMaxTileCells + 1);
        F32 px(team.team_scratch(0), kStaged * kTeamChunk);
        const float R2 = fc.R * fc.R;
        // 1. the cells of the span (in order), empty or too far from the tile: count 0
        Kokkos::parallel_for(Kokkos::TeamThreadRange(team, int(n_span)), [&](const int q) {
          const std::int64_t cx = lo[0] + q % nx, cy = lo[1] + (q / nx) % ny, cz = lo[2] + q / (nx * ny);
          std::uint32_t b = 0, e = 0;
          float d2 = 0;
          const float clo[3] = {float(cx) * S, float(cy) * S, float(cz) * S};
          for (int a = 0; a < 3; ++a) {
            const float gap = clo[a] > tmax[a] ? clo[a] - tmax[a] : (tmin[a] > clo[a] + S ? tmin[a] - clo[a] - S : 0.f);
            d2 += gap * gap;
          }
          if (d2 < R2) nb.cell_range(cx, cy, cz, b, e);
          begin(q) = b;
          count(q) = e - b;
        });
        team.team_barrier();
        // 2. prefix of the counts: where each cell's particles go in the staged sequence
        Kokkos::parallel_scan(Kokkos::TeamThreadRange(team, int(n_span)),
                              [&](const int q, std::uint32_t& upd, const bool final) {
                                const std::uint32_t cq = count(q);
                                if (final) start(q) = upd;
                                upd += cq;
                              });
        team.team_barrier();
        const std::uint32_t total = start(int(n_span) - 1) + count(int(n_span) - 1);
        // 3. stage chunks through shared memory; each thread accumulates its vertex
        float acc[Method::N];
        for (int q = 0; q < Method::N; ++q) acc[q] = 0.f;
        for (std::uint32_t base = 0; base < total; base += kTeamChunk) {
          const std::uint32_t m = total - base < std::uint32_t(kTeamChunk) ? total - base : std::uint32_t(kTeamChunk);
          Kokkos::parallel_for(Kokkos::TeamThreadRange(team, int(m)), [&](const int e) {
            const std::uint32_t pos = base + std::uint32_t(e);
            int a = 0, b = int(n_span) - 1;  // last cell with start <= pos and count > 0
            while (a < b) {
              const int mid = (a + b + 1) / 2;
              if (start(mid) <= pos) a = mid;
              else b = mid - 1;
            }
            while (count(a) == 0) --a;  // cells before a non-empty one share its start
            const std::uint32_t j = begin(a) + (pos - start(a));
            px(e) = nb.pos(j);
            px(kTeamChunk + e) = nb.pos(nb.n + j);
            px(2 * kTeamChunk + e) = nb.pos(2 * nb.n + j);
            for (int q = 0; q < Method::P; ++q)
              px(3 * kTeamChunk + Method::P * e + q) = nb.pdata(std::size_t(Method::P) * j + q);
            if (Method::radii) px(kSupport * kTeamChunk + e) = nb.support(j);
          });
          team.team_barrier();
          if (mine)
            evals += Method::accumulate(acc, SoaPositions{px.data(), px.data() + kTeamChunk, px.data() + 2 * kTeamChunk},
                                        Method::P ? px.data() + 3 * kTeamChunk : nullptr,
                                        Method::radii ? px.data() + kSupport * kTeamChunk : nullptr, 0, m, x[0],
                                        x[1], x[2], fc.inv_R2);
          team.team_barrier();
        }
        if (mine) {
          phi(out) = Method::value(acc, fc);
          Kokkos::atomic_add(&counter(), evals);
        }
      });
  space.fence();
  std::uint64_t evals = 0;
  Kokkos::deep_copy(evals, counter);
  return evals;
}

// Device gather, simplest form: one thread per band vertex walking its
// neighbour cells itself (pruned by distance); particles and the cell map are
// small enough to stay in the GPU's L2 cache.
template <class Method, int Path, class ExecSpace>
std::uint64_t gather_words_direct(const ExecSpace& space, const NeighbourView<typename ExecSpace::memory_space>& nb,
                                  const BandView<typename ExecSpace::memory_space>& band, std::size_t w0,
                                  std::size_t w1, const Grid& g, const FieldConstants& fc,
                                  const Kokkos::View<float*, typename ExecSpace::memory_space>& phi,
                                  const WordList<typename ExecSpace::memory_space>& list,
                                  const Kokkos::View<unsigned long long*, typename ExecSpace::memory_space>& sink) {
  using MemSpace = typename ExecSpace::memory_space;
  const float c = float(g.cell), S = float(g.nb_cell);
  // A parallel_for, not a parallel_reduce: Kokkos 3.4 launches a CUDA reduce
  // on a capped grid (ncu, H100, 1.65 M frame at cell r: 256 blocks of 256
  // threads, 0.48 waves, 21% achieved occupancy, 8.4 ms). The evaluation
  // count goes through counters (native 64-bit atomics): per word and a
  // small reduce here; for the band growth's gathers (band_growth.hpp), the
  // caller's `sink` (a power of two of counters, spread by word) read once
  // after the growth, so that its launches need no allocation and no sync.
  const bool to_sink = sink.extent(0) > 0;
  Kokkos::View<unsigned long long*, MemSpace> counts;
  if (!to_sink) counts = Kokkos::View<unsigned long long*, MemSpace>("nbmc::scalar_field::evals_per_word", w1 - w0);
  const Kokkos::View<unsigned long long*, MemSpace> target = to_sink ? sink : counts;
  // Counter of the q-th listed word: (q - base) & mask.
  const std::size_t base = to_sink ? 0 : w0, mask = to_sink ? sink.extent(0) - 1 : ~std::size_t(0);
  Kokkos::parallel_for(
      "nbmc::scalar_field::gather_direct", Kokkos::RangePolicy<ExecSpace>(space, w0 * 64, w1 * 64),
      KOKKOS_LAMBDA(const std::size_t v) {
        const std::size_t q = v >> 6;
        const std::size_t w = list.word(q);
        const int bit = int(v & 63);
        const std::uint64_t full = band.words(w);
        if (!((list.todo(q, full) >> bit) & 1)) return;
        std::int64_t i, j, k;
        band.vertex(w, bit, i, j, k);
        const std::size_t out = band.word_offset(w) + popcount64(full & ((std::uint64_t(1) << bit) - 1));
        const float x[3] = {float(i) * c, float(j) * c, float(k) * c};
        std::uint64_t e = 0;
        phi(out) = eval_vertex_direct<Method, Path>(nb, x, S, fc, e);
        if (e) Kokkos::atomic_add(&target((q - base) & mask), static_cast<unsigned long long>(e));
      });
  if (to_sink) return 0;
  std::uint64_t evals = 0;
  Kokkos::parallel_reduce(
      "nbmc::scalar_field::count_evals", Kokkos::RangePolicy<ExecSpace>(space, 0, w1 - w0),
      KOKKOS_LAMBDA(const std::size_t q, std::uint64_t& acc) { acc += counts(q); }, evals);
  space.fence();
  return evals;
}

// Word of band index o: the last word whose first vertex is at or before o
// (an empty word after it starts after o); and the bit of that vertex.
template <class MemSpace>
KOKKOS_INLINE_FUNCTION void word_and_bit_of(const BandView<MemSpace>& band, std::size_t n_words, std::uint64_t o,
                                            std::size_t& w, int& bit) {
  std::size_t a = 0, b = n_words - 1;
  while (a < b) {
    const std::size_t mid = (a + b + 1) / 2;
    if (band.word_offset(mid) <= o) a = mid;
    else b = mid - 1;
  }
  w = a;
  std::uint64_t word = band.words(a);
  int rank = int(o - band.word_offset(a));
  int base = 0;  // the rank-th set bit: halve the word while the rank lies beyond the lower half
  for (int half = 32; half >= 8; half /= 2) {
    const std::uint64_t low = word & ((std::uint64_t(1) << half) - 1);
    const int n = popcount64(low);
    if (rank >= n) {
      rank -= n;
      word >>= half;
      base += half;
    } else {
      word = low;
    }
  }
  for (; rank > 0; --rank) word &= word - 1;
  bit = base + ctz64(word);
}

// Device gather over band indices [o0, o1): one thread per band vertex, in
// band order, so that a warp's 32 threads are 32 vertices of one or two
// neighbouring words (one thread per vertex slot leaves the lanes of the
// slots outside the band idle: most of a word's 64 on a thin band). Each
// vertex's value is eval_vertex_direct's, as in gather_words_direct.
template <class Method, int Path, class ExecSpace>
std::uint64_t gather_vertices_direct(const ExecSpace& space, const NeighbourView<typename ExecSpace::memory_space>& nb,
                                     const BandView<typename ExecSpace::memory_space>& band, std::size_t n_words,
                                     std::size_t o0, std::size_t o1, const Grid& g, const FieldConstants& fc,
                                     const Kokkos::View<float*, typename ExecSpace::memory_space>& phi) {
  using MemSpace = typename ExecSpace::memory_space;
  const float c = float(g.cell), S = float(g.nb_cell);
  // Evaluation counts per 64 vertices, summed below (see gather_words_direct
  // on why not a parallel_reduce).
  Kokkos::View<unsigned long long*, MemSpace> counts("nbmc::scalar_field::evals_per_64", (o1 - o0 + 63) / 64);
  Kokkos::parallel_for(
      "nbmc::scalar_field::gather_vertices", Kokkos::RangePolicy<ExecSpace>(space, o0, o1),
      KOKKOS_LAMBDA(const std::size_t o) {
        std::size_t w;
        int bit;
        word_and_bit_of(band, n_words, o, w, bit);
        std::int64_t i, j, k;
        band.vertex(w, bit, i, j, k);
        const float x[3] = {float(i) * c, float(j) * c, float(k) * c};
        std::uint64_t e = 0;
        phi(o) = eval_vertex_direct<Method, Path>(nb, x, S, fc, e);
        if (e) Kokkos::atomic_add(&counts((o - o0) >> 6), static_cast<unsigned long long>(e));
      });
  std::uint64_t evals = 0;
  Kokkos::parallel_reduce(
      "nbmc::scalar_field::count_evals", Kokkos::RangePolicy<ExecSpace>(space, 0, counts.extent(0)),
      KOKKOS_LAMBDA(const std::size_t q, std::uint64_t& acc) { acc += counts(q); }, evals);
  space.fence();
  return evals;
}

// Evaluates the field on the band's words [0, n_words), or with a list (see
// WordList; n_words is then its length) only on the listed vertices: after
// the band grew, the new ones (carry_values copies the others). With `sink`
// (a power of two of device counters), the default device gather adds its
// evaluation count there and returns 0 (no sync); the host gathers return it.
template <class Method, class ExecSpace>
std::uint64_t gather_field(const ExecSpace& space, const NeighbourView<typename ExecSpace::memory_space>& nb,
                           const BandView<typename ExecSpace::memory_space>& band, std::size_t n_words,
                           const Grid& g, const FieldConstants& fc,
                           const Kokkos::View<float*, typename ExecSpace::memory_space>& phi,
                           const Progress& progress,
                           const WordList<typename ExecSpace::memory_space>& list = {},
                           const Kokkos::View<unsigned long long*, typename ExecSpace::memory_space>& sink = {}) {
  ScopedRegion region("nbmc::scalar_field::gather");
  using MemSpace = typename ExecSpace::memory_space;
  std::uint64_t total_evals = 0;
  // Chunks bound the time to react to cancellation. On a GPU, launches of
  // 4096 words filled half a wave of an H100 (ncu), so chunks are larger there.
  constexpr bool host = Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible;
  const bool sub_cells = nb.has_sub_cells();
  if constexpr (!host) {
    if (!list.listed() && device_gather_kind() == 2) {
      // One thread per band vertex (phi holds the band's values), in chunks.
      const std::size_t n = phi.extent(0);
      if (n_words == 0 || n == 0) return 0;
      const std::size_t vchunk = std::max<std::size_t>(std::size_t(1) << 22, n / 8);
      for (std::size_t o0 = 0; o0 < n; o0 += vchunk) {
        const std::size_t o1 = std::min(n, o0 + vchunk);
        total_evals += sub_cells ? gather_vertices_direct<Method, kRowsSubCells>(space, nb, band, n_words, o0, o1, g, fc, phi)
                                 : gather_vertices_direct<Method, kRowsWalk>(space, nb, band, n_words, o0, o1, g, fc, phi);
        trace("gather chunk", o1 - o0);
        progress(4 /*NBMC_STAGE_FIELD*/, double(o1) / double(n));
      }
      return total_evals;
    }
  }
  const std::size_t chunk = host ? std::max<std::size_t>(4096, n_words / 64) : std::max<std::size_t>(65536, n_words / 8);
  for (std::size_t w0 = 0; w0 < n_words; w0 += chunk) {
    const std::size_t w1 = std::min(n_words, w0 + chunk);
    if constexpr (host)
      total_evals += gather_words_host<Method>(space, nb, band, w0, w1, g, fc, phi, list);
    else if (device_gather_kind() != 0)
      total_evals += sub_cells ? gather_words_direct<Method, kRowsSubCells>(space, nb, band, w0, w1, g, fc, phi, list, sink)
                               : gather_words_direct<Method, kRowsWalk>(space, nb, band, w0, w1, g, fc, phi, list, sink);
    else
      total_evals += gather_words_team<Method>(space, nb, band, w0, w1, g, fc, phi, list);
    trace("gather chunk", w1 - w0);
    if (!list.listed()) progress(4 /*NBMC_STAGE_FIELD*/, double(w1) / double(n_words));
  }
  return total_evals;
}

// Serial scatter over a dense grid of accumulators (the paper's baseline).
// Host memory only. Writes phi for every vertex of a dense band.
template <class Method, class ExecSpace>
std::uint64_t scatter_field(const ExecSpace& space, MemoryTracker& tracker,
                            const Kokkos::View<const float*, Kokkos::HostSpace>& pos,
                            const Kokkos::View<const float*, Kokkos::HostSpace>& pdata,
                            const Kokkos::View<const float*, Kokkos::HostSpace>& support, std::size_t n,
                            const BandView<typename ExecSpace::memory_space>& band, std::size_t n_words,
                            const Grid& g, const FieldConstants& fc,
                            const Kokkos::View<float*, typename ExecSpace::memory_space>& phi,
                            const Progress& progress) {
  ScopedRegion region("nbmc::scalar_field::scatter");
  constexpr int N = Method::N;
  const std::uint64_t nv = g.vertex_count();
  Buffer<float, Kokkos::HostSpace> acc(tracker, "scalar_field::scatter_accumulators", nv * N, true);
  float* a = acc.data();
  const double c = g.cell;
  const std::int64_t d0 = g.dims[0], d1 = g.dims[1], d2 = g.dims[2];
  std::uint64_t evals = 0;
  for (std::size_t p = 0; p < n; ++p) {
    const float px = pos(p), py = pos(n + p), pz = pos(2 * n + p);
    const float* const pd = Method::P ? pdata.data() + std::size_t(Method::P) * p : nullptr;
    const float qp = Method::radii ? support(p) : fc.inv_R2;  // the vertex range below stays R's
    const std::int64_t lo[3] = {std::max<std::int64_t>(0, std::int64_t(std::ceil((px - fc.R) / c))),
                                std::max<std::int64_t>(0, std::int64_t(std::ceil((py - fc.R) / c))),
                                std::max<std::int64_t>(0, std::int64_t(std::ceil((pz - fc.R) / c)))};
    const std::int64_t hi[3] = {std::min<std::int64_t>(d0 - 1, std::int64_t(std::floor((px + fc.R) / c))),
                                std::min<std::int64_t>(d1 - 1, std::int64_t(std::floor((py + fc.R) / c))),
                                std::min<std::int64_t>(d2 - 1, std::int64_t(std::floor((pz + fc.R) / c)))};
    for (std::int64_t k = lo[2]; k <= hi[2]; ++k) {
      const float dz = pz - float(k) * float(c);
      for (std::int64_t j = lo[1]; j <= hi[1]; ++j) {
        const float dy = py - float(j) * float(c);
        float* row = a + N * std::size_t(d0) * (std::size_t(j) + std::size_t(d1) * std::size_t(k));
        for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
          const float dx = px - float(i) * float(c);
          const float s2 = scaled_distance2(dx, dy, dz, qp);
          if (s2 >= 1.f) continue;
          Method::add(row + N * i, dx, dy, dz, 1.f - s2, pd, qp);
          ++evals;
        }
      }
    }
    if ((p & 0xffff) == 0xffff) progress(4, 0.95 * double(p) / double(n));
  }
  Kokkos::parallel_for(
      "nbmc::scalar_field::scatter_finalize", Kokkos::RangePolicy<ExecSpace>(space, 0, n_words),
      KOKKOS_LAMBDA(const std::size_t w) {
        band.for_each_vertex(w, [&](const int bit, const std::int64_t out) {
          std::int64_t i, j, k;
          band.vertex(w, bit, i, j, k);
          const std::size_t lin = std::size_t(i) + std::size_t(d0) * (std::size_t(j) + std::size_t(d1) * std::size_t(k));
          phi(out) = Method::value(a + N * lin, fc);
        });
      });
  space.fence();
  progress(4, 1.0);
  return evals;
}

}  // namespace Details
}  // namespace nbmc
