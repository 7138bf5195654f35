// SPDX-License-Identifier: MIT
// The fairing flips alone (src/core/mesh_flip.hpp), timed: reads a raw
// marching-cubes mesh (PLY, e.g. `nbmc reconstruct ... --no-cleanup -o
// raw.ply`), runs the clean-up's repairs (cleanup_mesh) on it as the
// library does, then the flips K times on copies of the cleaned triangles,
// each with its wall and process CPU time (the CPU time is the figure to
// compare on a loaded machine) and a hash of the triangles (the same on
// every thread count).
//
//   nbmc_flip_bench RAW.ply CELL THREADS [K] [CHUNK]
//
// CELL: the marching-cubes cell edge (as the clean-up's small-component
// test takes it); CHUNK: the flips' chunk size (default kFlipChunkTriangles).
// With NBMC_TRACE=1 the flips' phases are traced.
#include "core/mesh_cleanup.hpp"
#include "core/mesh_flip.hpp"
#include "io/mesh.hpp"

#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

namespace {
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: nbmc_flip_bench RAW.ply CELL THREADS [K] [CHUNK]\n");
    return 2;
  }
  const nbmc::io::Mesh m = nbmc::io::read_mesh_ply(argv[1]);
  const double cell = std::atof(argv[2]);
  const std::size_t threads = std::size_t(std::atol(argv[3]));
  const int repeat = argc > 4 ? std::atoi(argv[4]) : 3;
  const std::size_t chunk = argc > 5 ? std::size_t(std::atol(argv[5])) : nbmc::mesh::kFlipChunkTriangles;
  const nbmc::ScopedHostThreads limit(threads);
  std::vector<float> p = m.positions, normals;
  std::vector<std::uint32_t> t = m.triangles;
  nbmc::mesh::cleanup_mesh(p, normals, t, cell);
  std::printf("cleaned: %zu vertices, %zu triangles\n", p.size() / 3, t.size() / 3);
  for (int r = 0; r < repeat; ++r) {
    std::vector<std::uint32_t> x = t;
    const double c0 = cpu_seconds();
    const auto w0 = std::chrono::steady_clock::now();
    const nbmc::mesh::FlipResult f =
        nbmc::mesh::flip_edges_fairing(p.data(), p.size() / 3, x, nbmc::mesh::kFlipRounds, chunk);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
    const double cpu = cpu_seconds() - c0;
    std::uint64_t h = 1469598103934665603ull;  // FNV-1a over the indices
    for (std::uint32_t v : x) h = (h ^ v) * 1099511628211ull;
    std::printf("FLIPS threads=%zu flips=%llu rounds=%d wall=%.4f cpu=%.4f hash=%016llx\n", threads,
                (unsigned long long)f.flips, f.rounds, wall, cpu, (unsigned long long)h);
  }
  return 0;
}
