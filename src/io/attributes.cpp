// SPDX-License-Identifier: MIT
#include "io/attributes.hpp"

#include "io/detail.hpp"

#if defined(_OPENMP)
#include <omp.h>
#endif

#include <algorithm>
#include <cmath>
#include <limits>

namespace nbmc::io {

const Attribute* find_attribute(const std::vector<Attribute>& list, const std::string& name) {
  for (const Attribute& a : list)
    if (a.name == name) return &a;
  const std::string lower = detail::to_lower(name);
  for (const Attribute& a : list)
    if (detail::to_lower(a.name) == lower) return &a;
  return nullptr;
}

std::string attribute_names(const std::vector<Attribute>& list) {
  if (list.empty()) return "none";
  std::string out;
  for (const Attribute& a : list) {
    if (!out.empty()) out += ", ";
    out += a.name + (a.components == 3 ? " (vector)" : " (scalar)");
  }
  return out;
}

namespace {

struct Cell {
  std::int64_t i, j, k;
  bool operator==(const Cell& o) const { return i == o.i && j == o.j && k == o.k; }
  bool operator<(const Cell& o) const { return i != o.i ? i < o.i : j != o.j ? j < o.j : k < o.k; }
};

std::uint64_t hash(const Cell& c) {
  std::uint64_t h = static_cast<std::uint64_t>(c.i) * 0x9E3779B97F4A7C15ull;
  h ^= static_cast<std::uint64_t>(c.j) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
  h ^= static_cast<std::uint64_t>(c.k) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
  h ^= h >> 31;
  return h;
}

// Particles sorted by cell; an open-addressing table from cell to the range
// of its particles.
class HashGrid {
public:
  HashGrid(const double* xyz, std::size_t n, double cell) : inv_(1.0 / cell) {
    for (int a = 0; a < 3; ++a) origin_[a] = std::numeric_limits<double>::infinity();
    for (std::size_t p = 0; p < n; ++p)
      for (int a = 0; a < 3; ++a) origin_[a] = std::min(origin_[a], xyz[3 * p + static_cast<std::size_t>(a)]);
    std::vector<std::pair<Cell, std::uint32_t>> items(n);
    for (std::size_t p = 0; p < n; ++p) items[p] = {cell_of(&xyz[3 * p]), static_cast<std::uint32_t>(p)};
    std::sort(items.begin(), items.end(), [](const auto& a, const auto& b) {
      return a.first == b.first ? a.second < b.second : a.first < b.first;
    });
    order_.resize(n);
    for (std::size_t p = 0; p < n; ++p) order_[p] = items[p].second;
    std::size_t cells = 0;
    for (std::size_t p = 0; p < n; ++p) cells += (p == 0 || !(items[p].first == items[p - 1].first));
    std::size_t cap = 16;
    while (cap < 2 * cells) cap *= 2;
    mask_ = cap - 1;
    slots_.assign(cap, Slot{});
    for (std::size_t p = 0; p < n;) {
      std::size_t q = p;
      while (q < n && items[q].first == items[p].first) ++q;
      std::size_t s = hash(items[p].first) & mask_;
      while (slots_[s].used) s = (s + 1) & mask_;
      slots_[s] = Slot{items[p].first, static_cast<std::uint32_t>(p), static_cast<std::uint32_t>(q), true};
      p = q;
    }
  }

