// SPDX-License-Identifier: MIT
#include "subdomains.hpp"

#include "core/parallel.hpp"

#include <Kokkos_Core.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

namespace nbmc {

namespace {

// Particles of packed xyz whose grid cell the subdomain owns.
std::uint64_t owned_particles(const Grid& g, const Subdomain& s, const std::vector<double>& xyz) {
  std::atomic<std::uint64_t> total{0};
  const std::size_t n_particles = xyz.size() / 3;
  for_chunks(n_particles, chunk_count(n_particles, 50000), [&](std::size_t, std::size_t b, std::size_t e) {
    std::uint64_t n = 0;
    for (std::size_t i = b; i < e; ++i) {
      bool in = true;
      for (int a = 0; a < 3 && in; ++a) {
        std::int64_t c = std::int64_t(std::floor((xyz[3 * i + std::size_t(a)] - g.origin[a]) / g.cell));
        c = std::max<std::int64_t>(0, std::min<std::int64_t>(c, g.dims[a] - 2));
        in = c >= s.cell_lo[a] && c < s.cell_hi[a];
      }
      n += in ? 1 : 0;
    }
    total += n;
  });
  return total.load();
}

}  // namespace

double seconds_now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

StitchResult stitch_into(const std::vector<Piece>& pieces, bool normals, bool f64, HostMesh& mesh, double& seconds) {
  const double t0 = seconds_now();
  std::vector<const Piece*> ptrs;
  for (const Piece& pc : pieces) ptrs.push_back(&pc);
  mesh.f64 = f64;
  const StitchResult r = stitch(ptrs, [&](std::uint64_t nv, std::uint64_t nt) {
    mesh.positions.resize(f64 ? 0 : 3 * nv);
    mesh.positions64.resize(f64 ? 3 * nv : 0);
    mesh.normals.resize(normals ? 3 * nv : 0);
    mesh.triangles.resize(3 * nt);
    StitchTarget t;
    t.positions = f64 ? nullptr : mesh.positions.data();
    t.positions64 = f64 ? mesh.positions64.data() : nullptr;
    t.normals = normals ? mesh.normals.data() : nullptr;
    t.triangles = mesh.triangles.data();
    return t;
  });
  seconds = seconds_now() - t0;
  return r;
}

void add_run_stats(RunStats& t, const RunStats& o) {
  t.surface_particles += o.surface_particles;
  t.occupied_cells += o.occupied_cells;
  t.band_vertices += o.band_vertices;
  t.band_blocks += o.band_blocks;
  t.cells += o.cells;
  t.evaluations += o.evaluations;
  t.band_growth_rounds = std::max(t.band_growth_rounds, o.band_growth_rounds);
  t.band_growth_cells += o.band_growth_cells;
  for (int s = 0; s < 16; ++s) t.stage[s] += o.stage[s];
}

std::vector<Piece> run_subdomain_job(const Decomposition& d, const Params& p, const std::vector<int>& mine,
                                     const PackParticles& particles, const RunRegion& run,
                                     const SubdomainComm& comm, RunStats& st, SubdomainReport& rep) {
  using Cell = std::array<std::int64_t, 3>;
  const std::size_t m = mine.size();
  std::map<int, std::size_t> local;
  for (std::size_t i = 0; i < m; ++i) local[mine[i]] = i;
  std::vector<std::set<Cell>> known(m);          // cells in the final band of each: grown or received
  std::vector<std::vector<std::int64_t>> seeds(m);
  std::vector<char> dirty(m, 1);
  std::vector<Piece> pieces(m);
  std::vector<RunStats> last(m);
  std::vector<SubdomainEntry> entries(m);
  std::vector<double> xyz, radii;
  for (std::size_t i = 0; i < m; ++i) {
    const Subdomain& s = d.subdomains[std::size_t(mine[i])];
    SubdomainEntry& e = entries[i];
    e.index = s.index;
    for (int a = 0; a < 3; ++a) {
      e.coord[a] = s.coord[a];
      e.cell_lo[a] = s.cell_lo[a];
      e.cell_hi[a] = s.cell_hi[a];
    }
  }
  std::vector<int> near;
  for (int round = 0;; ++round) {
    if (round > 1000) throw Error(NBMC_ERROR_INTERNAL, "subdomains: the band growth did not settle after 1000 exchanges");
    std::vector<std::array<std::int64_t, 4>> out;
    std::exception_ptr failed;
    try {
    for (std::size_t i = 0; i < m; ++i) {
      if (!dirty[i]) continue;
      dirty[i] = 0;
      const Subdomain& s = d.subdomains[std::size_t(mine[i])];
      particles(i, xyz, radii);
      if (p.radius_ref > 0 && radii.size() != xyz.size() / 3)
        throw Error(NBMC_ERROR_INTERNAL, "subdomains: the radii do not match the particles");
      SubdomainEntry& e = entries[i];
      if (e.runs == 0) {
        const std::uint64_t owned = owned_particles(d.grid, s, xyz);
        e.particles = owned;
        e.ghost_particles = xyz.size() / 3 - owned;
      }
      if (xyz.empty()) {  // nothing within reach: no band, no field, no surface
        pieces[i] = Piece();
        ++e.runs;
        continue;
      }
      Region reg;
      reg.grid = d.grid;
      for (int a = 0; a < 3; ++a) {
        reg.vert_lo[a] = s.vert_lo[a];
        reg.vert_hi[a] = s.vert_hi[a];
        reg.cell_lo[a] = s.cell_lo[a];
        reg.cell_hi[a] = s.cell_hi[a];
      }
      reg.seeds = seeds[i];
      Piece piece;
      reg.piece = &piece;
      ParticleInput in;
      in.xyz = xyz.data();
      in.count = xyz.size() / 3;
      in.region = &reg;
      in.radii = p.radius_ref > 0 ? radii.data() : nullptr;
      HostMesh mesh;
      RunStats one;
      const double t0 = seconds_now();
      run(in, p, mesh, one);
      e.seconds += seconds_now() - t0;
      if (e.runs > 0) ++rep.reruns;
      ++e.runs;
      for (int q = 0; q < 16; ++q) st.stage[q] += one.stage[q];
      st.evaluations += one.evaluations;
      one.evaluations = 0;
      for (double& x : one.stage) x = 0;
      last[i] = one;
      piece.positions.swap(mesh.positions);
      piece.positions64.swap(mesh.positions64);
      piece.normals.swap(mesh.normals);
      piece.triangles.swap(mesh.triangles);
      e.vertices = piece.vertex_count();
      e.triangles = piece.triangle_count();
      pieces[i] = std::move(piece);
      // Cells this subdomain's growth added: every subdomain whose owned cells
      // lie within two cells of one must have it in its band too (its leak
      // scan reads the cells around its own, its normals one vertex further).
      for (std::size_t c = 0; c + 2 < reg.grown.size(); c += 3) {
        const Cell cell = {reg.grown[c], reg.grown[c + 1], reg.grown[c + 2]};
        known[i].insert(cell);
        near.clear();
        subdomains_near_cell(d, cell[0], cell[1], cell[2], 2, near);
        for (int t : near)
          if (t != s.index) out.push_back({t, cell[0], cell[1], cell[2]});
      }
    }
    } catch (...) {
      failed = std::current_exception();
    }
    comm.agree(failed);  // every process fails together, or none
    bool fresh = false;
    for (const auto& r : comm.exchange(out)) {
      const auto it = local.find(int(r[0]));
      if (it == local.end()) throw Error(NBMC_ERROR_INTERNAL, "subdomains: a cell was sent to the wrong process");
      const std::size_t i = it->second;
      if (!known[i].insert({r[1], r[2], r[3]}).second) continue;
      seeds[i].insert(seeds[i].end(), {r[1], r[2], r[3]});
      dirty[i] = 1;
      fresh = true;
      ++rep.exchanged_cells;
    }
    if (!comm.any(fresh)) break;
  }
  for (std::size_t i = 0; i < m; ++i) {
    add_run_stats(st, last[i]);
    rep.ghost_particles += entries[i].ghost_particles;
  }
  rep.entries.insert(rep.entries.end(), entries.begin(), entries.end());
  return pieces;
}

namespace {

void run_split(const int parts[3], const Grid& g, const double* xyz, const double* radii, std::size_t count,
               const Params& p, const RunRegion& run, HostMesh& mesh, RunStats& st, SubdomainReport& rep) {
  const Decomposition d = decompose(g, p, parts);
  const std::vector<std::vector<std::uint32_t>> sel = select_particles(d, p, xyz, count);
  Params q = p;
  q.use_bbox = false;  // the selection applied the box; the grid comes from it
  std::vector<int> all(d.count());
  for (std::size_t s = 0; s < d.count(); ++s) all[s] = int(s);
  SubdomainComm local;
  local.exchange = [](const std::vector<std::array<std::int64_t, 4>>& out) { return out; };
  local.any = [](bool b) { return b; };
  local.agree = [](std::exception_ptr e) {
    if (e) std::rethrow_exception(e);
  };
  rep = SubdomainReport();
  rep.used = true;
  for (int a = 0; a < 3; ++a) rep.parts[a] = d.parts[a];
  rep.count = d.count();
  rep.ghost_width = double(d.ghost_nb_cells) * g.nb_cell;
  RunStats acc;
  const double t0 = seconds_now();
  std::vector<Piece> pieces = run_subdomain_job(
      d, q, all,
      [&](std::size_t i, std::vector<double>& out, std::vector<double>& out_radii) {
        out.resize(3 * sel[i].size());
        out_radii.resize(radii ? sel[i].size() : 0);
        for_chunks(sel[i].size(), chunk_count(sel[i].size(), 50000), [&](std::size_t, std::size_t b, std::size_t e) {
          for (std::size_t k = b; k < e; ++k) {
            for (int a = 0; a < 3; ++a) out[3 * k + std::size_t(a)] = xyz[3 * std::size_t(sel[i][k]) + std::size_t(a)];
            if (radii) out_radii[k] = radii[sel[i][k]];
          }
        });
      },
      run, local, acc, rep);
  std::uint64_t particles = 0;
  for (const SubdomainEntry& e : rep.entries) particles += e.particles;
  if (particles == 0 && p.use_bbox)
    throw Error(NBMC_ERROR_NO_PARTICLES, "no particle lies within the bounding box (extended by the influence radius)");
  const StitchResult r = stitch_into(pieces, p.normals, p.double_positions, mesh, rep.stitch_seconds);
  rep.shared_vertices = r.shared_vertices;
  acc.stage[6] += rep.stitch_seconds;
  acc.particles = particles;
  acc.vertices = r.vertices;
  acc.triangles = r.triangles;
  acc.grid_vertices = g.vertex_count();
  for (int a = 0; a < 3; ++a) {
    acc.dims[a] = std::uint64_t(g.dims[a]);
    acc.origin[a] = g.origin[a];
  }
  acc.cell = g.cell;
  acc.total = seconds_now() - t0;
  st = acc;
}

}  // namespace

bool reconstruct_subdomains(const SubdomainSetting& setting, std::uint64_t budget, const double* xyz,
                            const double* radii, std::size_t count, const Params& p, const RunRegion& run,
                            HostMesh& mesh, RunStats& st, SubdomainReport& rep, std::uint64_t at_least) {
  if (p.field != FieldKind::NarrowBand)
    throw Error(NBMC_ERROR_INVALID_PARAMETER, "subdomains need the narrow-band field (not the dense or scatter baselines)");
  double lo[3], hi[3];
  if (!p.use_bbox) particle_bounds(xyz, count, lo, hi);
  const Grid g = frame_grid(lo, hi, p);
  int parts[3] = {setting.parts[0], setting.parts[1], setting.parts[2]};
  std::uint64_t pieces = 1;
  if (setting.automatic) {
    if (budget) {
      // A subdomain may use 80% of the budget by the estimate; the rest is
      // the estimate's error and what the context holds besides.
      const double usable = 0.8 * double(budget);
      const double est = double(estimate_bytes(p, count));
      if (est > usable) pieces = std::uint64_t(std::ceil(est / usable * 1.15));  // ghosts add to each subdomain
    }
    pieces = std::max(pieces, at_least);
    if (pieces <= 1) return false;
    choose_parts(g, pieces, parts);
    if (parts[0] * parts[1] * parts[2] == 1) return false;
  }
  for (int attempt = 0;; ++attempt) {
    try {
      run_split(parts, g, xyz, radii, count, p, run, mesh, st, rep);
      rep.automatic = setting.automatic;
      rep.budget_bytes = setting.automatic ? budget : 0;
      return true;
    } catch (const Error& e) {
      // `auto`: a subdomain over the budget splits the frame further.
      if (!setting.automatic || !split_would_help(e) || attempt >= 6) throw;
      const int before = parts[0] * parts[1] * parts[2];
      pieces = std::uint64_t(before) * 2;
      choose_parts(g, pieces, parts);
      if (parts[0] * parts[1] * parts[2] <= before) throw;
    }
  }
}

}  // namespace nbmc
