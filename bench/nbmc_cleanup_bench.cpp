// SPDX-License-Identifier: MIT
// The clean-up alone (src/core/mesh_cleanup.hpp), timed: reads a raw
// marching-cubes mesh (PLY, e.g. `nbmc reconstruct ... --no-cleanup -o
// raw.ply`) and runs cleanup_mesh K times on copies of it, each with its wall
// and process CPU time and a hash of the cleaned mesh (positions' bits and
// triangles: the same on every thread count). With NBMC_TRACE=1 the
// clean-up's stages and passes are traced.
//
//   nbmc_cleanup_bench RAW.ply CELL THREADS [K] [left]
//
// CELL: the marching-cubes cell edge (the small-component test's; 0: none).
// left: as for a mesh in GPU memory, the clean-up also lists where its
// result differs from its input (cleanup_mesh's `changed`); the input with
// those places copied over (untimed) then gives the same hash.
#include "core/mesh_cleanup.hpp"
#include "io/mesh.hpp"

#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

namespace {
long minor_faults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: nbmc_cleanup_bench RAW.ply CELL THREADS [K] [left]\n");
    return 2;
  }
  const nbmc::io::Mesh m = nbmc::io::read_mesh_ply(argv[1]);
  const double cell = std::atof(argv[2]);
  const std::size_t threads = std::size_t(std::atol(argv[3]));
  const int repeat = argc > 4 ? std::atoi(argv[4]) : 3;
  const bool left = argc > 5 && std::strcmp(argv[5], "left") == 0;
  const nbmc::ScopedHostThreads limit(threads);
  for (int r = 0; r < repeat; ++r) {
    std::vector<float> p = m.positions, normals = m.normals;
    std::vector<std::uint32_t> t = m.triangles;
    const long f0 = minor_faults();
    const double c0 = cpu_seconds();
    const auto w0 = std::chrono::steady_clock::now();
    nbmc::mesh::ChangedEntries changed;
    const nbmc::mesh::CleanupResult c = nbmc::mesh::cleanup_mesh(p, normals, t, cell, nullptr, left ? &changed : nullptr);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
    const double cpu = cpu_seconds() - c0;
    const long faults = minor_faults() - f0;
    if (left) {
      std::vector<float> q(m.positions.begin(), m.positions.begin() + std::ptrdiff_t(p.size()));
      std::vector<float> qn(m.normals.begin(), m.normals.begin() + std::ptrdiff_t(normals.size()));
      std::vector<std::uint32_t> u(m.triangles.begin(), m.triangles.begin() + std::ptrdiff_t(t.size()));
      for (std::uint32_t v : changed.vertices)
        for (int a = 0; a < 3; ++a) {
          q[3 * std::size_t(v) + a] = p[3 * std::size_t(v) + a];
          if (!qn.empty()) qn[3 * std::size_t(v) + a] = normals[3 * std::size_t(v) + a];
        }
      for (std::uint32_t x : changed.triangles)
        for (int c2 = 0; c2 < 3; ++c2) u[3 * std::size_t(x) + c2] = t[3 * std::size_t(x) + c2];
      p.swap(q);
      normals.swap(qn);
      t.swap(u);
      std::printf("changed: %zu vertices, %zu triangles\n", changed.vertices.size(), changed.triangles.size());
    }
    std::uint64_t h = 1469598103934665603ull;  // FNV-1a over the positions' bits and the indices
    for (float x : p) {
      std::uint32_t b;
      std::memcpy(&b, &x, 4);
      h = (h ^ b) * 1099511628211ull;
    }
    for (std::uint32_t v : t) h = (h ^ v) * 1099511628211ull;
    std::printf("repairs: %llu moves, %llu flips, %llu collapses, %llu cuts; removed %llu triangles, %llu vertices\n",
                (unsigned long long)c.moves, (unsigned long long)c.flips, (unsigned long long)c.collapses,
                (unsigned long long)c.cuts, (unsigned long long)c.removed_triangles,
                (unsigned long long)c.removed_vertices);
    std::printf("CLEANUP threads=%zu bad=%llu->%llu vertices=%zu triangles=%zu wall=%.4f cpu=%.4f faults=%ld hash=%016llx\n",
                threads, (unsigned long long)c.bad_before, (unsigned long long)c.bad_after, p.size() / 3,
                t.size() / 3, wall, cpu, faults, (unsigned long long)h);
  }
  return 0;
}
