// SPDX-License-Identifier: MIT
// One frame over several processes (MPI ranks), through the collective
// operations of src/collective.h: libnbmc stays MPI-free. The same code as
// the in-process subdomains (src/subdomains.cpp) runs on every rank; what is
// added here is who runs which subdomain, moving particles and band cells
// between the ranks, the ranks' errors agreed on, and the output (the whole
// mesh stitched on one rank, or a piece per rank with global vertex ids).
//
// Every rank runs the same sequence of collective calls. A local failure is
// never thrown straight away: it is carried to the next agreement point
// (agree()), where all ranks learn the lowest failing rank's status and
// message and throw it together, so no rank is left waiting in a collective.
#include "collective.h"

#include "backends.hpp"
#include "capi_attributes.hpp"
#include "capi_mesh.hpp"
#include "context.hpp"
#include "subdomains.hpp"
#include "core/parallel.hpp"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <numeric>
#include <string>
#include <type_traits>
#include <unordered_map>
#include <vector>

namespace nbmc {
namespace {

struct Coll {
  const nbmc__collective& c;
  int rank() const { return c.rank; }
  int size() const { return c.size; }
  static void check(int32_t rc, const char* what) {
    if (rc != 0)
      throw Error(NBMC_ERROR_INTERNAL, std::string("MPI communication failed in ") + what + " (code " +
                                           std::to_string(rc) + ")");
  }
  void reduce(std::uint64_t* v, int n, int op) const { check(c.allreduce(c.user, v, n, op), "an allreduce"); }
  void reduce(double* v, int n, int op) const { check(c.allreduce(c.user, v, n, op), "an allreduce"); }
  // Byte blocks to every rank; returns what every rank sent here.
  std::vector<std::vector<char>> alltoall(const std::vector<std::vector<char>>& out) const {
    std::vector<std::uint64_t> sb(static_cast<std::size_t>(size())), rb(static_cast<std::size_t>(size()));
    std::vector<char> flat;
    for (int r = 0; r < size(); ++r) {
      sb[std::size_t(r)] = out[std::size_t(r)].size();
      flat.insert(flat.end(), out[std::size_t(r)].begin(), out[std::size_t(r)].end());
    }
    void* recv = nullptr;
    check(c.alltoallv(c.user, flat.data(), sb.data(), &recv, rb.data()), "an all-to-all exchange");
    std::unique_ptr<char, decltype(&std::free)> hold(static_cast<char*>(recv), &std::free);
    std::vector<std::vector<char>> in(static_cast<std::size_t>(size()));
    std::size_t at = 0;
    for (int r = 0; r < size(); ++r) {
      in[std::size_t(r)].assign(hold.get() + at, hold.get() + at + rb[std::size_t(r)]);
      at += rb[std::size_t(r)];
    }
    return in;
  }
  std::vector<std::vector<char>> gather(const std::vector<char>& mine, int root) const {
    std::vector<std::uint64_t> rb(static_cast<std::size_t>(size()));
    void* recv = nullptr;
    check(c.gatherv(c.user, mine.data(), mine.size(), root, &recv, rb.data()), "a gather");
    std::unique_ptr<char, decltype(&std::free)> hold(static_cast<char*>(recv), &std::free);
    std::vector<std::vector<char>> in;
    if (rank() != root) return in;
    in.resize(static_cast<std::size_t>(size()));
    std::size_t at = 0;
    for (int r = 0; r < size(); ++r) {
      in[std::size_t(r)].assign(hold.get() + at, hold.get() + at + rb[std::size_t(r)]);
      at += rb[std::size_t(r)];
    }
    return in;
  }
  std::string bcast(const std::string& s, int root) const {
    void* data = rank() == root ? const_cast<char*>(s.data()) : nullptr;
    std::uint64_t bytes = s.size();
    check(c.bcast(c.user, &data, &bytes, root), "a broadcast");
    if (rank() == root) return s;
    std::unique_ptr<char, decltype(&std::free)> hold(static_cast<char*>(data), &std::free);
    return std::string(hold.get(), std::size_t(bytes));
  }
};

// Status and message of an exception, as the C API maps them.
void describe(std::exception_ptr e, int32_t& status, std::string& msg) {
  try {
    std::rethrow_exception(e);
  } catch (const Error& x) {
    status = x.status;
    msg = x.what();
  } catch (const std::bad_alloc&) {
    status = NBMC_ERROR_OUT_OF_MEMORY;
    msg = "out of memory";
  } catch (const std::exception& x) {
    status = NBMC_ERROR_INTERNAL;
    msg = std::string("internal error: ") + x.what();
  } catch (...) {
    status = NBMC_ERROR_INTERNAL;
    msg = "internal error: unknown exception";
  }
}

// The agreement point: the lowest failing rank's error, thrown on all ranks.
void agree(const Coll& c, std::exception_ptr local) {
  std::uint64_t first = local ? std::uint64_t(c.rank()) : std::numeric_limits<std::uint64_t>::max();
  c.reduce(&first, 1, NBMC__MIN_U64);
  if (first == std::numeric_limits<std::uint64_t>::max()) return;
  std::string payload;
  if (std::uint64_t(c.rank()) == first) {
    int32_t status = 0;
    std::string msg;
    describe(local, status, msg);
    payload.assign(reinterpret_cast<const char*>(&status), sizeof status);
    payload += msg;
  }
  payload = c.bcast(payload, int(first));
  int32_t status = NBMC_ERROR_INTERNAL;
  if (payload.size() >= sizeof status) std::memcpy(&status, payload.data(), sizeof status);
  const std::string msg = payload.size() >= sizeof status ? payload.substr(sizeof status) : std::string();
  if (msg.rfind("rank ", 0) == 0) throw Error(status, msg);  // already named (an inner agreement)
  throw Error(status, "rank " + std::to_string(first) + " of " + std::to_string(c.size()) + ": " + msg);
}

template <class F>
void step(const Coll& c, F&& f) {
  std::exception_ptr e;
  try {
    f();
  } catch (...) {
    e = std::current_exception();
  }
  agree(c, e);
}

// ------------------------------------------------------------ byte packing
template <class T>
void put(std::vector<char>& b, const T& v) {
  static_assert(std::is_trivially_copyable<T>::value, "POD only");
  const char* p = reinterpret_cast<const char*>(&v);
  b.insert(b.end(), p, p + sizeof(T));
}
template <class V>
void put_array(std::vector<char>& b, const V& v) {
  put(b, std::uint64_t(v.size()));
  const char* p = reinterpret_cast<const char*>(v.data());
  b.insert(b.end(), p, p + v.size() * sizeof(typename V::value_type));
}
struct Reader {
  const std::vector<char>& b;
  std::size_t at = 0;
  template <class T>
  T get() {
    if (at + sizeof(T) > b.size()) throw Error(NBMC_ERROR_INTERNAL, "MPI: a message was shorter than announced");
    T v;
    std::memcpy(&v, b.data() + at, sizeof(T));
    at += sizeof(T);
    return v;
  }
  template <class V>
  void get_array(V& v) {
    const std::uint64_t n = get<std::uint64_t>();
    const std::size_t bytes = std::size_t(n) * sizeof(typename V::value_type);
    if (at + bytes > b.size()) throw Error(NBMC_ERROR_INTERNAL, "MPI: a message was shorter than announced");
    v.resize(std::size_t(n));
    if (bytes) std::memcpy(v.data(), b.data() + at, bytes);
    at += bytes;
  }
  bool done() const { return at >= b.size(); }
};

void pack_piece(std::vector<char>& b, const Piece& p) {
  put_array(b, p.positions);
  put_array(b, p.positions64);
  put_array(b, p.normals);
  put_array(b, p.triangles);
  put_array(b, p.vertex_keys);
  put_array(b, p.vertex_axes);
  put_array(b, p.triangle_cells);
}
Piece unpack_piece(Reader& r) {
  Piece p;
  r.get_array(p.positions);
  r.get_array(p.positions64);
  r.get_array(p.normals);
  r.get_array(p.triangles);
  r.get_array(p.vertex_keys);
  r.get_array(p.vertex_axes);
  r.get_array(p.triangle_cells);
  return p;
}

// Subdomains to ranks: largest first, each to the least loaded rank (the
// same on every rank: the loads are global sums).
std::vector<int> assign(const std::vector<std::uint64_t>& load, int ranks) {
  std::vector<int> order(load.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return load[std::size_t(a)] > load[std::size_t(b)]; });
  std::vector<std::uint64_t> total(std::size_t(ranks), 0);
  std::vector<int> owner(load.size(), 0);
  for (int s : order) {
    const int r = int(std::min_element(total.begin(), total.end()) - total.begin());
    owner[std::size_t(s)] = r;
    total[std::size_t(r)] += load[std::size_t(s)] + 1;  // +1: empty subdomains spread too
  }
  return owner;
}

// Global vertex ids of a rank's piece: a vertex belongs to the lowest rank
// that has it; owners number their vertices after the lower ranks' counts,
// then tell the other ranks that have a vertex its id.
void global_ids(const Coll& c, const Decomposition& d, const std::vector<int>& owner, const Piece& piece,
                std::vector<std::uint64_t>& ids, std::uint64_t& total) {
  const int me = c.rank(), P = c.size();
  // A vertex is on an edge whose endpoints are grid vertices; it can be shared
  // with another rank only if an endpoint lies on the boundary of one of my
  // subdomains next to a subdomain of another rank.
  const std::size_t nv = piece.vertex_count();
  std::vector<std::vector<char>> out(static_cast<std::size_t>(P));
  std::vector<std::vector<std::uint32_t>> sent(static_cast<std::size_t>(P));  // my vertex indices sent to each rank
  auto decode = [](std::uint64_t key, std::int64_t v[3]) {
    const std::uint64_t block = key >> 9;
    const int word = int((key >> 6) & 7), bit = int(key & 63);
    v[0] = std::int64_t(compact3(block)) * 8 + (word & 1) * 4 + (bit & 3);
    v[1] = std::int64_t(compact3(block >> 1)) * 8 + ((word >> 1) & 1) * 4 + ((bit >> 2) & 3);
    v[2] = std::int64_t(compact3(block >> 2)) * 8 + ((word >> 2) & 1) * 4 + (bit >> 4);
  };
  std::vector<char> flag(static_cast<std::size_t>(P));
  for (std::size_t v = 0; v < nv; ++v) {
    std::int64_t g[3];
    decode(piece.vertex_keys[v], g);
    const int ax = piece.vertex_axes[v];
    std::fill(flag.begin(), flag.end(), 0);
    for (const Subdomain& other : d.subdomains) {
      const int r = owner[std::size_t(other.index)];
      if (r == me || flag[std::size_t(r)]) continue;
      // The edge (g, g + e_ax) touches the other subdomain's cells' corners.
      bool in = true;
      for (int k = 0; k < 3 && in; ++k) {
        const std::int64_t lo = g[k], hi = g[k] + (k == ax ? 1 : 0);
        in = hi >= other.cell_lo[k] && lo <= other.cell_hi[k];
      }
      if (in) flag[std::size_t(r)] = 1;
    }
    for (int r = 0; r < P; ++r)
      if (flag[std::size_t(r)]) {
        put(out[std::size_t(r)], piece.vertex_keys[v]);
        put(out[std::size_t(r)], std::uint64_t(ax));
        sent[std::size_t(r)].push_back(std::uint32_t(v));
      }
  }
  const std::vector<std::vector<char>> in = c.alltoall(out);
  // Which of my vertices a lower rank also has; lookup of my vertices by key.
  std::unordered_map<std::uint64_t, std::uint32_t> index;  // (key << 2 | axis) -> my vertex
  index.reserve(std::size_t(nv / 8 + 16));
  for (int r = 0; r < P; ++r)
    for (std::uint32_t v : sent[std::size_t(r)]) index[(piece.vertex_keys[v] << 2) | piece.vertex_axes[v]] = v;
  std::vector<char> foreign(nv, 0);  // owned by a lower rank
  std::vector<std::vector<std::uint32_t>> asked(static_cast<std::size_t>(P));  // my vertices rank r also has
  for (int r = 0; r < P; ++r) {
    Reader rd{in[std::size_t(r)]};
    while (!rd.done()) {
      const std::uint64_t key = rd.get<std::uint64_t>(), ax = rd.get<std::uint64_t>();
      const auto it = index.find((key << 2) | ax);
      if (it == index.end()) continue;
      asked[std::size_t(r)].push_back(it->second);
      if (r < me) foreign[it->second] = 1;
    }
  }
  std::uint64_t owned = 0;
  for (std::size_t v = 0; v < nv; ++v) owned += foreign[v] ? 0 : 1;
  std::vector<std::uint64_t> counts(static_cast<std::size_t>(P), 0);
  counts[std::size_t(me)] = owned;
  c.reduce(counts.data(), P, NBMC__SUM_U64);
  std::uint64_t offset = 0;
  for (int r = 0; r < me; ++r) offset += counts[std::size_t(r)];
  total = std::accumulate(counts.begin(), counts.end(), std::uint64_t(0));
  ids.assign(nv, std::numeric_limits<std::uint64_t>::max());
  std::uint64_t next = offset;
  for (std::size_t v = 0; v < nv; ++v)
    if (!foreign[v]) ids[v] = next++;
  // Owners tell the higher ranks that share a vertex its id.
  std::vector<std::vector<char>> reply(static_cast<std::size_t>(P));
  for (int r = me + 1; r < P; ++r)
    for (std::uint32_t v : asked[std::size_t(r)])
      if (!foreign[v]) {
        put(reply[std::size_t(r)], piece.vertex_keys[v]);
        put(reply[std::size_t(r)], std::uint64_t(piece.vertex_axes[v]));
        put(reply[std::size_t(r)], ids[v]);
      }
  const std::vector<std::vector<char>> answers = c.alltoall(reply);
  for (int r = 0; r < me; ++r) {
    Reader rd{answers[std::size_t(r)]};
    while (!rd.done()) {
      const std::uint64_t key = rd.get<std::uint64_t>(), ax = rd.get<std::uint64_t>(), id = rd.get<std::uint64_t>();
      const auto it = index.find((key << 2) | ax);
      if (it != index.end() && foreign[it->second]) ids[it->second] = std::min(ids[it->second], id);
    }
  }
  for (std::size_t v = 0; v < nv; ++v)
    if (ids[v] == std::numeric_limits<std::uint64_t>::max())
      throw Error(NBMC_ERROR_INTERNAL, "MPI: a shared vertex got no global id from its owner");
}


// ------------------------------------------------------- particle attributes
// The attributes of every rank's particles interpolated onto the vertices
// that `out` holds on this rank (the root's gathered, post-processed mesh, or
// each rank's piece), with the values a single process gives, bit for bit:
// each vertex goes to the rank that runs the subdomain owning the cell it
// lies in; every rank sends that rank its particles within R + 2 cells of the
// subdomain's cells, with their values; the owner sums them as one process
// would (the same cell grid, from the frame's bounds, and the same sorted
// order: backends/kokkos/attributes.hpp) and sends the values back. The
// only difference: a vertex with no particle within R takes the value of
// the nearest particle among those sent (within R + 2 cells), not the
// nearest in the frame.
void collective_attributes(nbmc_context& ctx, const Coll& c, const Params& p, const Decomposition& d,
                           const std::vector<int>& owner, const double box[6], const double* xyz, std::size_t count,
                           nbmc_mesh& out, RunStats& frame) {
  // Collective calls stay outside step(): a rank that fails between them
  // carries its error to the next agreement, so none waits alone.
  const double t0 = seconds_now();
  // Which attributes: every rank with particles must have set the same
  // names and components (ranks without particles set none).
  std::vector<char> sig;
  put(sig, std::uint64_t(count));
  for (const io::Attribute& a : ctx.attributes) {
    sig.insert(sig.end(), a.name.begin(), a.name.end());
    sig.push_back('\0');
    put(sig, std::int32_t(a.components));
  }
  const std::vector<std::vector<char>> sigs = c.alltoall(std::vector<std::vector<char>>(std::size_t(c.size()), sig));
  std::vector<io::Attribute> layout;
  step(c, [&] {
    // Every rank has the same lists, so every rank decides alike.
    auto body = [](const std::vector<char>& b) {
      return std::vector<char>(b.begin() + std::ptrdiff_t(std::min(b.size(), sizeof(std::uint64_t))), b.end());
    };
    auto describe_sig = [&](const std::vector<char>& b) {
      const std::vector<char> x = body(b);
      std::string text;
      for (std::size_t i = 0; i < x.size();) {
        const std::size_t z = std::size_t(std::find(x.begin() + std::ptrdiff_t(i), x.end(), '\0') - x.begin());
        std::int32_t comps = 0;
        if (z + 1 + sizeof comps <= x.size()) std::memcpy(&comps, x.data() + z + 1, sizeof comps);
        text += (text.empty() ? "'" : ", '") + std::string(x.begin() + std::ptrdiff_t(i), x.begin() + std::ptrdiff_t(z)) +
                "' (" + std::to_string(comps) + " components)";
        i = z + 1 + sizeof comps;
      }
      return text.empty() ? std::string("none") : text;
    };
    int first = -1;
    for (int r = 0; r < c.size(); ++r) {
      const std::vector<char>& b = sigs[std::size_t(r)];
      std::uint64_t n = 0;
      if (b.size() >= sizeof n) std::memcpy(&n, b.data(), sizeof n);
      if (n == 0) continue;  // no particles: nothing to match
      if (first < 0) {
        first = r;
        continue;
      }
      if (body(b) != body(sigs[std::size_t(first)]))
        throw Error(NBMC_ERROR_INVALID_ARGUMENT,
                    "the ranks with particles must set the same attributes (rank " + std::to_string(first) + ": " +
                        describe_sig(sigs[std::size_t(first)]) + "; rank " + std::to_string(r) + ": " +
                        describe_sig(b) + ")");
    }
    if (first < 0) return;
    const std::vector<char> x = body(sigs[std::size_t(first)]);
    for (std::size_t i = 0; i < x.size();) {
      const std::size_t z = std::size_t(std::find(x.begin() + std::ptrdiff_t(i), x.end(), '\0') - x.begin());
      io::Attribute a;
      a.name.assign(x.begin() + std::ptrdiff_t(i), x.begin() + std::ptrdiff_t(z));
      std::int32_t comps = 0;
      if (z + 1 + sizeof comps > x.size()) throw Error(NBMC_ERROR_INTERNAL, "MPI: a short attribute list");
      std::memcpy(&comps, x.data() + z + 1, sizeof comps);
      a.components = comps;
      layout.push_back(a);
      i = z + 1 + sizeof comps;
    }
  });
  if (layout.empty()) return;  // the same on every rank
  std::size_t width = 0;
  for (const io::Attribute& a : layout) width += std::size_t(a.components);

  const Grid& g = d.grid;
  const double R = p.influence_radius, margin = R + 2 * g.cell;
  // Per-particle radii: particle j's support is R r_j / r_max (its radius
  // travels after its values).
  const bool with_radii = p.radius_ref > 0;
  std::int64_t cells[3];
  std::vector<std::int64_t> bounds[3];  // subdomain coordinate i owns cells [bounds[i], bounds[i + 1])
  for (int a = 0; a < 3; ++a) {
    cells[a] = std::max<std::int64_t>(1, g.dims[a] - 1);
    for (int i = 0; i <= d.parts[a]; ++i) bounds[a].push_back(split_point(cells[a], d.parts[a], i));
  }
  auto cell_of = [&](double x, int a) {
    const double f = std::floor((x - g.origin[a]) / g.cell);
    return std::int64_t(f < 0 ? 0.0 : (f > double(cells[a] - 1) ? double(cells[a] - 1) : f));
  };
  auto coord_of = [&](std::int64_t cell, int a) {
    return int(std::upper_bound(bounds[a].begin() + 1, bounds[a].end() - 1, cell) - (bounds[a].begin() + 1));
  };
  auto index_of = [&](const int k[3]) { return std::size_t(k[0] + d.parts[0] * (k[1] + d.parts[1] * k[2])); };

  // a. This rank's vertices to the owners of their subdomains.
  const HostMesh& m = out.mesh;
  const std::size_t nv = std::size_t(m.vertex_count());
  std::vector<std::vector<char>> vout(std::size_t(c.size()));
  step(c, [&] {
    std::vector<float, NoInitAllocator<float>> vcopy;
    const float* v32 = m.positions.empty() ? nullptr : m.positions.data();
    if (m.on_device && nv) {
      vcopy.resize(3 * nv);
      run_on_kokkos_thread(ctx, [&] { download_mesh(m, vcopy.data(), nullptr, nullptr); });
      v32 = vcopy.data();
    }
    for (std::size_t v = 0; v < nv; ++v) {
      double x[3];
      for (int a = 0; a < 3; ++a) x[a] = m.f64 ? m.positions64[3 * v + std::size_t(a)] : double(v32[3 * v + std::size_t(a)]);
      int k[3];
      for (int a = 0; a < 3; ++a) k[a] = coord_of(cell_of(x[a], a), a);
      const std::size_t s = index_of(k);
      std::vector<char>& b = vout[std::size_t(owner[s])];
      put(b, std::uint64_t(s));
      put(b, std::uint64_t(v));
      for (int a = 0; a < 3; ++a) put(b, x[a]);
    }
  });
  const std::vector<std::vector<char>> vin = c.alltoall(vout);
  vout.clear();
  // b. Particles with their values to the owners of the subdomains near them.
  std::vector<std::vector<char>> pout(std::size_t(c.size()));
  step(c, [&] {
    if (with_radii && ctx.radii.size() != count) throw Error(NBMC_ERROR_INTERNAL, "MPI: the radii do not match");
    std::vector<double> packed(count * width);
    std::size_t off = 0;
    for (const io::Attribute& a : ctx.attributes) {
      const std::size_t comps = std::size_t(a.components);
      for (std::size_t i = 0; i < count; ++i)
        for (std::size_t q = 0; q < comps; ++q) packed[i * width + off + q] = a.values[i * comps + q];
      off += comps;
    }
    for (std::size_t i = 0; i < count; ++i) {
      int lo[3], hi[3];
      for (int a = 0; a < 3; ++a) {
        lo[a] = coord_of(cell_of(xyz[3 * i + std::size_t(a)] - margin, a), a);
        hi[a] = coord_of(cell_of(xyz[3 * i + std::size_t(a)] + margin, a), a);
      }
      int k[3];
      for (k[2] = lo[2]; k[2] <= hi[2]; ++k[2])
        for (k[1] = lo[1]; k[1] <= hi[1]; ++k[1])
          for (k[0] = lo[0]; k[0] <= hi[0]; ++k[0]) {
            const std::size_t s = index_of(k);
            std::vector<char>& b = pout[std::size_t(owner[s])];
            put(b, std::uint64_t(s));
            for (int a = 0; a < 3; ++a) put(b, xyz[3 * i + std::size_t(a)]);
            const char* vp = reinterpret_cast<const char*>(packed.data() + i * width);
            b.insert(b.end(), vp, vp + width * sizeof(double));
            if (with_radii) put(b, ctx.radii[i]);
          }
    }
  });
  const std::vector<std::vector<char>> pin = c.alltoall(pout);
  pout.clear();
  // c. Per subdomain of this rank: its particles and vertices, the sums,
  //    and the values back to the vertices' ranks.
  std::vector<std::vector<char>> rout(std::size_t(c.size()));
  step(c, [&] {
    struct Work {
      std::vector<double> xyz, scale;
      std::vector<io::Attribute> attrs;
      std::vector<double> verts;
      std::vector<std::pair<int, std::uint64_t>> from;  // (rank, vertex index there)
    };
    std::map<std::uint64_t, Work> work;
    for (int r = 0; r < c.size(); ++r) {
      Reader rd{vin[std::size_t(r)]};
      while (!rd.done()) {
        const std::uint64_t s = rd.get<std::uint64_t>(), v = rd.get<std::uint64_t>();
        Work& w = work[s];
        for (int a = 0; a < 3; ++a) w.verts.push_back(rd.get<double>());
        w.from.push_back({r, v});
      }
    }
    for (auto& entry : work) {
      entry.second.attrs = layout;
      for (io::Attribute& a : entry.second.attrs) a.values.clear();
    }
    for (int r = 0; r < c.size(); ++r) {
      Reader rd{pin[std::size_t(r)]};
      while (!rd.done()) {
        const std::uint64_t s = rd.get<std::uint64_t>();
        double x[3];
        for (int a = 0; a < 3; ++a) x[a] = rd.get<double>();
        const auto it = work.find(s);
        if (it != work.end()) {  // a subdomain without vertices needs no particles
          Work& w = it->second;
          w.xyz.insert(w.xyz.end(), x, x + 3);
          for (io::Attribute& a : w.attrs)
            for (int q = 0; q < a.components; ++q) a.values.push_back(rd.get<double>());
          if (with_radii) w.scale.push_back(rd.get<double>() / p.radius_ref);
        } else {
          const std::size_t skip = (width + (with_radii ? 1 : 0)) * sizeof(double);
          if (rd.at + skip > rd.b.size()) throw Error(NBMC_ERROR_INTERNAL, "MPI: short attribute message");
          rd.at += skip;
        }
      }
    }
    for (auto& entry : work) {
      Work& w = entry.second;
      const std::size_t n = w.xyz.size() / 3, k = w.verts.size() / 3;
      if (n == 0)  // a vertex lies within a cell of the particles that made it
        throw Error(NBMC_ERROR_INTERNAL, "MPI: no particles near the vertices of subdomain " + std::to_string(entry.first));
      const auto res = interpolate_at_vertices(ctx, w.xyz.data(), false, n, w.attrs, nullptr, w.verts.data(), k, R, box,
                                               with_radii ? w.scale.data() : nullptr);
      for (std::size_t i = 0; i < k; ++i) {
        std::vector<char>& b = rout[std::size_t(w.from[i].first)];
        put(b, w.from[i].second);
        const char* vp = reinterpret_cast<const char*>(res.data() + i * width);
        b.insert(b.end(), vp, vp + width * sizeof(double));
      }
    }
  });
  const std::vector<std::vector<char>> rin = c.alltoall(rout);
  rout.clear();
  // d. The values of this rank's vertices.
  step(c, [&] {
    std::vector<double> result(nv * width, 0.0);
    std::size_t got = 0;
    for (int r = 0; r < c.size(); ++r) {
      Reader rd{rin[std::size_t(r)]};
      while (!rd.done()) {
        const std::uint64_t v = rd.get<std::uint64_t>();
        if (v >= nv || rd.at + width * sizeof(double) > rd.b.size())
          throw Error(NBMC_ERROR_INTERNAL, "MPI: a bad attribute reply");
        std::memcpy(result.data() + v * width, rd.b.data() + rd.at, width * sizeof(double));
        rd.at += width * sizeof(double);
        ++got;
      }
    }
    if (got != nv)
      throw Error(NBMC_ERROR_INTERNAL, "MPI: attribute values for " + std::to_string(got) + " of " +
                                           std::to_string(nv) + " vertices came back");
    store_mesh_attributes(layout, result.data(), out);
  });
  frame.stage[NBMC_STAGE_ATTRIBUTES] += seconds_now() - t0;
}

}  // namespace

