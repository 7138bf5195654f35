// SPDX-License-Identifier: MIT
#include "stitch.hpp"

#include "params.hpp"

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

}  // namespace

StitchResult stitch(const std::vector<const Piece*>& pieces,
                    const std::function<StitchTarget(std::uint64_t, std::uint64_t)>& out) {
  const std::size_t k = pieces.size();
  bool normals = false;
  for (const Piece* p : pieces) normals = normals || !p->normals.empty();
  // Pass 1: merge the vertices, giving every piece vertex its final index.
  std::vector<std::vector<std::uint32_t>> remap(k);
  std::uint64_t tri_total = 0;
  for (std::size_t q = 0; q < k; ++q) {
    remap[q].resize(pieces[q]->vertex_count());
    tri_total += pieces[q]->triangle_count();
  }
  std::vector<std::size_t> next(k, 0);
  std::priority_queue<Cursor, std::vector<Cursor>, std::greater<Cursor>> heap;
  for (std::size_t q = 0; q < k; ++q)
    if (pieces[q]->vertex_count())
      heap.push({pieces[q]->vertex_keys[0], pieces[q]->vertex_axes[0], std::uint32_t(q)});
  // (piece, local index) of each final vertex, in order.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> source;
  StitchResult r;
  std::uint64_t last_key = 0;
  std::uint8_t last_axis = 0;
  bool have_last = false;
  while (!heap.empty()) {
    const Cursor c = heap.top();
    heap.pop();
    const Piece& p = *pieces[c.piece];
    const std::size_t v = next[c.piece]++;
    if (have_last && c.key == last_key && c.axis == last_axis) {
      // The same edge vertex from another piece: bitwise the same, or a bug.
      const auto& [sp, sv] = source.back();
      const Piece& s = *pieces[sp];
      const bool same =
          std::memcmp(&s.positions[3 * std::size_t(sv)], &p.positions[3 * v], 3 * sizeof(float)) == 0 &&
          (!normals || std::memcmp(&s.normals[3 * std::size_t(sv)], &p.normals[3 * v], 3 * sizeof(float)) == 0);
      if (!same) {
        std::ostringstream m;
        m << "stitching: the vertex on grid edge " << c.key << "/" << int(c.axis) << " differs between subdomains "
          << sp << " and " << c.piece << " (their fields disagree)";
        throw Error(NBMC_ERROR_INTERNAL, m.str());
      }
      remap[c.piece][v] = std::uint32_t(source.size() - 1);
      ++r.shared_vertices;
    } else {
      if (source.size() >= std::numeric_limits<std::uint32_t>::max())
        throw Error(NBMC_ERROR_DOMAIN_TOO_LARGE, "the stitched mesh has more vertices than 32-bit indices can address");
      remap[c.piece][v] = std::uint32_t(source.size());
      source.emplace_back(c.piece, std::uint32_t(v));
      last_key = c.key;
      last_axis = c.axis;
      have_last = true;
    }
    if (next[c.piece] < p.vertex_count())
      heap.push({p.vertex_keys[next[c.piece]], p.vertex_axes[next[c.piece]], c.piece});
  }
  r.vertices = source.size();
  r.triangles = tri_total;
  const StitchTarget t = out(r.vertices, r.triangles);
  for (std::size_t v = 0; v < source.size(); ++v) {
    const Piece& p = *pieces[source[v].first];
    const std::size_t s = source[v].second;
    std::memcpy(t.positions + 3 * v, &p.positions[3 * s], 3 * sizeof(float));
    if (normals && t.normals) std::memcpy(t.normals + 3 * v, &p.normals[3 * s], 3 * sizeof(float));
    if (t.vertex_keys) t.vertex_keys[v] = p.vertex_keys[s];
    if (t.vertex_axes) t.vertex_axes[v] = p.vertex_axes[s];
  }
  // Pass 2: merge the triangles by cell (each cell belongs to one piece).
  std::fill(next.begin(), next.end(), 0);
  struct TCursor {
    std::uint64_t key;
    std::uint32_t piece;
    bool operator>(const TCursor& o) const { return key != o.key ? key > o.key : piece > o.piece; }
  };
  std::priority_queue<TCursor, std::vector<TCursor>, std::greater<TCursor>> th;
  for (std::size_t q = 0; q < k; ++q)
    if (pieces[q]->triangle_count()) th.push({pieces[q]->triangle_cells[0], std::uint32_t(q)});
  std::size_t at = 0;
  while (!th.empty()) {
    const TCursor c = th.top();
    th.pop();
    const Piece& p = *pieces[c.piece];
    std::size_t& i = next[c.piece];
    // The whole run of this cell's triangles.
    do {
      for (int e = 0; e < 3; ++e) t.triangles[3 * at + e] = remap[c.piece][p.triangles[3 * i + e]];
      if (t.triangle_cells) t.triangle_cells[at] = c.key;
      ++at;
      ++i;
    } while (i < p.triangle_count() && p.triangle_cells[i] == c.key);
    if (i < p.triangle_count()) th.push({p.triangle_cells[i], c.piece});
  }
  return r;
}

}  // namespace nbmc
