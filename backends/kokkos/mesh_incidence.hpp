// SPDX-License-Identifier: MIT
// The clean-up's incidence, built where the mesh was made: on the GPU, right
// after marching cubes, and downloaded with the mesh (pipeline.hpp), so that
// the clean-up's first run on the host (src/core/mesh_cleanup.hpp, Cleaner)
// starts from it instead of building it on the host threads. On an H100
// machine's 16 host threads, the 1.65 M frame at r/2 (843 k vertices, 1.69 M
// triangles): the host's build and first scan took 8.3 ms of the
// clean-up's 22; this takes 0.5 ms on the GPU, about 1.1 ms more download
// and 1.6 ms on the host (bench/RESULTS.md, "Session 34").
//
// What it gives is mesh::PrebuiltIncidence's contract:
//  - start, incident: per vertex, its triangles in ascending order (the
//    corners are counted and placed with atomics, in whatever order the GPU
//    runs them; each vertex's short list is then sorted, so the lists are
//    exactly the host's);
//  - maybe_bad: a bit per triangle, set for every triangle that
//    mesh::surely_good may reject. The test below is surely_good's with a
//    margin of 1e-4 instead of 1e-6: a triangle that passes it here passes
//    it on the host, whatever the rounding of either (a triangle with an
//    angle of at least one degree has |cross|^2 within about 1e-12 of its
//    exact value relative; the float positions are the same values, taken
//    to double on both sides). The host classifies exactly the triangles
//    set here (add_if_bad), so its first list of bad triangles is the one
//    its own scan finds.
//  - The degenerate test's area is relative to the mesh's extent: the
//    positions' bounding box, reduced here as the host reduces it (min and
//    max are exact). A position that is not finite sets every bit (the
//    host then classifies every triangle, as without this).
#pragma once

#include "common.hpp"
#include "mesh_moves.hpp"

#include "../../src/core/mesh_check.hpp"  // kSinOneDegree, kDegenerateAreaFraction
#include "../../src/core/mesh_incidence.hpp"

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <new>
#include <type_traits>

