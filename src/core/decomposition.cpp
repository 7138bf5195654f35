// SPDX-License-Identifier: MIT
#include "decomposition.hpp"

#include "parallel.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace nbmc {

void particle_bounds(const double* xyz, std::size_t count, double lo[3], double hi[3]) {
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::numeric_limits<double>::max();
    hi[a] = -std::numeric_limits<double>::max();
  }
  for (std::size_t i = 0; i < count; ++i)
    for (int a = 0; a < 3; ++a) {
      const double x = xyz[3 * i + a];
      lo[a] = x < lo[a] ? x : lo[a];
      hi[a] = x > hi[a] ? x : hi[a];
    }
}

Grid frame_grid(const double lo[3], const double hi[3], const Params& p) {
  if (p.use_bbox) return make_grid(p.bbox_min, p.bbox_max, p);
  return make_grid(lo, hi, p);
}

std::int64_t split_point(std::int64_t n, int k, int i) {
  return std::int64_t((__int128)n * i / k);
}

void ghost_box(const Grid& g, const Params& p, const std::int64_t vert_lo[3], const std::int64_t vert_hi[3],
               std::int64_t nb_lo[3], std::int64_t nb_hi[3]) {
  const double c = g.cell, S = g.nb_cell;
  // Neighbour cells the surface test of a particle reads around its own.
  const std::int64_t range = std::int64_t(std::ceil(p.surface_radius / S));
  for (int a = 0; a < 3; ++a) {
    const double x0 = double(vert_lo[a]) * c, x1 = double(vert_hi[a]) * c;
    // Surface particles whose band box reaches the vertex box (one cell more
    // for the rounding of the box to vertices), and the cells their surface
    // test reads.
    const std::int64_t band_lo = std::int64_t(std::floor((x0 - p.band_width - c) / S)) - range;
    const std::int64_t band_hi = std::int64_t(std::floor((x1 + p.band_width + c) / S)) + range;
    // Particles within R of a vertex of the box (2R for the SPH density:
    // the particles within R of those, for their densities).
    const double reach = particle_reach(p);
    const std::int64_t field_lo = std::int64_t(std::floor((x0 - reach - c) / S));
    const std::int64_t field_hi = std::int64_t(std::floor((x1 + reach + c) / S));
    // One more cell against rounding between these doubles and the floats of
    // the kernels.
    nb_lo[a] = std::max<std::int64_t>(0, std::min(band_lo, field_lo) - 1);
    nb_hi[a] = std::min<std::int64_t>(g.nb_dims[a] - 1, std::max(band_hi, field_hi) + 1);
  }
}

Decomposition decompose(const Grid& g, const Params& p, const int parts_in[3]) {
  Decomposition d;
  d.grid = g;
  std::int64_t cells[3];
  for (int a = 0; a < 3; ++a) {
    cells[a] = std::max<std::int64_t>(1, g.dims[a] - 1);
    d.parts[a] = int(std::max<std::int64_t>(1, std::min<std::int64_t>(parts_in[a], cells[a])));
  }
  d.subdomains.reserve(std::size_t(d.parts[0]) * d.parts[1] * d.parts[2]);
  for (int z = 0; z < d.parts[2]; ++z)
    for (int y = 0; y < d.parts[1]; ++y)
      for (int x = 0; x < d.parts[0]; ++x) {
        Subdomain s;
        s.index = int(d.subdomains.size());
        const int c[3] = {x, y, z};
        for (int a = 0; a < 3; ++a) {
          s.coord[a] = c[a];
          s.cell_lo[a] = split_point(cells[a], d.parts[a], c[a]);
          s.cell_hi[a] = split_point(cells[a], d.parts[a], c[a] + 1);
          s.vert_lo[a] = std::max<std::int64_t>(0, s.cell_lo[a] - 1);
          s.vert_hi[a] = std::min<std::int64_t>(g.dims[a] - 1, s.cell_hi[a] + 1);
        }
        ghost_box(g, p, s.vert_lo, s.vert_hi, s.nb_lo, s.nb_hi);
        for (int a = 0; a < 3; ++a) {
          const double S = g.nb_cell, cc = g.cell;
          const std::int64_t own_lo = std::int64_t(std::floor(double(s.cell_lo[a]) * cc / S));
          const std::int64_t own_hi = std::int64_t(std::floor(double(s.cell_hi[a]) * cc / S));
          d.ghost_nb_cells = std::max(d.ghost_nb_cells, std::max(own_lo - s.nb_lo[a], s.nb_hi[a] - own_hi));
        }
        d.subdomains.push_back(s);
      }
  return d;
}

