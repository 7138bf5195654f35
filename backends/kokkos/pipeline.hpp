// SPDX-License-Identifier: MIT
// The whole reconstruction (paper Alg. 1), templated on the execution space:
// upload -> neighbourhood -> surface particles -> band -> field -> marching cubes.
#pragma once

#include "common.hpp"
#include "field_ssp07.hpp"
#include "field_zb05.hpp"
#include "grid.hpp"
#include "marching_cubes.hpp"
#include "narrow_band.hpp"
#include "neighbourhood.hpp"
#include "scalar_field.hpp"
#include "surface_particles.hpp"

#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

namespace nbmc {

// The mesh as the C API hands it out.
struct HostMesh {
  std::vector<float> positions, normals;
  std::vector<std::uint32_t> triangles;
};

struct RunStats {
  std::uint64_t particles = 0, surface_particles = 0, occupied_cells = 0, band_vertices = 0, band_blocks = 0,
                grid_vertices = 0, cells = 0, vertices = 0, triangles = 0, evaluations = 0;
  std::uint64_t band_growth_rounds = 0, band_growth_cells = 0;
  std::uint64_t dims[3] = {0, 0, 0};
  double stage[16] = {0};
  double total = 0;
  double origin[3] = {0, 0, 0};
  double cell = 0;
};

namespace Details {

template <class ExecSpace>
void reconstruct(const ExecSpace& space, const double* xyz, std::size_t count, const Params& p,
                 MemoryTracker& tracker, const Progress& progress, HostMesh& mesh, RunStats& st) {
  using MemSpace = typename ExecSpace::memory_space;
  ScopedRegion region("nbmc::reconstruct");
  Kokkos::Timer total, timer;
  auto lap = [&](int stage) {
    space.fence();
    trace("stage done", std::uint64_t(stage));
    st.stage[stage] += timer.seconds();
    timer.reset();
    progress(stage, 1.0);
  };

  // ---------------------------------------------------------------- upload
  progress(0, 0.0);
  std::vector<std::uint32_t> keep;
  double lo[3] = {std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
                  std::numeric_limits<double>::max()};
  double hi[3] = {-lo[0], -lo[1], -lo[2]};
  if (p.use_bbox) {
    const double R = p.influence_radius;
    for (std::size_t i = 0; i < count; ++i) {
      bool in = true;
      for (int a = 0; a < 3; ++a) {
        const double x = xyz[3 * i + a];
        in = in && x >= p.bbox_min[a] - R && x <= p.bbox_max[a] + R;
      }
      if (in) keep.push_back(std::uint32_t(i));
    }
    if (keep.empty()) throw Error(3, "no particle lies within the bounding box (extended by the influence radius)");
    for (int a = 0; a < 3; ++a) {
      lo[a] = p.bbox_min[a];
      hi[a] = p.bbox_max[a];
    }
  } else {
    for (std::size_t i = 0; i < count; ++i)
      for (int a = 0; a < 3; ++a) {
        const double x = xyz[3 * i + a];
        lo[a] = x < lo[a] ? x : lo[a];
        hi[a] = x > hi[a] ? x : hi[a];
      }
  }
  const Grid g = make_grid(lo, hi, p);
  st.particles = keep.empty() ? count : keep.size();
  st.grid_vertices = g.vertex_count();
  for (int a = 0; a < 3; ++a) {
    st.dims[a] = std::uint64_t(g.dims[a]);
    st.origin[a] = g.origin[a];
  }
  st.cell = g.cell;
  lap(0);

  // Up-front estimate (bytes) from what is known now: the particles, and for
  // the baselines the dense grid. The band is estimated again below.
  {
    const std::uint64_t n = st.particles;
    std::uint64_t need = n * (sizeof(SortRecord) + 3 * sizeof(float) + sizeof(std::uint32_t) + 1) + n / 2 * 24;
    if (p.field != 0) {
      const std::uint64_t nv = g.vertex_count();
      need += nv * 14;  // field value, cell info, vertex numbering, bitmap
      if (p.field == 2) need += nv * 4 * (p.method == 1 ? FieldZB05::N : FieldSSP07::N);
    }
    tracker.require(need, p.field == 0 ? "the neighbourhood" : "the dense baseline grid (estimated)");
  }

  // ---------------------------------------------------------- neighbourhood
  Neighbourhood<MemSpace> nbh;
  build_neighbourhood(space, tracker, xyz, count, keep, g, nbh);
  const NeighbourView<MemSpace> nb = view_of(nbh, g);
  st.occupied_cells = nbh.n_cells;
  lap(1);

  // ------------------------------------------------ surface particles, band
  Band<MemSpace> band;
  if (p.field == 0 /*NBMC_FIELD_NARROW_BAND*/) {
    Buffer<std::uint8_t, MemSpace> flags(tracker, "surface_particles::flags", nbh.n);
    st.surface_particles = mark_surface_particles(
        space, nb, Kokkos::View<const std::uint64_t*, MemSpace>(nbh.cell_keys.view()), nbh.n_cells, p, g, flags.view());
    lap(2);
    build_narrow_band(space, tracker, g, p, Kokkos::View<const float*, MemSpace>(nbh.pos.view()),
                      Kokkos::View<const std::uint8_t*, MemSpace>(flags.view()), nbh.n, band);
  } else {
    lap(2);
    build_dense_band(space, tracker, g, band);
  }
  lap(3);

  // ------------------------------------------------------------------ field
  {  // the per-vertex arrays of the field and of marching cubes, before allocating them
    const std::uint64_t need = band.n_vertices * (sizeof(float) + 2 * sizeof(std::uint32_t)) +
                               band.n_blocks * 8 * sizeof(std::uint64_t);
    tracker.require(need, "the field and triangulation of " + std::to_string(band.n_vertices) +
                              " band vertices (estimated)");
  }
  const FieldConstants fc = field_constants(p.influence_radius, p.iso_radius, p.t_low, p.t_high);
  Buffer<float, MemSpace> phi(tracker, "scalar_field::values", band.n_vertices);
  const BandView<MemSpace> bv0 = view_of(band, g);
  const std::size_t n_words0 = band.n_blocks * 8;
  auto run_field = [&](auto method) {
    using Method = decltype(method);
    if (p.field == 2 /*NBMC_FIELD_SCATTER*/) {
      if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible) {
        return scatter_field<Method>(space, tracker, Kokkos::View<const float*, Kokkos::HostSpace>(nbh.pos.view()),
                                     nbh.n, bv0, n_words0, g, fc, phi.view(), progress);
      } else {
        throw Error(4, "the scatter baseline runs on the CPU backends only");
        return std::uint64_t(0);
      }
    }
    return gather_field<Method>(space, nb, bv0, n_words0, g, fc, phi.view(), progress);
  };
  st.evaluations = p.method == 1 ? run_field(FieldZB05{}) : run_field(FieldSSP07{});

