// SPDX-License-Identifier: MIT
// Parallel k-way merge: the key space is cut at splitter keys sampled from
// the pieces, so that every thread merges its own key range of all pieces
// (equal keys never straddle two ranges); a prefix sum over the ranges'
// counts then places each range's output.
#include "stitch.hpp"

#include "parallel.hpp"
#include "params.hpp"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <queue>
#include <sstream>
#include <utility>

namespace nbmc {

namespace {

struct Cursor {
  std::uint64_t key;
  std::uint8_t axis;
  std::uint32_t piece;
  bool operator>(const Cursor& o) const {
    if (key != o.key) return key > o.key;
    if (axis != o.axis) return axis > o.axis;
    return piece > o.piece;
  }
};

// Splitter keys cutting the union of sorted key arrays into about n ranges.
template <class GetKeys>
std::vector<std::uint64_t> splitters(std::size_t pieces, int n, const GetKeys& keys) {
  std::vector<std::uint64_t> sample;
  for (std::size_t q = 0; q < pieces; ++q) {
    const auto& k = keys(q);
    const std::size_t step = std::max<std::size_t>(1, k.size() / (std::size_t(n) * 16));
    for (std::size_t i = 0; i < k.size(); i += step) sample.push_back(k[i]);
  }
  std::sort(sample.begin(), sample.end());
  std::vector<std::uint64_t> s;
  for (int t = 1; t < n; ++t)
    if (!sample.empty()) s.push_back(sample[sample.size() * std::size_t(t) / std::size_t(n)]);
  s.erase(std::unique(s.begin(), s.end()), s.end());
  return s;
}

}  // namespace

StitchResult stitch(const std::vector<const Piece*>& pieces,
                    const std::function<StitchTarget(std::uint64_t, std::uint64_t)>& out) {
  const std::size_t k = pieces.size();
  bool normals = false, f64 = false;
  std::uint64_t vtotal = 0, ttotal = 0;
  for (const Piece* p : pieces) {
    normals = normals || !p->normals.empty();
    f64 = f64 || !p->positions64.empty();
    vtotal += p->vertex_count();
    ttotal += p->triangle_count();
  }
  int n = int(chunk_count(std::size_t(vtotal), 200000));
  // NBMC_STITCH_RANGES=n (tests): that many key ranges whatever the size.
  if (const char* e = std::getenv("NBMC_STITCH_RANGES")) n = std::max(1, std::min(256, std::atoi(e)));

  // Ranges: for thread t and piece q, [first[t][q], first[t+1][q]).
  auto ranges = [&](const std::vector<std::uint64_t>& cut, auto keys_of) {
    std::vector<std::vector<std::size_t>> first(cut.size() + 2, std::vector<std::size_t>(k, 0));
    for (std::size_t q = 0; q < k; ++q) {
      const auto& keys = keys_of(q);
      for (std::size_t t = 0; t < cut.size(); ++t)
        first[t + 1][q] = std::size_t(std::lower_bound(keys.begin(), keys.end(), cut[t]) - keys.begin());
      first[cut.size() + 1][q] = keys.size();
    }
    return first;
  };

  // ---- vertices: merge each range, dropping repeats of shared vertices.
  const auto vkeys = [&](std::size_t q) -> const auto& { return pieces[q]->vertex_keys; };
  const std::vector<std::uint64_t> vcut = splitters(k, n, vkeys);
  const auto vfirst = ranges(vcut, vkeys);
  const int nv_ranges = int(vcut.size()) + 1;
  std::vector<std::vector<std::uint32_t>> remap(k);
  for (std::size_t q = 0; q < k; ++q) remap[q].resize(pieces[q]->vertex_count());
  // Per range: the (piece, index) of each kept vertex, and its shared count.
  std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> kept(static_cast<std::size_t>(nv_ranges));
  std::vector<std::uint64_t> shared(static_cast<std::size_t>(nv_ranges), 0);
  on_threads(std::size_t(nv_ranges), [&](std::size_t ti) {
    const int t = int(ti);
    std::vector<std::size_t> next(vfirst[std::size_t(t)]);
    const std::vector<std::size_t>& end = vfirst[std::size_t(t) + 1];
    std::priority_queue<Cursor, std::vector<Cursor>, std::greater<Cursor>> heap;
    for (std::size_t q = 0; q < k; ++q)
      if (next[q] < end[q]) heap.push({pieces[q]->vertex_keys[next[q]], pieces[q]->vertex_axes[next[q]], std::uint32_t(q)});
    auto& src = kept[std::size_t(t)];
    bool have_last = false;
    std::uint64_t last_key = 0;
    std::uint8_t last_axis = 0;
    while (!heap.empty()) {
      const Cursor c = heap.top();
      heap.pop();
      const Piece& p = *pieces[c.piece];
      const std::size_t v = next[c.piece]++;
      if (have_last && c.key == last_key && c.axis == last_axis) {
        // The same edge vertex from another piece: bitwise the same, or a bug.
        const auto [sp, sv] = src.back();
        const Piece& s = *pieces[sp];
        const bool same =
            (f64 ? std::memcmp(&s.positions64[3 * std::size_t(sv)], &p.positions64[3 * v], 3 * sizeof(double)) == 0
                 : std::memcmp(&s.positions[3 * std::size_t(sv)], &p.positions[3 * v], 3 * sizeof(float)) == 0) &&
            (!normals || std::memcmp(&s.normals[3 * std::size_t(sv)], &p.normals[3 * v], 3 * sizeof(float)) == 0);
        if (!same) {
          std::ostringstream m;
          m << "stitching: the vertex on grid edge " << c.key << "/" << int(c.axis)
            << " differs between subdomains " << sp << " and " << c.piece << " (their fields disagree)";
          throw Error(NBMC_ERROR_INTERNAL, m.str());
        }
        remap[c.piece][v] = std::uint32_t(src.size() - 1);  // local for now
        ++shared[std::size_t(t)];
      } else {
        remap[c.piece][v] = std::uint32_t(src.size());
        src.emplace_back(c.piece, std::uint32_t(v));
        last_key = c.key;
        last_axis = c.axis;
        have_last = true;
      }
      if (next[c.piece] < end[c.piece])
        heap.push({p.vertex_keys[next[c.piece]], p.vertex_axes[next[c.piece]], c.piece});
    }
  });
  std::vector<std::uint64_t> voff(static_cast<std::size_t>(nv_ranges) + 1, 0);
  StitchResult r;
  for (int t = 0; t < nv_ranges; ++t) {
    voff[std::size_t(t) + 1] = voff[std::size_t(t)] + kept[std::size_t(t)].size();
    r.shared_vertices += shared[std::size_t(t)];
  }
  r.vertices = voff.back();
  r.triangles = ttotal;
  if (r.vertices > std::numeric_limits<std::uint32_t>::max())
    throw Error(NBMC_ERROR_DOMAIN_TOO_LARGE, "the stitched mesh has more vertices than 32-bit indices can address");
  const StitchTarget tg = out(r.vertices, r.triangles);
  if (r.vertices && (f64 ? !tg.positions64 : !tg.positions))
    throw Error(NBMC_ERROR_INTERNAL, "stitching: no target for the pieces' positions");
  // Final indices and the vertex arrays, range by range.
  on_threads(std::size_t(nv_ranges), [&](std::size_t ti) {
    const int t = int(ti);
    const std::uint64_t base = voff[std::size_t(t)];
    for (std::size_t q = 0; q < k; ++q)
      for (std::size_t v = vfirst[std::size_t(t)][q]; v < vfirst[std::size_t(t) + 1][q]; ++v)
        remap[q][v] += std::uint32_t(base);
    const auto& src = kept[std::size_t(t)];
    for (std::size_t i = 0; i < src.size(); ++i) {
      const Piece& p = *pieces[src[i].first];
      const std::size_t s = src[i].second, v = std::size_t(base) + i;
      if (f64) std::memcpy(tg.positions64 + 3 * v, &p.positions64[3 * s], 3 * sizeof(double));
      else std::memcpy(tg.positions + 3 * v, &p.positions[3 * s], 3 * sizeof(float));
      if (normals && tg.normals) std::memcpy(tg.normals + 3 * v, &p.normals[3 * s], 3 * sizeof(float));
      if (tg.vertex_keys) tg.vertex_keys[v] = p.vertex_keys[s];
      if (tg.vertex_axes) tg.vertex_axes[v] = p.vertex_axes[s];
    }
  });

  // ---- triangles: each cell belongs to one piece; merge by cell key.
  const auto tkeys = [&](std::size_t q) -> const auto& { return pieces[q]->triangle_cells; };
  const std::vector<std::uint64_t> tcut = splitters(k, n, tkeys);
  const auto tfirst = ranges(tcut, tkeys);
  const int nt_ranges = int(tcut.size()) + 1;
  std::vector<std::uint64_t> toff(static_cast<std::size_t>(nt_ranges) + 1, 0);
  for (int t = 0; t < nt_ranges; ++t) {
    std::uint64_t c = 0;
    for (std::size_t q = 0; q < k; ++q) c += tfirst[std::size_t(t) + 1][q] - tfirst[std::size_t(t)][q];
    toff[std::size_t(t) + 1] = toff[std::size_t(t)] + c;
  }
  struct TCursor {
    std::uint64_t key;
    std::uint32_t piece;
    bool operator>(const TCursor& o) const { return key != o.key ? key > o.key : piece > o.piece; }
  };
  on_threads(std::size_t(nt_ranges), [&](std::size_t ti) {
    const int t = int(ti);
    std::vector<std::size_t> next(tfirst[std::size_t(t)]);
    const std::vector<std::size_t>& end = tfirst[std::size_t(t) + 1];
    std::priority_queue<TCursor, std::vector<TCursor>, std::greater<TCursor>> heap;
    for (std::size_t q = 0; q < k; ++q)
      if (next[q] < end[q]) heap.push({pieces[q]->triangle_cells[next[q]], std::uint32_t(q)});
    std::size_t at = std::size_t(toff[std::size_t(t)]);
    while (!heap.empty()) {
      const TCursor c = heap.top();
      heap.pop();
      const Piece& p = *pieces[c.piece];
      std::size_t& i = next[c.piece];
      do {  // the whole run of this cell's triangles
        for (int e = 0; e < 3; ++e) tg.triangles[3 * at + std::size_t(e)] = remap[c.piece][p.triangles[3 * i + std::size_t(e)]];
        if (tg.triangle_cells) tg.triangle_cells[at] = c.key;
        ++at;
        ++i;
      } while (i < end[c.piece] && p.triangle_cells[i] == c.key);
      if (i < end[c.piece]) heap.push({p.triangle_cells[i], c.piece});
    }
  });
  return r;
}

}  // namespace nbmc