namespace nbmc {
namespace Details {

// The positions' bounding box (lo, hi) and whether one is not finite.
struct MeshBox {
  double lo[3], hi[3];
  int not_finite;
};

template <class PosView>
struct MeshBoxReduce {
  using value_type = MeshBox;
  PosView pos;
  KOKKOS_INLINE_FUNCTION void init(value_type& b) const {
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = INFINITY;
      b.hi[a] = -INFINITY;
    }
    b.not_finite = 0;
  }
  // (Kokkos joins volatile values on some paths, plain ones on others.)
  template <class D, class S>
  KOKKOS_INLINE_FUNCTION static void merge(D& d, S& s) {
    for (int a = 0; a < 3; ++a) {
      d.lo[a] = s.lo[a] < d.lo[a] ? s.lo[a] : d.lo[a];
      d.hi[a] = s.hi[a] > d.hi[a] ? s.hi[a] : d.hi[a];
    }
    d.not_finite |= s.not_finite;
  }
  KOKKOS_INLINE_FUNCTION void join(value_type& d, const value_type& s) const { merge(d, s); }
  KOKKOS_INLINE_FUNCTION void join(volatile value_type& d, const volatile value_type& s) const { merge(d, s); }
  KOKKOS_INLINE_FUNCTION void operator()(const std::size_t v, value_type& b) const {
    for (int a = 0; a < 3; ++a) {
      const double x = double(pos(3 * v + a));
      if (!(x - x == 0)) b.not_finite = 1;  // NaN or infinite
      b.lo[a] = x < b.lo[a] ? x : b.lo[a];
      b.hi[a] = x > b.hi[a] ? x : b.hi[a];
    }
  }
};

// Builds the incidence and the maybe-bad bits of the mesh (pos: 3 nv Real,
// tri: 3 nt indices, every one below nv) into start (nv + 1), incident
// (3 nt) and bits ((nt + 31) / 32 words), all in MemSpace. Queued on
// `space`; one wait, for the bounding box. Returns the degenerate area the
// bits were set with (the host clean-up's, from the same box), or -1 when
// a position is not finite (every bit set).
template <class ExecSpace, class Real>
double build_prebuilt_incidence(const ExecSpace& space, MemoryTracker& tracker,
                              const Kokkos::View<const Real*, typename ExecSpace::memory_space>& pos,
                              const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& tri,
                              std::size_t nv, std::size_t nt,
                              const Kokkos::View<std::uint32_t*, typename ExecSpace::memory_space>& start,
                              const Kokkos::View<std::uint32_t*, typename ExecSpace::memory_space>& incident,
                              const Kokkos::View<std::uint32_t*, typename ExecSpace::memory_space>& bits) {
  using MemSpace = typename ExecSpace::memory_space;
  using Policy = Kokkos::RangePolicy<ExecSpace>;
  // Corners per vertex (start(v) counts v's; start(nv) stays 0), then their
  // exclusive sum: v's list begins at start(v), start(nv) = 3 nt.
  Kokkos::deep_copy(space, start, std::uint32_t(0));
  Kokkos::deep_copy(space, bits, std::uint32_t(0));
  Kokkos::parallel_for(
      "nbmc::incidence::count", Policy(space, 0, 3 * nt),
      KOKKOS_LAMBDA(const std::size_t i) { Kokkos::atomic_increment(&start(tri(i))); });
  prefix_counts(
      space, tracker, "nbmc::incidence::start", nv + 1, start, KOKKOS_LAMBDA(const std::size_t v) { return start(v); },
      false);
  {
    Buffer<std::uint32_t, MemSpace> cursor(tracker, "incidence::cursor", nv);
    const Kokkos::View<std::uint32_t*, MemSpace> cur = cursor.view();
    Kokkos::parallel_for(
        "nbmc::incidence::cursor", Policy(space, 0, nv), KOKKOS_LAMBDA(const std::size_t v) { cur(v) = start(v); });
    Kokkos::parallel_for(
        "nbmc::incidence::place", Policy(space, 0, 3 * nt), KOKKOS_LAMBDA(const std::size_t i) {
          incident(Kokkos::atomic_fetch_add(&cur(tri(i)), std::uint32_t(1))) = std::uint32_t(i / 3);
        });
    space.fence();  // (cursor is freed here)
  }
  // Each list in ascending order (a few entries: insertion sort).
  Kokkos::parallel_for(
      "nbmc::incidence::sort", Policy(space, 0, nv), KOKKOS_LAMBDA(const std::size_t v) {
        const std::uint32_t b = start(v), e = start(v + 1);
        for (std::uint32_t i = b + 1; i < e; ++i) {
          const std::uint32_t t = incident(i);
          std::uint32_t j = i;
          while (j > b && incident(j - 1) > t) {
            incident(j) = incident(j - 1);
            --j;
          }
          incident(j) = t;
        }
      });
  // The extent, as the host's clean-up finds it, and the bits.
  MeshBox box;
  Kokkos::parallel_reduce("nbmc::incidence::box", Policy(space, 0, nv), MeshBoxReduce<std::decay_t<decltype(pos)>>{pos}, box);
  double extent = 0;
  for (int a = 0; a < 3; ++a) extent = std::max(extent, box.hi[a] - box.lo[a]);
  const bool all = box.not_finite != 0 || !std::isfinite(extent);
  const double deg = 2 * mesh::kDegenerateAreaFraction * extent * extent;
  const double deg2 = deg * deg, sin2 = mesh::kSinOneDegree * mesh::kSinOneDegree;
  Kokkos::parallel_for(
      "nbmc::incidence::maybe_bad", Policy(space, 0, nt), KOKKOS_LAMBDA(const std::size_t t) {
        bool bad = all;
        if (!bad) {
          double p[3][3];
          for (int k = 0; k < 3; ++k)
            for (int a = 0; a < 3; ++a) p[k][a] = double(pos(3 * std::size_t(tri(3 * t + k)) + a));
          double ab[3], bc[3], ca[3];
          for (int a = 0; a < 3; ++a) {
            ab[a] = p[1][a] - p[0][a];
            bc[a] = p[2][a] - p[1][a];
            ca[a] = p[0][a] - p[2][a];
          }
          const double n0 = ab[1] * ca[2] - ab[2] * ca[1], n1 = ab[2] * ca[0] - ab[0] * ca[2],
                       n2 = ab[0] * ca[1] - ab[1] * ca[0];
          const double area2 = n0 * n0 + n1 * n1 + n2 * n2;
          const double x = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
          const double y = bc[0] * bc[0] + bc[1] * bc[1] + bc[2] * bc[2];
          const double z = ca[0] * ca[0] + ca[1] * ca[1] + ca[2] * ca[2];
          double l12 = x * y;
          if (y * z > l12) l12 = y * z;
          if (z * x > l12) l12 = z * x;
          constexpr double kMargin = 1 + 1e-4;  // (the host's: 1 + 1e-6)
          bad = !(area2 > 0 && area2 >= deg2 * kMargin && area2 >= sin2 * l12 * kMargin);
        }
        if (bad) Kokkos::atomic_fetch_or(&bits(t / 32), std::uint32_t(1) << (t % 32));
      });
  return all ? -1.0 : deg;
}

// build_prebuilt_incidence for a mesh in device memory, with the device
// buffers it fills and the host vectors (inc) sized for their download;
// then download start, incident and bits into inc's vectors. An
// optimisation: where the device or the host has no room for it
// (OUT_OF_MEMORY, bad_alloc, or the memory budget: wanted() leaves out its
// small scratch) build() builds nothing, returns false and leaves inc empty
// (the clean-up then builds its own).
template <class ExecSpace>
struct DeviceIncidence {
  using MemSpace = typename ExecSpace::memory_space;
  Buffer<std::uint32_t, MemSpace> start, incident, bits;
  double degenerate_double_area = -1;  // (build's: build_prebuilt_incidence)
  // Whether to build it for a mesh of nv vertices and nt triangles (32-bit
  // offsets) that takes mesh_bytes in host memory: not where the memory
  // budget would not hold it on the device (with its fill cursors) and on
  // the host besides the mesh.
  static bool wanted(const MemoryTracker& tracker, std::uint64_t mesh_bytes, std::uint64_t nv, std::uint64_t nt) {
    return nt > 0 && 3 * nt <= std::numeric_limits<std::uint32_t>::max() &&
           (!tracker.budget || tracker.current.load() + mesh_bytes +
                                       (2 * mesh::PrebuiltIncidence::words(nv, nt) + nv) * sizeof(std::uint32_t) <=
                                   tracker.budget);
  }
  template <class Real>
  bool build(const ExecSpace& space, MemoryTracker& tracker, const Kokkos::View<const Real*, MemSpace>& pos,
             const Kokkos::View<const std::uint32_t*, MemSpace>& tri, std::size_t nv, std::size_t nt,
             mesh::PrebuiltIncidence& inc) {
    inc.clear();
    try {
      start = Buffer<std::uint32_t, MemSpace>(tracker, "incidence::start", nv + 1);
      incident = Buffer<std::uint32_t, MemSpace>(tracker, "incidence::incident", 3 * nt);
      bits = Buffer<std::uint32_t, MemSpace>(tracker, "incidence::maybe_bad", mesh::PrebuiltIncidence::bit_words(nt));
      degenerate_double_area = build_prebuilt_incidence<ExecSpace, Real>(space, tracker, pos, tri, nv, nt,
                                                                         start.view(), incident.view(), bits.view());
      inc.start.resize(nv + 1);
      inc.incident.resize(3 * nt);
      inc.maybe_bad.resize(mesh::PrebuiltIncidence::bit_words(nt));
      return true;
    } catch (const Error& e) {
      if (e.status != 6 /*NBMC_ERROR_OUT_OF_MEMORY*/ && e.status != 10 /*NBMC_ERROR_MEMORY_BUDGET*/) throw;
    } catch (const std::bad_alloc&) {
    }
    start.release(), incident.release(), bits.release();
    inc.clear();
    return false;
  }
  // After build: the clean-up's move rounds on this mesh (mesh_moves.hpp;
  // pos: the positions build was given), unless the mesh holds a position
  // that is not finite or NBMC_DEVICE_MOVES=0; false when not made.
  template <class Real>
  bool move_rounds(const ExecSpace& space, MemoryTracker& tracker, const Kokkos::View<Real*, MemSpace>& pos,
                   const Kokkos::View<const std::uint32_t*, MemSpace>& tri, std::size_t nv, std::size_t nt,
                   mesh::PrebuiltIncidence& inc) {
    if (!(degenerate_double_area >= 0) || !device_moves_switched_on()) return false;
    return device_move_rounds<ExecSpace, Real>(space, tracker, pos, tri, start.view(), incident.view(), bits.view(),
                                               nv, nt, degenerate_double_area, inc);
  }
  // NBMC_DEVICE_MOVES=0: the host makes the moves (for comparisons).
  static bool device_moves_switched_on() {
    static const bool on = [] {
      const char* e = std::getenv("NBMC_DEVICE_MOVES");
      return !(e && e[0] == '0' && e[1] == 0);
    }();
    return on;
  }
};

}  // namespace Details
}  // namespace nbmc
