// SPDX-License-Identifier: MIT
// The fairing flips alone (src/core/mesh_flip.hpp), timed: reads a raw
// marching-cubes mesh (PLY, e.g. `nbmc reconstruct ... --no-cleanup -o
// raw.ply`), runs the clean-up's repairs (cleanup_mesh) on it as the
// library does, then the flips K times on copies of the cleaned triangles,
// each with its wall and process CPU time (the CPU time is the figure to
// compare on a loaded machine) and a hash of the triangles (the same on
// every thread count); with NBMC_FLIP_QUALITY=1 then the dihedral mean of
// the mesh before and after the flips (as bench/nbmc_quality takes it: the
// angle between the normals of each edge's two triangles, edges of exactly
// two), its smallest angle and the closed / manifold / oriented flags
// (mesh_check.hpp).
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

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

namespace {
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}
// Mean dihedral angle in degrees over the edges of exactly two triangles.
double dihedral_mean(const std::vector<float>& p, const std::vector<std::uint32_t>& t) {
  struct E {
    std::uint64_t key;
    std::uint32_t tri;
  };
  std::vector<E> e;
  for (std::uint32_t i = 0; i < t.size() / 3; ++i)
    for (int k = 0; k < 3; ++k) {
      std::uint64_t a = t[3 * i + k], b = t[3 * i + (k + 1) % 3];
      if (a > b) std::swap(a, b);
      e.push_back({(a << 32) | b, i});
    }
  std::sort(e.begin(), e.end(), [](const E& x, const E& y) { return x.key != y.key ? x.key < y.key : x.tri < y.tri; });
  auto normal = [&](std::uint32_t i, double n[3]) {
    const float *a = &p[3 * std::size_t(t[3 * i])], *b = &p[3 * std::size_t(t[3 * i + 1])],
                *c = &p[3 * std::size_t(t[3 * i + 2])];
    const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
    const double w[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
    n[0] = u[1] * w[2] - u[2] * w[1], n[1] = u[2] * w[0] - u[0] * w[2], n[2] = u[0] * w[1] - u[1] * w[0];
    return std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  };
  double sum = 0;
  std::uint64_t count = 0;
  for (std::size_t i = 0; i < e.size();) {
    std::size_t j = i;
    while (j < e.size() && e[j].key == e[i].key) ++j;
    double n0[3], n1[3];
    if (j - i == 2) {
      const double l0 = normal(e[i].tri, n0), l1 = normal(e[i + 1].tri, n1);
      if (l0 > 0 && l1 > 0) {
        const double c = std::min(1.0, std::max(-1.0, (n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2]) / (l0 * l1)));
        sum += std::acos(c) * 180.0 / 3.14159265358979323846;
        ++count;
      }
    }
    i = j;
  }
  return count ? sum / double(count) : 0;
}

void report(const char* what, const std::vector<float>& p, const std::vector<std::uint32_t>& t) {
  const nbmc::mesh::CheckResult c = nbmc::mesh::check_mesh(p.data(), p.size() / 3, t.data(), t.size() / 3);
  std::printf("QUALITY %s dihedral_mean=%.4f min_angle=%.4f closed=%d manifold=%d oriented=%d\n", what,
              dihedral_mean(p, t), c.min_angle_degrees, int(c.closed), int(c.manifold), int(c.oriented));
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
  std::vector<std::uint32_t> x;
  for (int r = 0; r < repeat; ++r) {
    x = t;
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
  if (std::getenv("NBMC_FLIP_QUALITY")) {
    report("before", p, t);
    report("after", p, x);
  }
  return 0;
}