// The collective reconstruction (see collective.h).
void reconstruct_collective(nbmc_context& ctx, const nbmc_params& full, const nbmc__collective& hooks,
                            int32_t output, int32_t root, nbmc_mesh& out) {
  HostMesh& mesh = out.mesh;
  const Coll c{hooks};
  const double t_start = seconds_now();
  const ScopedHostThreads host_threads(host_threads_of(ctx));  // the root's post-processing, as in capi.cpp
  Params p;
  // 1. Parameters, and what each rank's upload left (agreed: a rank whose
  //    particles were rejected fails the call on every rank).
  step(c, [&] {
    if (!ctx.pending_error.empty()) throw Error(ctx.pending_status, ctx.pending_error);
    check_postprocess_params(full);
    p = resolve_params(full);
    check_domain(p);
    if (p.field != FieldKind::NarrowBand)
      throw Error(NBMC_ERROR_INVALID_PARAMETER, "MPI reconstruction needs the narrow-band field");
    if (p.drop_isolated)
      throw Error(NBMC_ERROR_INVALID_PARAMETER,
                  "isolated = drop or sphere is not available over MPI (clusters may span the ranks)");
    if (full.smooth_weighting == NBMC_SMOOTH_FEATURE)
      throw Error(NBMC_ERROR_INVALID_PARAMETER,
                  "smooth_weighting = feature is not available over MPI (the root has no particles)");
    if (output != NBMC__OUTPUT_GATHER && output != NBMC__OUTPUT_PIECES)
      throw Error(NBMC_ERROR_INVALID_ARGUMENT, "unknown MPI output mode " + std::to_string(output));
    if (root < 0 || root >= c.size())
      throw Error(NBMC_ERROR_INVALID_ARGUMENT, "root rank " + std::to_string(root) + " is not in the communicator");
  });
  // 2. Host copies of this rank's particles; the frame's bounds and grid.
  ParticleVector host;
  const double* xyz = nullptr;
  std::size_t count = 0;
  step(c, [&] {
    if (ctx.device_particles.count) {
      count = ctx.device_particles.count;
      host.resize(3 * count);
      run_on_kokkos_thread(ctx, [&] { download_particles(ctx.device_particles.data.get(), count, host.data()); });
      xyz = host.data();
    } else {
      count = ctx.particles.size() / 3;
      xyz = ctx.particles.data();
    }
  });
  // Per-particle radii: the frame's smallest and largest, over the ranks that
  // have particles (all with radii, or none), scale the parameters alike on
  // every rank (scale_for_radii).
  {
    const bool mine = !ctx.radii.empty();
    double rr[4] = {mine ? ctx.radius_min : std::numeric_limits<double>::infinity(),
                    mine ? -ctx.radius_max : std::numeric_limits<double>::infinity(),
                    count > 0 && !mine ? 0.0 : 1.0,  // 0 somewhere: a rank with particles and no radii
                    mine ? -1.0 : 0.0};              // -1 somewhere: a rank with radii
    c.reduce(rr, 4, NBMC__MIN_F64);
    step(c, [&] {
      if (mine && ctx.radii.size() != count)
        throw Error(NBMC_ERROR_INTERNAL, "MPI: the radii do not match the particles");
      if (rr[3] < 0 && rr[2] == 0)
        throw Error(NBMC_ERROR_INVALID_ARGUMENT,
                    "nbmc_mpi_reconstruct: some ranks set per-particle radii (nbmc_context_set_radii_*) and some "
                    "ranks with particles did not");
      if (rr[3] < 0) {
        scale_for_radii(p, rr[0], -rr[1]);
        check_domain(p);
      }
    });
  }
  // Sent with the particles when they differ (then every rank with particles has them).
  const bool with_radii = p.radius_ref > 0;
  const double* const radii = with_radii ? ctx.radii.data() : nullptr;
  double box[6];
  particle_bounds(xyz, count, box, box + 3);
  for (int a = 0; a < 3; ++a) box[3 + a] = -box[3 + a];
  c.reduce(box, 6, NBMC__MIN_F64);
  for (int a = 0; a < 3; ++a) box[3 + a] = -box[3 + a];
  std::uint64_t total_particles = count;
  c.reduce(&total_particles, 1, NBMC__SUM_U64);
  if (total_particles == 0) throw Error(NBMC_ERROR_NO_PARTICLES, "no rank has particles");
  Grid g;
  Decomposition d;
  step(c, [&] {
    g = frame_grid(box, box + 3, p);
    int parts[3] = {ctx.subdomains.parts[0], ctx.subdomains.parts[1], ctx.subdomains.parts[2]};
    // By default four subdomains per rank: particles are rarely spread evenly
    // over the cells, and the largest-first assignment needs several per rank
    // to balance them (a 2-rank run of the 292 k frame: 230 k / 62 k particles
    // with one each, 148 k / 144 k with four).
    std::uint64_t pieces = 4 * std::uint64_t(c.size());
    if (ctx.subdomains.automatic && ctx.memory.budget) {
      const double usable = 0.8 * double(ctx.memory.budget);
      pieces = std::max<std::uint64_t>(
          pieces, std::uint64_t(std::ceil(double(estimate_bytes(p, total_particles)) / usable * 1.15)));
    }
    if (ctx.subdomains.automatic || parts[0] * parts[1] * parts[2] == 1) choose_parts(g, pieces, parts);
    d = decompose(g, p, parts);
  });
  // 3. Who runs which subdomain: loads are the particles (ghosts included).
  std::vector<std::vector<std::uint32_t>> sel;
  std::vector<std::uint64_t> load(d.count(), 0);
  step(c, [&] {
    sel = select_particles(d, p, xyz, count);
    for (std::size_t s = 0; s < d.count(); ++s) load[s] = sel[s].size();
  });
  c.reduce(load.data(), int(load.size()), NBMC__SUM_U64);
  const std::vector<int> owner = assign(load, c.size());
  std::vector<int> mine;
  std::map<int, std::size_t> local;
  for (std::size_t s = 0; s < d.count(); ++s)
    if (owner[s] == c.rank()) {
      local[int(s)] = mine.size();
      mine.push_back(int(s));
    }
  // 4. Particles to the ranks of their subdomains.
  std::vector<std::vector<double>> parts_xyz(mine.size()), parts_radii(mine.size());
  {
    std::vector<std::vector<char>> out(static_cast<std::size_t>(c.size()));
    step(c, [&] {
      for (std::size_t s = 0; s < d.count(); ++s) {
        if (sel[s].empty()) continue;
        std::vector<char>& b = out[std::size_t(owner[s])];
        put(b, std::uint64_t(s));
        put(b, std::uint64_t(sel[s].size()));
        for (std::uint32_t i : sel[s]) b.insert(b.end(), reinterpret_cast<const char*>(xyz + 3 * std::size_t(i)),
                                               reinterpret_cast<const char*>(xyz + 3 * std::size_t(i) + 3));
        if (with_radii)  // then the same particles' radii
          for (std::uint32_t i : sel[s]) put(b, radii[i]);
      }
      sel.clear();
      sel.shrink_to_fit();
    });
    const std::vector<std::vector<char>> in = c.alltoall(out);
    out.clear();
    step(c, [&] {
      for (int r = 0; r < c.size(); ++r) {
        Reader rd{in[std::size_t(r)]};
        while (!rd.done()) {
          const std::uint64_t s = rd.get<std::uint64_t>(), n = rd.get<std::uint64_t>();
          const auto it = local.find(int(s));
          if (it == local.end()) throw Error(NBMC_ERROR_INTERNAL, "MPI: particles arrived for another rank's subdomain");
          std::vector<double>& dst = parts_xyz[it->second];
          const std::size_t at = dst.size();
          dst.resize(at + 3 * std::size_t(n));
          if (rd.at + 3 * n * sizeof(double) > rd.b.size()) throw Error(NBMC_ERROR_INTERNAL, "MPI: short particle message");
          std::memcpy(dst.data() + at, rd.b.data() + rd.at, 3 * std::size_t(n) * sizeof(double));
          rd.at += 3 * std::size_t(n) * sizeof(double);
          if (with_radii) {
            std::vector<double>& rdst = parts_radii[it->second];
            for (std::uint64_t k = 0; k < n; ++k) rdst.push_back(rd.get<double>());
          }
        }
      }
    });
  }
  // 5. The subdomains, with band growth exchanged between the ranks.
  SubdomainReport& rep = ctx.subdomain_report;
  rep = SubdomainReport();
  rep.used = true;
  for (int a = 0; a < 3; ++a) rep.parts[a] = d.parts[a];
  rep.count = d.count();
  rep.automatic = ctx.subdomains.automatic;
  rep.ghost_width = double(d.ghost_nb_cells) * g.nb_cell;
  SubdomainComm comm;
  comm.exchange = [&](const std::vector<std::array<std::int64_t, 4>>& recs) {
    std::vector<std::vector<char>> out(static_cast<std::size_t>(c.size()));
    for (const auto& r : recs) put(out[std::size_t(owner[std::size_t(r[0])])], r);
    std::vector<std::array<std::int64_t, 4>> got;
    for (const auto& b : c.alltoall(out)) {
      Reader rd{b};
      while (!rd.done()) got.push_back(rd.get<std::array<std::int64_t, 4>>());
    }
    return got;
  };
  comm.any = [&](bool b) {
    std::uint64_t v = b ? 1 : 0;
    c.reduce(&v, 1, NBMC__MAX_U64);
    return v != 0;
  };
  comm.agree = [&](std::exception_ptr e) { agree(c, e); };
  Progress progress;
  if (ctx.progress_fn) {
    nbmc_progress_fn fn = ctx.progress_fn;
    void* user = ctx.progress_user;
    progress.fn = [fn, user](int stage, double f) { return fn(user, stage, f) == 0; };
  }
  Params q = p;
  q.use_bbox = false;  // the selection applied the box
  const RunRegion run = [&](const ParticleInput& in, const Params& pp, HostMesh& m, RunStats& s) {
    run_region(ctx, in, pp, progress, m, s);
  };
  RunStats st;
  ctx.memory.reset_peak();
  std::vector<Piece> pieces = run_subdomain_job(
      d, q, mine,
      [&](std::size_t i, std::vector<double>& out, std::vector<double>& out_radii) {
        out = parts_xyz[i];
        out_radii = parts_radii[i];
      },
      run, comm, st, rep);
  for (SubdomainEntry& e : rep.entries) e.rank = c.rank();
  parts_xyz.clear();
  parts_radii.clear();
  // 6. This rank's subdomains merged into one piece (with keys).
  Piece merged;
  step(c, [&] {
    std::vector<const Piece*> ptrs;
    for (const Piece& pc : pieces) ptrs.push_back(&pc);
    stitch(ptrs, [&](std::uint64_t nv, std::uint64_t nt) {
      merged.positions.resize(p.double_positions ? 0 : 3 * nv);
      merged.positions64.resize(p.double_positions ? 3 * nv : 0);
      merged.normals.resize(p.normals ? 3 * nv : 0);
      merged.triangles.resize(3 * nt);
      merged.vertex_keys.resize(nv);
      merged.vertex_axes.resize(nv);
      merged.triangle_cells.resize(nt);
      StitchTarget t;
      t.positions = p.double_positions ? nullptr : merged.positions.data();
      t.positions64 = p.double_positions ? merged.positions64.data() : nullptr;
      t.normals = p.normals ? merged.normals.data() : nullptr;
      t.triangles = merged.triangles.data();
      t.vertex_keys = merged.vertex_keys.data();
      t.vertex_axes = merged.vertex_axes.data();
      t.triangle_cells = merged.triangle_cells.data();
      return t;
    });
    pieces.clear();
  });
  // 7. Counts over all ranks (stage times: the slowest rank's).
  std::uint64_t sums[8] = {st.surface_particles, st.occupied_cells, st.band_vertices, st.band_blocks,
                           st.cells, st.evaluations, st.band_growth_cells, rep.ghost_particles};
  c.reduce(sums, 8, NBMC__SUM_U64);
  double stage_max[16];
  std::copy(st.stage, st.stage + 16, stage_max);
  c.reduce(stage_max, 16, NBMC__MAX_F64);
  std::uint64_t ex[2] = {rep.reruns, rep.exchanged_cells};
  c.reduce(ex, 2, NBMC__SUM_U64);
  // Per-subdomain entries to the root (fixed-size records).
  {
    std::vector<char> b;
    for (const SubdomainEntry& e : rep.entries) put(b, e);
    const auto all = c.gather(b, root);
    if (c.rank() == root) {
      std::vector<SubdomainEntry> entries;
      for (const auto& part : all) {
        Reader rd{part};
        while (!rd.done()) entries.push_back(rd.get<SubdomainEntry>());
      }
      std::sort(entries.begin(), entries.end(),
                [](const SubdomainEntry& a, const SubdomainEntry& b2) { return a.index < b2.index; });
      rep.entries = entries;
    }
  }
  rep.reruns = ex[0];
  rep.exchanged_cells = ex[1];
  rep.ghost_particles = sums[7];
  RunStats frame;
  frame.particles = total_particles;
  frame.surface_particles = sums[0];
  frame.occupied_cells = sums[1];
  frame.band_vertices = sums[2];
  frame.band_blocks = sums[3];
  frame.cells = sums[4];
  frame.evaluations = sums[5];
  frame.band_growth_cells = sums[6];
  std::copy(stage_max, stage_max + 16, frame.stage);
  frame.grid_vertices = g.vertex_count();
  for (int a = 0; a < 3; ++a) {
    frame.dims[a] = std::uint64_t(g.dims[a]);
    frame.origin[a] = g.origin[a];
  }
  frame.cell = g.cell;
  // 8. Output.
  if (output == NBMC__OUTPUT_GATHER) {
    std::vector<char> b;
    step(c, [&] {
      pack_piece(b, merged);
      merged = Piece();
    });
    const auto all = c.gather(b, root);
    b.clear();
    b.shrink_to_fit();
    step(c, [&] {
      if (c.rank() != root) return;
      std::vector<Piece> ps;
      for (const auto& part : all) {
        Reader rd{part};
        ps.push_back(unpack_piece(rd));
      }
      const StitchResult r = stitch_into(ps, p.normals, p.double_positions, mesh, rep.stitch_seconds);
      rep.shared_vertices = r.shared_vertices;
      frame.stage[6] += rep.stitch_seconds;
      frame.vertices = r.vertices;
      frame.triangles = r.triangles;
      if (ctx.mesh_memory == NBMC_MEMORY_DEVICE) run_on_kokkos_thread(ctx, [&] { move_mesh_to_device(mesh); });
    });
  } else {
    std::vector<std::uint64_t> ids;
    std::uint64_t total = 0;
    {
      std::exception_ptr e;
      try {
        global_ids(c, d, owner, merged, ids, total);  // collective inside: not in a step()
      } catch (...) {
        e = std::current_exception();
      }
      agree(c, e);
    }
    step(c, [&] {
      mesh.f64 = p.double_positions;
      mesh.positions.swap(merged.positions);
      mesh.positions64.swap(merged.positions64);
      mesh.normals.swap(merged.normals);
      mesh.triangles.swap(merged.triangles);
      mesh.global_ids = std::move(ids);
      mesh.global_vertex_count = total;
      frame.vertices = mesh.vertex_count();
      frame.triangles = mesh.triangle_count();
      if (ctx.mesh_memory == NBMC_MEMORY_DEVICE) run_on_kokkos_thread(ctx, [&] { move_mesh_to_device(mesh); });
    });
  }
  // 9. Clean-up and smoothing work on whole meshes: on the root's stitched
  //    mesh; pieces stay as marching cubes made them (their shared vertices
  //    must stay shared). Agreed, as the attributes need every rank next.
  //    On nbmc's Kokkos thread, as for one process: a mesh in GPU memory
  //    gets its clean-up's adjacency from the GPU.
  ctx.postprocess = nbmc::mesh::PostprocessStats();
  step(c, [&] {
    if (output == NBMC__OUTPUT_GATHER && c.rank() == root)
      run_on_kokkos_thread(ctx, [&] { ctx.postprocess = postprocess_mesh(full, mesh, frame, ctx.memory); });
    else if (output == NBMC__OUTPUT_PIECES)
      ctx.postprocess.raw_triangles = ctx.postprocess.pre_decimation_triangles = mesh.triangle_count();
  });
  // 10. Particle attributes onto the final vertices.
  out.attributes.clear();
  collective_attributes(ctx, c, p, d, owner, box, xyz, count, out, frame);
  frame.total = seconds_now() - t_start;
  ctx.stats = frame;
  ctx.peak_memory = ctx.memory.peak.load();
}

}  // namespace nbmc