  Cell cell_of(const double* x) const {
    Cell c;
    c.i = static_cast<std::int64_t>(std::floor((x[0] - origin_[0]) * inv_));
    c.j = static_cast<std::int64_t>(std::floor((x[1] - origin_[1]) * inv_));
    c.k = static_cast<std::int64_t>(std::floor((x[2] - origin_[2]) * inv_));
    return c;
  }
  // Range [begin, end) in order() of the particles in cell c.
  bool find(const Cell& c, std::uint32_t& begin, std::uint32_t& end) const {
    std::size_t s = hash(c) & mask_;
    while (slots_[s].used) {
      if (slots_[s].cell == c) {
        begin = slots_[s].begin;
        end = slots_[s].end;
        return true;
      }
      s = (s + 1) & mask_;
    }
    return false;
  }
  const std::vector<std::uint32_t>& order() const { return order_; }

private:
  struct Slot {
    Cell cell{0, 0, 0};
    std::uint32_t begin = 0, end = 0;
    bool used = false;
  };
  double inv_;
  double origin_[3];
  std::vector<std::uint32_t> order_;
  std::vector<Slot> slots_;
  std::size_t mask_ = 0;
};

} // namespace

std::vector<Attribute> interpolate_attributes(const std::vector<double>& xyz, const std::vector<Attribute>& attributes,
                                              const std::vector<std::string>& names, const float* vertices,
                                              std::uint64_t vertex_count, double radius) {
  return interpolate_attributes(xyz.data(), xyz.size() / 3, attributes, names, vertices, vertex_count, radius);
}

namespace {

// Real: the vertex positions' scalar (float, or double for meshes made with
// double_positions).
template <class Real>
std::vector<Attribute> interpolate_at(const double* xyz, std::size_t n, const std::vector<Attribute>& attributes,
                                      const std::vector<std::string>& names, const Real* vertices,
                                      std::uint64_t vertex_count, double radius, int threads, const double* scale) {
  const std::string who = "attribute interpolation";
  if (!(radius > 0) || !std::isfinite(radius)) detail::fail_arg(who, "the radius must be positive and finite");
  if (n > 0 && !xyz) detail::fail_arg(who, "no particle positions");
  if (n == 0) detail::fail_arg(who, "there are no particles");
  if (n > std::numeric_limits<std::uint32_t>::max()) detail::fail_arg(who, "too many particles");
  if (vertex_count > 0 && !vertices) detail::fail_arg(who, "no vertex positions");
  std::vector<const Attribute*> chosen;
  if (names.empty()) {
    for (const Attribute& a : attributes) chosen.push_back(&a);
  } else {
    for (const std::string& nm : names) {
      const Attribute* a = find_attribute(attributes, nm);
      if (!a) detail::fail_arg(who, "no particle attribute '" + nm + "' (the file has: " + attribute_names(attributes) + ")");
      if (std::find(chosen.begin(), chosen.end(), a) == chosen.end()) chosen.push_back(a);
    }
  }
  std::size_t width = 0;
  std::vector<std::size_t> offset;
  for (const Attribute* a : chosen) {
    if (a->components != 1 && a->components != 3)
      detail::fail_arg(who, "attribute '" + a->name + "' has " + std::to_string(a->components) + " components");
    if (a->values.size() != n * static_cast<std::size_t>(a->components))
      detail::fail_arg(who, "attribute '" + a->name + "' has " + std::to_string(a->values.size()) + " values for " +
                                std::to_string(n) + " particles");
    offset.push_back(width);
    width += static_cast<std::size_t>(a->components);
  }
  // Extent / radius must fit the cell indices.
  double lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::numeric_limits<double>::infinity();
    hi[a] = -lo[a];
  }
  for (std::size_t p = 0; p < n; ++p)
    for (int a = 0; a < 3; ++a) {
      const double v = xyz[3 * p + static_cast<std::size_t>(a)];
      if (!std::isfinite(v)) detail::fail_arg(who, "particle " + std::to_string(p) + " is not finite");
      lo[a] = std::min(lo[a], v);
      hi[a] = std::max(hi[a], v);
    }
  for (int a = 0; a < 3; ++a)
    if ((hi[a] - lo[a]) / radius > 1e15) detail::fail_arg(who, "the radius is too small for the particle extent");

  std::vector<Attribute> out(chosen.size());
  for (std::size_t a = 0; a < chosen.size(); ++a) {
    out[a].name = chosen[a]->name;
    out[a].components = chosen[a]->components;
    out[a].values.assign(static_cast<std::size_t>(vertex_count) * static_cast<std::size_t>(chosen[a]->components), 0.0);
  }
  if (vertex_count == 0 || chosen.empty()) return out;

