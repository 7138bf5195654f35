// SPDX-License-Identifier: MIT
#include "clusters.hpp"

#include "params.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <unordered_map>

namespace nbmc {

namespace {
constexpr std::int64_t kAxisCells = (std::int64_t(1) << 21) - 1;

std::uint64_t key_of(std::int64_t x, std::int64_t y, std::int64_t z) {
  return std::uint64_t(x) | (std::uint64_t(y) << 21) | (std::uint64_t(z) << 42);
}

// Union-find with path halving; the root of a set is its smallest index, so
// the partition (and everything derived from it) does not depend on the
// order in which pairs are found.
std::uint32_t find(std::vector<std::uint32_t>& parent, std::uint32_t i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}
}  // namespace

ClusterFilter drop_small_clusters(const double* xyz, std::size_t n, double radius, std::uint32_t min_cluster) {
  ClusterFilter out;
  if (n == 0) return out;
  double lo[3], hi[3];
  for (int a = 0; a < 3; ++a) lo[a] = hi[a] = xyz[a];
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], xyz[3 * i + a]);
      hi[a] = std::max(hi[a], xyz[3 * i + a]);
    }
  for (int a = 0; a < 3; ++a)
    if (!((hi[a] - lo[a]) / radius < double(kAxisCells - 1))) {
      std::ostringstream s;
      s << "the particles span " << (hi[a] - lo[a]) / radius << " cluster radii (the surface radius) along axis "
        << "xyz"[a] << "; the isolated-particle filter supports at most " << kAxisCells - 1;
      throw Error(NBMC_ERROR_DOMAIN_TOO_LARGE, s.str());
    }
  // Cells of edge `radius`: linked particles lie in the same or adjacent cells.
  std::vector<std::int64_t> cell(3 * n);
  std::vector<std::uint64_t> key(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) cell[3 * i + a] = std::int64_t(std::floor((xyz[3 * i + a] - lo[a]) / radius));
    key[i] = key_of(cell[3 * i], cell[3 * i + 1], cell[3 * i + 2]);
  }
  std::vector<std::uint32_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = std::uint32_t(i);
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) {
    return key[a] != key[b] ? key[a] < key[b] : a < b;
  });
  std::unordered_map<std::uint64_t, std::pair<std::size_t, std::size_t>> cells;  // key -> [begin, end) of order
  cells.reserve(n / 4 + 1);
  for (std::size_t b = 0; b < n;) {
    std::size_t e = b + 1;
    while (e < n && key[order[e]] == key[order[b]]) ++e;
    cells.emplace(key[order[b]], std::make_pair(b, e));
    b = e;
  }
  std::vector<std::uint32_t> parent(n);
  for (std::size_t i = 0; i < n; ++i) parent[i] = std::uint32_t(i);
  const double r2 = radius * radius;
  for (std::size_t i = 0; i < n; ++i) {
    const std::int64_t* c = &cell[3 * i];
    for (std::int64_t dz = -1; dz <= 1; ++dz)
      for (std::int64_t dy = -1; dy <= 1; ++dy)
        for (std::int64_t dx = -1; dx <= 1; ++dx) {
          const std::int64_t x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
          if (x < 0 || y < 0 || z < 0) continue;
          const auto it = cells.find(key_of(x, y, z));
          if (it == cells.end()) continue;
          for (std::size_t q = it->second.first; q < it->second.second; ++q) {
            const std::uint32_t j = order[q];
            if (j <= i) continue;
            const double ex = xyz[3 * j] - xyz[3 * i], ey = xyz[3 * j + 1] - xyz[3 * i + 1],
                         ez = xyz[3 * j + 2] - xyz[3 * i + 2];
            if (ex * ex + ey * ey + ez * ez >= r2) continue;
            const std::uint32_t a = find(parent, std::uint32_t(i)), b = find(parent, j);
            if (a != b) parent[std::max(a, b)] = std::min(a, b);
          }
        }
  }
  std::vector<std::uint32_t> size(n, 0);
  for (std::size_t i = 0; i < n; ++i) ++size[find(parent, std::uint32_t(i))];
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t root = find(parent, std::uint32_t(i));
    if (size[root] >= min_cluster) {
      out.kept.push_back(std::uint32_t(i));
    } else {
      ++out.dropped_particles;
      if (root == i) ++out.dropped_clusters;
    }
  }
  return out;
}

}  // namespace nbmc