  // Close the band where the surface leaves it (a triangulated cell with a
  // crossed face next to a cell that is not entirely in the band): add that
  // cell's corners, evaluate the new vertices only, repeat. The paper's band
  // has no such guarantee; without it real frames get holes.
  if (p.field == 0) {
    for (int round = 0;; ++round) {
      const std::vector<std::int64_t> leaks =
          find_band_leaks(space, view_of(band, g), band.n_blocks * 8, Kokkos::View<const float*, MemSpace>(phi.view()));
      trace("band leaks", leaks.size() / 3);
      if (leaks.empty()) break;
      if (round >= 1000) throw Error(9, "the narrow band did not close after 1000 growth rounds");
      Band<MemSpace> grown;
      extend_band(space, tracker, g, band, leaks, grown);
      Buffer<float, MemSpace> grown_phi(tracker, "scalar_field::values", grown.n_vertices);
      const BandView<MemSpace> old_view = view_of(band, g);
      const Kokkos::View<const float*, MemSpace> old_phi = phi.view();
      auto grow = [&](auto method) {
        return gather_field<decltype(method)>(space, nb, view_of(grown, g), grown.n_blocks * 8, g, fc,
                                              grown_phi.view(), progress, &old_view, old_phi);
      };
      st.evaluations += p.method == 1 ? grow(FieldZB05{}) : grow(FieldSSP07{});
      trace("band growth round", grown.n_vertices);
      band = std::move(grown);
      phi = std::move(grown_phi);
      st.band_growth_rounds = std::uint64_t(round + 1);
      st.band_growth_cells += leaks.size() / 3;
    }
  }
  lap(4);
  const BandView<MemSpace> bv = view_of(band, g);
  const std::size_t n_words = band.n_blocks * 8;
  st.band_vertices = band.n_vertices;
  st.band_blocks = p.field == 0 ? band.n_blocks : 0;

