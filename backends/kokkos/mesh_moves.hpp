// SPDX-License-Identifier: MIT
// The clean-up's move rounds (src/core/mesh_moves.hpp) where the mesh was
// made: on the GPU, right after its incidence (mesh_incidence.hpp), before
// the mesh is downloaded for the rest of the clean-up on the host. The
// rounds are the host's (Cleaner::move_rounds), step for step: each
// triangle's decision is evaluate_move, the same function with the same
// arithmetic (no contraction into fused multiply-adds on either side), and
// no step depends on the order in which threads run, so the moved mesh is
// the host's bit for bit. The host's clean-up then starts from its scan of
// the maybe-bad triangles (which finds what the moves left) and its passes.
//
// Per round, three kernels over the waiting triangles and one wait for the
// count of those left. Each waiting triangle has taken its vertices
// (atomic minimum of its index) where it was listed: in the list kernel, or
// in the last round's "make". (1) "decide": those holding all three decide,
// and each proposal's vertex takes the smallest proposing index (a second
// array, so the two steps cannot meet); (2) "check": the first array is
// freed, and a proposal holding its vertex with no neighbour held by a
// smaller index is made; (3) "make": the moves are written, the second
// array freed, and the losers and the waiting ones listed for the next
// round, taking their vertices. (In Kokkos' own blocks: blocks of one warp,
// to spread a round's few long evaluations over more multiprocessors, made
// "decide" slower on an H200, 1.61-1.69 against 1.22-1.31 ms for the 1.65 M
// frame; bench/RESULTS.md, session 42.)
#pragma once

#include "common.hpp"

#include "../../src/core/mesh_incidence.hpp"
#include "../../src/core/mesh_moves.hpp"

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <new>
#include <utility>