std::vector<std::vector<std::uint32_t>> select_particles(const Decomposition& d, const Params& p, const double* xyz,
                                                         std::size_t count) {
  const Grid& g = d.grid;
  // Per axis and neighbour cell: the range of subdomain coordinates whose
  // ghost box contains it (boxes are monotone along an axis, so a range).
  std::vector<int> first[3], last[3];
  for (int a = 0; a < 3; ++a) {
    first[a].assign(std::size_t(g.nb_dims[a]), std::numeric_limits<int>::max());
    last[a].assign(std::size_t(g.nb_dims[a]), -1);
  }
  for (const Subdomain& s : d.subdomains)
    for (int a = 0; a < 3; ++a)
      for (std::int64_t c = s.nb_lo[a]; c <= s.nb_hi[a]; ++c) {
        first[a][std::size_t(c)] = std::min(first[a][std::size_t(c)], s.coord[a]);
        last[a][std::size_t(c)] = std::max(last[a][std::size_t(c)], s.coord[a]);
      }
  std::vector<std::vector<std::uint32_t>> out(d.subdomains.size());
  const double inv = 1.0 / g.nb_cell;
  double lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = p.bbox_min[a] - particle_reach(p);
    hi[a] = p.bbox_max[a] + particle_reach(p);
  }
  const int px = d.parts[0], py = d.parts[1];
  // Contiguous chunks of the particles on the host's threads, each into its
  // own lists, joined in chunk order (so every list stays in input order).
  const std::size_t chunks = chunk_count(count, 20000);
  std::vector<std::vector<std::vector<std::uint32_t>>> part(chunks, std::vector<std::vector<std::uint32_t>>(out.size()));
  for_chunks(count, chunks, [&](std::size_t k, std::size_t begin, std::size_t end) {
    auto& mine = part[k];
    for (std::size_t i = begin; i < end; ++i) {
      const double* x = xyz + 3 * i;
      if (p.use_bbox && !(x[0] >= lo[0] && x[0] <= hi[0] && x[1] >= lo[1] && x[1] <= hi[1] && x[2] >= lo[2] &&
                          x[2] <= hi[2]))
        continue;
      std::uint32_t c[3];
      for (int a = 0; a < 3; ++a) c[a] = neighbour_cell(x[a] - g.origin[a], inv, g.nb_dims[a]);
      for (int z = first[2][c[2]]; z <= last[2][c[2]]; ++z)
        for (int y = first[1][c[1]]; y <= last[1][c[1]]; ++y)
          for (int xx = first[0][c[0]]; xx <= last[0][c[0]]; ++xx)
            mine[std::size_t((z * py + y) * px + xx)].push_back(std::uint32_t(i));
    }
  });
  for (std::size_t s = 0; s < out.size(); ++s) {
    std::size_t n = 0;
    for (const auto& c : part) n += c[s].size();
    out[s].reserve(n);
    for (auto& c : part) {
      out[s].insert(out[s].end(), c[s].begin(), c[s].end());
      std::vector<std::uint32_t>().swap(c[s]);
    }
  }
  return out;
}

void subdomains_near_cell(const Decomposition& d, std::int64_t i, std::int64_t j, std::int64_t k, int margin,
                          std::vector<int>& out) {
  const std::int64_t c[3] = {i, j, k};
  for (const Subdomain& s : d.subdomains) {
    bool in = true;
    for (int a = 0; a < 3 && in; ++a) in = c[a] >= s.cell_lo[a] - margin && c[a] < s.cell_hi[a] + margin;
    if (in) out.push_back(s.index);
  }
}

std::uint64_t estimate_bytes(const Params& p, std::uint64_t particles) {
  // Measured peaks per particle (bench/RESULTS.md, "Scale-out"): 41, 148 and
  // 910 bytes at cells r, r/2 and r/4 on the 292 k frame (CPU), 137-138 at
  // r/2 on the 1.65 M and 13.2 M frames (GPU): about 26 + 15 (r/c)^3 (the band
  // is 2r thick, so its vertices grow with the cube of r/c). 10% margin, plus
  // fixed overhead; a subdomain over the budget anyway makes `auto` split
  // further.
  const double ratio = p.spacing / p.cell_size;
  const double per_particle = 1.1 * (30.0 + 16.0 * ratio * ratio * ratio);
  return std::uint64_t(per_particle * double(particles)) + (std::uint64_t(64) << 20);
}

void choose_parts(const Grid& g, std::uint64_t pieces, int parts[3]) {
  // Split the longest axis (in cells) until there are enough pieces.
  double len[3];
  for (int a = 0; a < 3; ++a) {
    parts[a] = 1;
    len[a] = double(std::max<std::int64_t>(1, g.dims[a] - 1));
  }
  while (std::uint64_t(parts[0]) * parts[1] * parts[2] < pieces) {
    int a = 0;
    for (int b = 1; b < 3; ++b)
      if (len[b] / parts[b] > len[a] / parts[a]) a = b;
    if (len[a] / parts[a] < 16) break;  // subdomains thinner than 16 cells: ghosts would dominate
    ++parts[a];
  }
}

}  // namespace nbmc