  const HashGrid grid(xyz, n, radius);
  const std::vector<std::uint32_t>& order = grid.order();
  const double r2 = radius * radius;
  const std::int64_t nvert = static_cast<std::int64_t>(vertex_count);
  // Beyond this many shells the nearest particle is found by a full scan.
  constexpr std::int64_t kMaxShells = 32;

#if defined(_OPENMP)
  if (threads <= 0) threads = omp_get_max_threads();
#endif
  (void)threads;
#pragma omp parallel num_threads(threads)
  {
    std::vector<double> acc(width);
#pragma omp for schedule(dynamic, 256)
    for (std::int64_t v = 0; v < nvert; ++v) {
      const double x[3] = {vertices[3 * v], vertices[3 * v + 1], vertices[3 * v + 2]};
      std::fill(acc.begin(), acc.end(), 0.0);
      double wsum = 0;
      const Cell c = grid.cell_of(x);
      for (std::int64_t dk = -1; dk <= 1; ++dk)
        for (std::int64_t dj = -1; dj <= 1; ++dj)
          for (std::int64_t di = -1; di <= 1; ++di) {
            std::uint32_t b, e;
            if (!grid.find(Cell{c.i + di, c.j + dj, c.k + dk}, b, e)) continue;
            for (std::uint32_t q = b; q < e; ++q) {
              const std::size_t p = order[q];
              const double d0 = x[0] - xyz[3 * p], d1 = x[1] - xyz[3 * p + 1], d2 = x[2] - xyz[3 * p + 2];
              const double s2 = (d0 * d0 + d1 * d1 + d2 * d2) / (scale ? r2 * (scale[p] * scale[p]) : r2);
              if (s2 >= 1.0) continue;
              const double t = 1.0 - s2;
              const double w = t * t * t;
              wsum += w;
              for (std::size_t a = 0; a < chosen.size(); ++a) {
                const std::size_t comps = static_cast<std::size_t>(chosen[a]->components);
                const double* src = chosen[a]->values.data() + p * comps;
                for (std::size_t k = 0; k < comps; ++k) acc[offset[a] + k] += w * src[k];
              }
            }
          }
      if (wsum > 0) {
        for (std::size_t a = 0; a < chosen.size(); ++a) {
          const std::size_t comps = static_cast<std::size_t>(chosen[a]->components);
          for (std::size_t k = 0; k < comps; ++k)
            out[a].values[static_cast<std::size_t>(v) * comps + k] = acc[offset[a] + k] / wsum;
        }
        continue;
      }
      // No particle within R: the nearest one (lowest index on ties).
      double best = std::numeric_limits<double>::infinity();
      std::size_t best_p = 0;
      const auto consider = [&](std::size_t p) {
        const double d0 = x[0] - xyz[3 * p], d1 = x[1] - xyz[3 * p + 1], d2 = x[2] - xyz[3 * p + 2];
        const double d = d0 * d0 + d1 * d1 + d2 * d2;
        if (d < best || (d == best && p < best_p)) {
          best = d;
          best_p = p;
        }
      };
      bool found = false;
      for (std::int64_t r = 0; r <= kMaxShells && !found; ++r) {
        for (std::int64_t dk = -r; dk <= r; ++dk)
          for (std::int64_t dj = -r; dj <= r; ++dj)
            for (std::int64_t di = -r; di <= r; ++di) {
              if (std::max({std::abs(di), std::abs(dj), std::abs(dk)}) != r) continue;
              std::uint32_t b, e;
              if (!grid.find(Cell{c.i + di, c.j + dj, c.k + dk}, b, e)) continue;
              for (std::uint32_t q = b; q < e; ++q) consider(order[q]);
            }
        // Particles in farther shells (r + 1 and more) are at least r * R away.
        const double reach = static_cast<double>(r) * radius;
        if (best <= reach * reach) found = true;
      }
      if (!found)
        for (std::size_t p = 0; p < n; ++p) consider(p);
      for (std::size_t a = 0; a < chosen.size(); ++a) {
        const std::size_t comps = static_cast<std::size_t>(chosen[a]->components);
        for (std::size_t k = 0; k < comps; ++k)
          out[a].values[static_cast<std::size_t>(v) * comps + k] = chosen[a]->values[best_p * comps + k];
      }
    }
  }
  return out;
}

}  // namespace

std::vector<Attribute> interpolate_attributes(const double* xyz, std::size_t n, const std::vector<Attribute>& attributes,
                                              const std::vector<std::string>& names, const float* vertices,
                                              std::uint64_t vertex_count, double radius, int threads,
                                              const double* scale) {
  return interpolate_at(xyz, n, attributes, names, vertices, vertex_count, radius, threads, scale);
}

std::vector<Attribute> interpolate_attributes(const double* xyz, std::size_t n, const std::vector<Attribute>& attributes,
                                              const std::vector<std::string>& names, const double* vertices,
                                              std::uint64_t vertex_count, double radius, int threads,
                                              const double* scale) {
  return interpolate_at(xyz, n, attributes, names, vertices, vertex_count, radius, threads, scale);
}

} // namespace nbmc::io