  // ---------------------------------------------------------- triangulation
  const McTables<MemSpace> tables = make_mc_tables(space);
  Buffer<std::uint32_t, MemSpace> info(tracker, "marching_cubes::info", band.n_vertices, true);
  Buffer<std::uint32_t, MemSpace> vert_offset(tracker, "marching_cubes::vertex_offsets", band.n_vertices);
  Buffer<std::uint64_t, MemSpace> tri_offset(tracker, "marching_cubes::triangle_offsets", n_words);
  const Kokkos::View<const float*, MemSpace> cphi = phi.view();
  const McResult r = classify_cells(space, bv, n_words, cphi, tables, info.view(), vert_offset.view(),
                                    tri_offset.view());
  if (r.vertices > std::numeric_limits<std::uint32_t>::max()) {
    std::ostringstream s;
    s << "the mesh would have " << r.vertices << " vertices, more than 32-bit indices can address";
    throw Error(5, s.str());
  }
  st.cells = r.cells;
  st.vertices = r.vertices;
  st.triangles = r.triangles;

  const std::uint64_t out_bytes =
      r.vertices * 3 * sizeof(float) * (p.normals ? 2 : 1) + r.triangles * 3 * sizeof(std::uint32_t);
  tracker.require(out_bytes, "the mesh");
  mesh.positions.resize(3 * r.vertices);
  mesh.normals.resize(p.normals ? 3 * r.vertices : 0);
  mesh.triangles.resize(3 * r.triangles);
  // Counted while nbmc builds it; released on every exit (a cancel in the
  // last stages too), since the mesh then belongs to the caller or is freed.
  struct Counted {
    MemoryTracker& t;
    std::uint64_t b;
    ~Counted() { t.sub(b); }
  } counted{tracker, out_bytes};
  tracker.add(out_bytes);
  using Unmanaged = Kokkos::MemoryTraits<Kokkos::Unmanaged>;
  Kokkos::View<float*, Kokkos::HostSpace, Unmanaged> hpos(mesh.positions.data(), mesh.positions.size());
  Kokkos::View<float*, Kokkos::HostSpace, Unmanaged> hnrm(mesh.normals.data(), mesh.normals.size());
  Kokkos::View<std::uint32_t*, Kokkos::HostSpace, Unmanaged> htri(mesh.triangles.data(), mesh.triangles.size());
  const Kokkos::View<const std::uint32_t*, MemSpace> cinfo = info.view(), cvoff = vert_offset.view();
  if constexpr (std::is_same<MemSpace, Kokkos::HostSpace>::value) {
    compute_vertices(space, bv, n_words, g, cphi, cinfo, cvoff, Kokkos::View<float*, MemSpace>(hpos),
                     Kokkos::View<float*, MemSpace>(hnrm), p.normals);
    compute_triangles(space, bv, n_words, tables, cinfo, cvoff,
                      Kokkos::View<const std::uint64_t*, MemSpace>(tri_offset.view()),
                      Kokkos::View<std::uint32_t*, MemSpace>(htri));
    lap(5);
  } else {
    Buffer<float, MemSpace> dpos(tracker, "mesh::positions", hpos.extent(0));
    Buffer<float, MemSpace> dnrm(tracker, "mesh::normals", hnrm.extent(0));
    Buffer<std::uint32_t, MemSpace> dtri(tracker, "mesh::triangles", htri.extent(0));
    compute_vertices(space, bv, n_words, g, cphi, cinfo, cvoff, dpos.view(), dnrm.view(), p.normals);
    compute_triangles(space, bv, n_words, tables, cinfo, cvoff,
                      Kokkos::View<const std::uint64_t*, MemSpace>(tri_offset.view()), dtri.view());
    lap(5);
    Kokkos::deep_copy(space, hpos, dpos.view());
    Kokkos::deep_copy(space, hnrm, dnrm.view());
    Kokkos::deep_copy(space, htri, dtri.view());
  }
  lap(6);
  st.total = total.seconds();
}

}  // namespace Details
}  // namespace nbmc