namespace nbmc {
namespace Details {

// The move rounds on the mesh pos (3 nv Real) / tri (3 nt) with its
// incidence (start, incident) and maybe-bad bits, whose degenerate area
// (relative to the positions' bounding box before the moves) is
// degenerate_double_area. Returns false, having changed nothing, when its
// scratch does not fit (OUT_OF_MEMORY, bad_alloc, the memory budget): the
// host then makes the moves. Otherwise fills inc's moves_made, moves,
// bad_before_moves and degenerate_double_area.
template <class ExecSpace, class Real>
bool device_move_rounds(const ExecSpace& space, MemoryTracker& tracker,
                        const Kokkos::View<Real*, typename ExecSpace::memory_space>& pos,
                        const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& tri,
                        const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& start,
                        const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& incident,
                        const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& bits,
                        std::size_t nv, std::size_t nt, double degenerate_double_area, mesh::PrebuiltIncidence& inc) {
  using MemSpace = typename ExecSpace::memory_space;
  using Policy = Kokkos::RangePolicy<ExecSpace>;
  constexpr std::uint32_t kFree = ~0u;
  const bool trace = host_trace_on();
  using Clock = std::chrono::steady_clock;
  const Clock::time_point t0 = trace ? Clock::now() : Clock::time_point();
  mesh::MoveMesh<Real> mm;
  mm.P = pos.data();
  mm.T = tri.data();
  mm.start = start.data();
  mm.incident = incident.data();
  mm.degenerate_double_area = degenerate_double_area;
  mm.cos_limit = mesh::kCosMaxNormalTurn;
  const std::size_t words = mesh::PrebuiltIncidence::bit_words(nt);
  try {
    // The maybe-bad triangles (an upper bound of the bad ones).
    std::uint64_t maybe = 0;
    Kokkos::parallel_reduce(
        "nbmc::moves::count", Policy(space, 0, words),
        KOKKOS_LAMBDA(const std::size_t w, std::uint64_t& s) { s += std::uint64_t(Kokkos::Impl::bit_count(bits(w))); },
        maybe);
    inc.moves_made = true;
    inc.moves = 0;
    inc.bad_before_moves = 0;
    inc.degenerate_double_area = degenerate_double_area;
    if (maybe == 0) return true;
    Buffer<std::uint32_t, MemSpace> held(tracker, "moves::held", nv), held2(tracker, "moves::held_moves", nv);
    Buffer<std::uint32_t, MemSpace> cur(tracker, "moves::waiting", maybe), next(tracker, "moves::next", maybe);
    Buffer<mesh::MoveProposal, MemSpace> prop(tracker, "moves::proposals", maybe);
    Buffer<std::uint8_t, MemSpace> state(tracker, "moves::state", maybe);
    // (32-bit counters: the GPU adds them natively; a 64-bit add became a
    // compare-and-swap loop, 1 ms per round for the 1.65 M frame's 10 k
    // items on one address.)
    Buffer<std::uint32_t, MemSpace> counts(tracker, "moves::counts", 2);  // waiting next, moved
    const Kokkos::View<std::uint32_t*, MemSpace> h = held.view(), h2 = held2.view();
    Kokkos::View<std::uint32_t*, MemSpace> c = cur.view(), x = next.view();
    const Kokkos::View<mesh::MoveProposal*, MemSpace> pr = prop.view();
    const Kokkos::View<std::uint8_t*, MemSpace> st = state.view();
    const Kokkos::View<std::uint32_t*, MemSpace> n = counts.view();
    Kokkos::deep_copy(space, h, kFree);
    Kokkos::deep_copy(space, h2, kFree);
    Kokkos::deep_copy(space, n, std::uint32_t(0));
    // The bad triangles among them, in any order (the rounds need none).
    Kokkos::parallel_for(
        "nbmc::moves::list", Policy(space, 0, words), KOKKOS_LAMBDA(const std::size_t w) {
          std::uint32_t b = bits(w);
          while (b) {
            const int i = Kokkos::Impl::bit_scan_forward(b);  // (the lowest set bit)
            b &= b - 1;
            const std::uint32_t t = std::uint32_t(32 * w) + std::uint32_t(i);
            if (t >= nt) break;
            const std::uint32_t* v = mm.T + 3 * std::size_t(t);
            if (mesh::triangle_class_of(mesh::load(mm.P, v[0]), mesh::load(mm.P, v[1]), mesh::load(mm.P, v[2]),
                                        mm.degenerate_double_area) == 0)
              continue;
            c(Kokkos::atomic_fetch_add(&n(0), 1u)) = t;
            for (int k = 0; k < 3; ++k) Kokkos::atomic_fetch_min(&h(v[k]), t);  // (step 1 of the first round)
          }
        });
    Clock::time_point ts = t0;
    std::uint32_t host_n[2] = {0, 0};
    Kokkos::View<std::uint32_t*, Kokkos::HostSpace, Kokkos::MemoryTraits<Kokkos::Unmanaged>> hn(host_n, 2);
    Kokkos::deep_copy(space, hn, n);
    space.fence();
    std::size_t m = host_n[0];
    inc.bad_before_moves = m;
    std::uint64_t rounds = 0;
    // (NBMC_TRACE: each step's time, the GPU waited for after each.)
    double step_ms[4] = {0, 0, 0, 0};  // list, decide, check, make and count
    auto step = [&](int k) {
      if (!trace) return;
      space.fence();
      const Clock::time_point t1 = Clock::now();
      step_ms[k] += std::chrono::duration<double, std::milli>(t1 - ts).count();
      ts = t1;
    };
    step(0);
    while (m > 0) {
      // (Step 1, each waiting triangle taking its vertices, was done where
      // it was listed: above, or in the last round's "make".)
      Kokkos::deep_copy(space, Kokkos::subview(n, 0), std::uint32_t(0));
      const Kokkos::View<const std::uint32_t*, MemSpace> cc = c;
      Kokkos::parallel_for("nbmc::moves::decide", Policy(space, 0, m), KOKKOS_LAMBDA(const std::size_t i) {
        const std::uint32_t t = cc(i);
        const std::uint32_t* v = mm.T + 3 * std::size_t(t);
        st(i) = 0;
        for (int k = 0; k < 3; ++k)
          if (h(v[k]) != t) return;
        mesh::MoveProposal p;
        const mesh::MoveVerdict verdict = mesh::evaluate_move(mm, t, p);
        st(i) = std::uint8_t(verdict);
        if (verdict != mesh::MoveVerdict::Propose) return;
        pr(i) = p;
        Kokkos::atomic_fetch_min(&h2(p.v), t);
      });
      step(1);
      Kokkos::parallel_for("nbmc::moves::check", Policy(space, 0, m), KOKKOS_LAMBDA(const std::size_t i) {
        const std::uint32_t t = cc(i);
        for (int k = 0; k < 3; ++k) h(mm.T[3 * std::size_t(t) + k]) = kFree;
        if (st(i) != std::uint8_t(mesh::MoveVerdict::Propose)) return;
        const std::uint32_t v = pr(i).v;
        if (h2(v) == t && !mesh::neighbour_taken_before(mm, v, t, h2.data(), 1)) st(i) = 3;
      });
      step(2);
      Kokkos::parallel_for("nbmc::moves::make", Policy(space, 0, m), KOKKOS_LAMBDA(const std::size_t i) {
        const std::uint8_t s = st(i);
        if (s == std::uint8_t(mesh::MoveVerdict::Leave)) return;
        if (s >= std::uint8_t(mesh::MoveVerdict::Propose)) h2(pr(i).v) = kFree;
        if (s == 3) {
          const mesh::MoveProposal& p = pr(i);
          for (int a = 0; a < 3; ++a) mm.P[3 * std::size_t(p.v) + a] = Real(p.p[a]);
          Kokkos::atomic_fetch_add(&n(1), 1u);
          return;
        }
        // Waits for the next round, taking its vertices (all freed by
        // "check" above).
        const std::uint32_t t = cc(i);
        x(Kokkos::atomic_fetch_add(&n(0), 1u)) = t;
        for (int k = 0; k < 3; ++k) Kokkos::atomic_fetch_min(&h(mm.T[3 * std::size_t(t) + k]), t);
      });
      Kokkos::deep_copy(space, hn, n);
      space.fence();
      m = host_n[0];
      step(3);
      ++rounds;
      std::swap(c, x);
    }
    inc.moves = host_n[1];
    if (trace)
      std::fprintf(stderr,
                   "[nbmc trace] moves on the device: items=%llu moved=%llu rounds=%llu %.3f ms (list %.3f, decide "
                   "%.3f, check %.3f, make and count %.3f)\n",
                   (unsigned long long)inc.bad_before_moves, (unsigned long long)inc.moves,
                   (unsigned long long)rounds, std::chrono::duration<double, std::milli>(Clock::now() - t0).count(),
                   step_ms[0], step_ms[1], step_ms[2], step_ms[3]);
    return true;
  } catch (const Error& e) {
    if (e.status != 6 /*NBMC_ERROR_OUT_OF_MEMORY*/ && e.status != 10 /*NBMC_ERROR_MEMORY_BUDGET*/) throw;
  } catch (const std::bad_alloc&) {
  }
  inc.moves_made = false;
  inc.moves = inc.bad_before_moves = 0;
  return false;
}

}  // namespace Details
}  // namespace nbmc
