// SPDX-License-Identifier: MIT
// The whole reconstruction (paper Alg. 1), templated on the execution space:
// upload -> neighbourhood -> surface particles -> band -> field -> marching cubes.
#pragma once

#include "band_growth.hpp"
#include "common.hpp"
#include "field_methods.hpp"
#include "grid.hpp"
#include "marching_cubes.hpp"
#include "mesh_incidence.hpp"
#include "narrow_band.hpp"
#include "neighbourhood.hpp"
#include "radii.hpp"
#include "scalar_field.hpp"
#include "sph_density.hpp"
#include "yt10_kernels.hpp"
#include "surface_particles.hpp"
#include "../../src/core/mesh_incidence.hpp"
#include "../../src/core/piece.hpp"

#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <sstream>
#include <type_traits>
#include <vector>

namespace nbmc {

// The mesh as the C API hands it out: in host vectors, or (CUDA backend,
// NBMC_MEMORY_DEVICE) in one device allocation owned by `device`.
struct HostMesh {
  // positions: 3 floats per vertex, or, in a mesh made with double positions
  // (f64), empty until the C API rounds positions64 into it on demand.
  std::vector<float, NoInitAllocator<float>> positions, normals;
  std::vector<double, NoInitAllocator<double>> positions64;
  bool f64 = false;
  std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>> triangles;
  bool on_device = false;
  std::shared_ptr<void> device;
  float* d_positions = nullptr;
  float* d_normals = nullptr;
  std::uint32_t* d_triangles = nullptr;
  std::uint64_t d_vertices = 0, d_triangles_count = 0;
  // With Params::prebuilt_incidence, from the CUDA pipeline (a whole frame,
  // mesh in host memory): the clean-up's incidence of this mesh
  // (mesh_incidence.hpp). Only for the mesh as the pipeline made it: the
  // clean-up takes it (capi_mesh.cpp); anything else that changes the
  // triangles must clear it.
  mesh::PrebuiltIncidence incidence;
  // A piece of a frame reconstructed over several processes: per vertex, its
  // id in the whole mesh (the same on every process that has the vertex).
  std::vector<std::uint64_t> global_ids;
  std::uint64_t global_vertex_count = 0;
  std::uint64_t vertex_count() const {
    return on_device ? d_vertices : (f64 ? positions64.size() : positions.size()) / 3;
  }
  std::uint64_t triangle_count() const { return on_device ? d_triangles_count : triangles.size() / 3; }
};

// A subdomain's part of a frame (src/subdomains.cpp): the frame's grid, the
// vertex box its band stays in, the cells it owns (triangulates), cells the
// band must contain from the start (grown by its neighbours), and what comes
// back besides the mesh.
struct Region {
  Grid grid;
  std::int64_t vert_lo[3] = {0, 0, 0}, vert_hi[3] = {0, 0, 0};  // inclusive
  std::int64_t cell_lo[3] = {0, 0, 0}, cell_hi[3] = {0, 0, 0};  // half-open
  std::vector<std::int64_t> seeds;  // cells (minimum corners, x y z triples)
  Piece* piece = nullptr;           // receives the vertex and triangle keys
  std::vector<std::int64_t> grown;  // out: the cells the band growth added
};

// The particles of a reconstruction: absolute positions, 3 doubles each, in
// host memory or (on_device) in the memory of the CUDA execution space; with
// a region, one subdomain's particles and ghosts (host memory). With
// per-particle radii (Params::radius_ref > 0), radii holds one radius per
// particle, in host memory, in the order of xyz.
struct ParticleInput {
  const double* xyz = nullptr;
  std::size_t count = 0;
  bool on_device = false;
  Region* region = nullptr;
  const double* radii = nullptr;
};

#if defined(KOKKOS_ENABLE_CUDA)
// Device memory outside Kokkos' bookkeeping (pipeline_cuda.cpp): for meshes
// handed to the caller, which may outlive the Kokkos runtime.
std::shared_ptr<void> cuda_allocate(std::size_t bytes, const char* what);
// Gives mesh one device allocation the caller owns (positions, normals when
// asked, triangles) and sets its device pointers and counts.
void allocate_device_mesh(HostMesh& mesh, std::uint64_t vertices, std::uint64_t triangles, bool normals);
#endif

struct RunStats {
  std::uint64_t particles = 0, surface_particles = 0, occupied_cells = 0, band_vertices = 0, band_blocks = 0,
                grid_vertices = 0, cells = 0, vertices = 0, triangles = 0, evaluations = 0;
  std::uint64_t band_growth_rounds = 0, band_growth_cells = 0;
  std::uint64_t dropped_particles = 0, dropped_clusters = 0;  // isolated-particle filter (run_backend)
  std::uint64_t dims[3] = {0, 0, 0};
  double stage[16] = {0};
  double total = 0;
  double origin[3] = {0, 0, 0};
  double cell = 0;
};

namespace Details {

// The bounding box extended by particle_reach (R; 2R for SPH and YT10):
// the particles a clipped reconstruction keeps (host and device paths).
struct ExtendedBox {
  double lo[3], hi[3];
  explicit ExtendedBox(const Params& p) {
    for (int a = 0; a < 3; ++a) {
      lo[a] = p.bbox_min[a] - particle_reach(p);
      hi[a] = p.bbox_max[a] + particle_reach(p);
    }
  }
  KOKKOS_INLINE_FUNCTION bool contains(double x, double y, double z) const {
    return x >= lo[0] && x <= hi[0] && y >= lo[1] && y <= hi[1] && z >= lo[2] && z <= hi[2];
  }
};

// Bounds of positions (3 per particle) in one reduction: value v[0..2] the
// minima, v[3..5] the negated maxima (so that every entry is a minimum).
template <class MemSpace>
struct BoundsReduce {
  Kokkos::View<const double*, MemSpace> xyz;
  using value_type = double[];
  static constexpr unsigned value_count = 6;
  KOKKOS_INLINE_FUNCTION void init(double* v) const {
    for (int a = 0; a < 6; ++a) v[a] = Kokkos::Experimental::infinity<double>::value;
  }
  KOKKOS_INLINE_FUNCTION void join(volatile double* v, const volatile double* w) const {
    for (int a = 0; a < 6; ++a)
      if (w[a] < v[a]) v[a] = w[a];
  }
  KOKKOS_INLINE_FUNCTION void operator()(const std::size_t i, double* v) const {
    for (int a = 0; a < 3; ++a) {
      const double x = xyz(3 * i + a);
      if (x < v[a]) v[a] = x;
      if (-x < v[3 + a]) v[3 + a] = -x;
    }
  }
};

template <class ExecSpace>
void reconstruct(const ExecSpace& space, const ParticleInput& in, const Params& p, MemoryTracker& tracker,
                 const Progress& progress, bool mesh_on_device, HostMesh& mesh, RunStats& st) {
  using MemSpace = typename ExecSpace::memory_space;
  constexpr bool host_memory = Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible;
  const double* const xyz = in.xyz;
  const std::size_t count = in.count;
  if (host_memory && (in.on_device || mesh_on_device))
    throw Error(7, "device memory needs the CUDA backend");
  Region* const region_in = in.region;
  if (region_in && (in.on_device || mesh_on_device || p.use_bbox || p.field != FieldKind::NarrowBand))
    throw Error(9, "a subdomain takes host particles, a host mesh, no clipping box and the narrow band");
  // Bounds are needed unless the grid is given (a subdomain) or the box sets it.
  const bool need_bounds = !p.use_bbox && !region_in;
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
  trace("upload: start");
  progress(0, 0.0);
  std::vector<std::uint32_t> keep;
  double lo[3] = {std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
                  std::numeric_limits<double>::max()};
  double hi[3] = {-lo[0], -lo[1], -lo[2]};
  // Device path: the positions on the device (copied there if they are on
  // the host), the bounds and the bounding-box selection computed there.
  Buffer<double, MemSpace> staged;
  Kokkos::View<const double*, MemSpace> dxyz;
  Buffer<std::uint32_t, MemSpace> dkeep;
  std::size_t n_used = count;
  const ExtendedBox box(p);
  if constexpr (!host_memory) {
    using Range = Kokkos::RangePolicy<ExecSpace>;
    if (in.on_device) {
      dxyz = Kokkos::View<const double*, MemSpace, Kokkos::MemoryTraits<Kokkos::Unmanaged>>(xyz, 3 * count);
    } else {
      staged = Buffer<double, MemSpace>(tracker, "particles::device_copy", 3 * count);
      trace("upload: allocate", count);
      Kokkos::deep_copy(space, staged.view(),
                        Kokkos::View<const double*, Kokkos::HostSpace, Kokkos::MemoryTraits<Kokkos::Unmanaged>>(
                            xyz, 3 * count));
      trace("upload: copy", count);
      dxyz = staged.view();
    }
    const Kokkos::View<const double*, MemSpace> dx = dxyz;
    if (p.use_bbox) {
      std::uint64_t kept = 0;
      Kokkos::parallel_reduce(
          "nbmc::upload::count_in_box", Range(space, 0, count),
          KOKKOS_LAMBDA(const std::size_t i, std::uint64_t& c) {
            c += box.contains(dx(3 * i), dx(3 * i + 1), dx(3 * i + 2)) ? 1 : 0;
          },
          kept);
      n_used = std::size_t(kept);
      if (kept) {
        dkeep = Buffer<std::uint32_t, MemSpace>(tracker, "particles::kept", kept);
        const auto kv = dkeep.view();
        Kokkos::parallel_scan(
            "nbmc::upload::select_in_box", Range(space, 0, count),
            KOKKOS_LAMBDA(const std::size_t i, std::uint64_t& c, const bool final) {
              const bool inside = box.contains(dx(3 * i), dx(3 * i + 1), dx(3 * i + 2));
              if (final && inside) kv(c) = std::uint32_t(i);
              c += inside ? 1 : 0;
            });
      }
    } else if (need_bounds) {
      // One pass for the three axes (three MinMax reductions took 112 µs
      // for the 1.65 M frame on an H100). Minima and maxima are exact in
      // any order.
      double b[6];
      Kokkos::parallel_reduce("nbmc::upload::bounds", Range(space, 0, count), BoundsReduce<MemSpace>{dx}, b);
      trace("upload: bounds", count);
      for (int a = 0; a < 3; ++a) {
        lo[a] = b[a];
        hi[a] = -b[3 + a];
      }
    }
  } else if (p.use_bbox) {
    for (std::size_t i = 0; i < count; ++i)
      if (box.contains(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2])) keep.push_back(std::uint32_t(i));
    n_used = keep.size();
  } else if (need_bounds) {
    for (std::size_t i = 0; i < count; ++i)
      for (int a = 0; a < 3; ++a) {
        const double x = xyz[3 * i + a];
        lo[a] = x < lo[a] ? x : lo[a];
        hi[a] = x > hi[a] ? x : hi[a];
      }
  }
  if (p.use_bbox) {
    if (n_used == 0) throw Error(3, "no particle lies within the bounding box (extended by the influence radius)");
    for (int a = 0; a < 3; ++a) {
      lo[a] = p.bbox_min[a];
      hi[a] = p.bbox_max[a];
    }
  }
  const Grid g = region_in ? region_in->grid : make_grid(lo, hi, p);
  st.particles = n_used;
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
    // host: sort records; device: unsorted positions, keys and two key/order
    // pairs for the radix sort; then the sorted positions, the permutation,
    // the surface flags and the cells.
    const std::uint64_t sort_bytes = host_memory ? sizeof(SortRecord) : 3 * sizeof(float) + 8 + 2 * (8 + 4);
    std::uint64_t need = n * (sort_bytes + 3 * sizeof(float) + sizeof(std::uint32_t) + 1) + n / 2 * 24;
    if (p.radius_ref > 0) need += n * 3 * sizeof(float) + (host_memory ? 0 : count * sizeof(double));
    if (p.field != FieldKind::NarrowBand) {
      const std::uint64_t nv = g.vertex_count();
      need += nv * 14;  // field value, cell info, vertex numbering, bitmap
      if (p.field == FieldKind::Scatter) need += nv * 4 * std::uint64_t(field_state_floats(p.method, p.radius_ref > 0));
    }
    tracker.require(need, p.field == FieldKind::NarrowBand ? "the neighbourhood" : "the dense baseline grid (estimated)");
  }

  // ---------------------------------------------------------- neighbourhood
  // Per-particle radii (radii.hpp): they order coincident particles, then
  // give every particle its lengths.
  const bool radii = p.radius_ref > 0;
  Buffer<double, MemSpace> radii_copy;
  Kokkos::View<const double*, MemSpace> radii_in =
      radii ? radii_view(space, tracker, in.radii, count, radii_copy) : Kokkos::View<const double*, MemSpace>();
  Neighbourhood<MemSpace> nbh;
  if constexpr (host_memory) {
    build_neighbourhood(space, tracker, xyz, count, keep, g, nbh, radii ? in.radii : nullptr);
  } else {
    build_neighbourhood_device(space, tracker, dxyz, Kokkos::View<const std::uint32_t*, MemSpace>(dkeep.view()),
                               n_used, g, nbh, radii_in);
    dkeep.release();
    staged.release();
    dxyz = Kokkos::View<const double*, MemSpace>();
  }
  if (radii) attach_radii(space, tracker, radii_in, p, nbh);
  radii_in = Kokkos::View<const double*, MemSpace>();
  radii_copy.release();
  const NeighbourView<MemSpace> nb = view_of(nbh, g);
  st.occupied_cells = nbh.n_cells;
  lap(1);

  // ------------------------------------------------ surface particles, band
  Band<MemSpace> band;
  if (p.field == FieldKind::NarrowBand) {
    Buffer<std::uint8_t, MemSpace> flags(tracker, "surface_particles::flags", nbh.n);
    st.surface_particles = mark_surface_particles(
        space, nb, Kokkos::View<const std::uint64_t*, MemSpace>(nbh.cell_keys.view()), nbh.n_cells, p, g, flags.view(),
        &tracker);
    if (region_in) {
      // A subdomain counts the surface particles in its own cells only, so
      // that the counts of all subdomains add up to the frame's.
      const auto pos = nbh.pos.view();
      const auto fl = flags.view();
      const std::size_t n = nbh.n;
      const float inv_c = float(1.0 / g.cell);
      std::int64_t lo_c[3], hi_c[3];
      for (int a = 0; a < 3; ++a) {
        lo_c[a] = region_in->cell_lo[a];
        hi_c[a] = region_in->cell_hi[a];
      }
      const std::int64_t l0 = lo_c[0], l1 = lo_c[1], l2 = lo_c[2], h0 = hi_c[0], h1 = hi_c[1], h2 = hi_c[2];
      std::uint64_t owned = 0;
      Kokkos::parallel_reduce(
          "nbmc::surface_particles::owned", Kokkos::RangePolicy<ExecSpace>(space, 0, n),
          KOKKOS_LAMBDA(const std::size_t i, std::uint64_t& acc) {
            if (!fl(i)) return;
            const std::int64_t ci = std::int64_t(Kokkos::Experimental::floor(pos(i) * inv_c)),
                               cj = std::int64_t(Kokkos::Experimental::floor(pos(n + i) * inv_c)),
                               ck = std::int64_t(Kokkos::Experimental::floor(pos(2 * n + i) * inv_c));
            acc += (ci >= l0 && ci < h0 && cj >= l1 && cj < h1 && ck >= l2 && ck < h2) ? 1 : 0;
          },
          owned);
      st.surface_particles = owned;
    }
    lap(2);
    if (region_in)
      for (int a = 0; a < 3; ++a) {
        band.clip_lo[a] = region_in->vert_lo[a];
        band.clip_hi[a] = region_in->vert_hi[a];
        band.own_lo[a] = region_in->cell_lo[a];
        band.own_hi[a] = region_in->cell_hi[a];
      }
    build_narrow_band(space, tracker, g, p, Kokkos::View<const float*, MemSpace>(nbh.pos.view()),
                      Kokkos::View<const std::uint8_t*, MemSpace>(flags.view()), nbh.n, band,
                      Kokkos::View<const float*, MemSpace>(nbh.scale.view()));
    if (region_in && !region_in->seeds.empty()) {
      // Cells its neighbours' band growth added near this subdomain.
      Band<MemSpace> seeded;
      extend_band(space, tracker, g, band, region_in->seeds, seeded);
      band = std::move(seeded);
    }
  } else {
    lap(2);
    build_dense_band(space, tracker, g, band);
  }
  lap(3);

  // ------------------------------------------------------------------ field
  {  // the per-vertex arrays of the field and of marching cubes, before allocating them
    const std::uint64_t need = band.n_vertices * (sizeof(float) + 3 * sizeof(std::uint32_t));
    tracker.require(need, "the field and triangulation of " + std::to_string(band.n_vertices) +
                              " band vertices (estimated)");
  }
  FieldConstants fc = field_constants(p.influence_radius, p.iso_radius, p.t_low, p.t_high, p.iso_threshold,
                                      guard_ratio(p));
  // The passes over the particles: the SPH density's weights, YT10's kernels
  // (which also narrow the radius the field visits; YT10 has no radii
  // variant, params.hpp refuses it with per-particle radii).
  SphWeights<MemSpace> sph;
  auto sph_update = [&] {
    if (radii) sph.template update<true>(space, nbh, g, fc);
    else sph.template update<false>(space, nbh, g, fc);
  };
  if (p.method == Method::SPH) {  // the band's reach (every particle for the other fields)
    sph.start(tracker, nbh, g, p.field != FieldKind::NarrowBand);
    sph.add_words(space, view_of(band, g), band.n_blocks * 8, {});
    sph_update();
  }
  Yt10Kernels<MemSpace> yt10;
  const FieldConstants fc_r = fc;  // YT10's kernels are summed over R; fc's radius becomes R_f
  if (p.method == Method::YT10) {  // the band's reach (every particle for the other fields)
    yt10.start(tracker, nbh, g, p.field != FieldKind::NarrowBand);
    yt10.add_words(space, view_of(band, g), band.n_blocks * 8, {});
    fc = yt10.update(space, nbh, g, p, fc_r);
  }
  const NeighbourView<MemSpace> nbf = view_of(nbh, g);
  Buffer<float, MemSpace> phi(tracker, "scalar_field::values", band.n_vertices);
  const BandView<MemSpace> bv0 = view_of(band, g);
  const std::size_t n_words0 = band.n_blocks * 8;
  auto run_field = [&](auto method) {
    using Method = decltype(method);
    if (p.field == FieldKind::Scatter) {
      if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible) {
        return scatter_field<Method>(space, tracker, Kokkos::View<const float*, Kokkos::HostSpace>(nbh.pos.view()),
                                     Kokkos::View<const float*, Kokkos::HostSpace>(nbh.pdata.view()),
                                     Kokkos::View<const float*, Kokkos::HostSpace>(nbh.support.view()), nbh.n, bv0,
                                     n_words0, g, fc, phi.view(), progress);
      } else {
        throw Error(4, "the scatter baseline runs on the CPU backends only");
        return std::uint64_t(0);
      }
    }
    return gather_field<Method>(space, nbf, bv0, n_words0, g, fc, phi.view(), progress);
  };
  st.evaluations = with_field_method(p.method, radii, run_field);

  // Close the band where the surface leaves it (a triangulated cell with a
  // crossed face next to a cell that is not entirely in the band): add that
  // cell's corners, evaluate the new vertices only, repeat. The paper's band
  // has no such guarantee; without it real frames get holes.
  // The growth runs on the execution space (band_growth.hpp: one small
  // device-to-host copy per round).
  if (p.field == FieldKind::NarrowBand) {
    GrowthTotals totals;
    if (region_in) totals.grown_cells = &region_in->grown;
    const GrowthEvaluate<MemSpace> evaluate = [&](const BandView<MemSpace>& bv, std::size_t n_list,
                                                  const WordList<MemSpace>& list,
                                                  const Kokkos::View<float*, MemSpace>& out,
                                                  const Kokkos::View<unsigned long long*, MemSpace>& sink) {
      if (p.method == Method::SPH) {  // the new vertices' particles
        sph.add_words(space, bv, n_list, list.words);
        sph_update();
      }
      if (p.method == Method::YT10) {
        yt10.add_words(space, bv, n_list, list.words);
        fc = yt10.update(space, nbh, g, p, fc_r);
      }
      auto grow = [&](auto method) {
        return gather_field<decltype(method)>(space, nbf, bv, n_list, g, fc, out, progress, list, sink);
      };
      return std::uint64_t(with_field_method(p.method, radii, grow));
    };
    grow_band(space, tracker, g, band, phi, evaluate, totals);
    if (totals.rounds) st.band_growth_rounds = totals.rounds;
    st.band_growth_cells += totals.cells;
    st.evaluations += totals.evaluations;
  }
  lap(4);
  // The gathers' extra copies (float4 positions, sub-cell splits) are not
  // needed past the field: give their memory back before the triangulation,
  // the stage of the peak (nb and nbf are not used from here on).
  nbh.pos4.release();
  nbh.dense_sub.release();
  const BandView<MemSpace> bv = view_of(band, g);
  const std::size_t n_words = band.n_blocks * 8;
  st.band_vertices = band.n_vertices;
  st.band_blocks = p.field == FieldKind::NarrowBand ? band.n_blocks : 0;

  // ---------------------------------------------------------- triangulation
  const McTables<MemSpace> tables = make_mc_tables(space);
  Buffer<std::uint32_t, MemSpace> info(tracker, "marching_cubes::info", band.n_vertices, true);
  Buffer<std::uint32_t, MemSpace> vert_offset(tracker, "marching_cubes::vertex_offsets", band.n_vertices);
  Buffer<std::uint32_t, MemSpace> tri_offset(tracker, "marching_cubes::triangle_offsets", band.n_vertices, true);
  const Kokkos::View<const float*, MemSpace> cphi = phi.view();
  const McResult r = classify_cells(space, tracker, bv, n_words, cphi, tables, info.view(), vert_offset.view(),
                                    tri_offset.view());
  if (r.vertices > std::numeric_limits<std::uint32_t>::max() || r.triangles > std::numeric_limits<std::uint32_t>::max()) {
    std::ostringstream s;
    s << "the mesh would have " << r.vertices << " vertices and " << r.triangles
      << " triangles, more than 32-bit indices and offsets can address";
    throw Error(5, s.str());
  }
  st.cells = r.cells;
  st.vertices = r.vertices;
  st.triangles = r.triangles;

  // Positions in float, or in double with p.double_positions (host meshes).
  if (p.double_positions && mesh_on_device)
    throw Error(4, "double_positions: the mesh must be in host memory (not NBMC_MEMORY_DEVICE)");
  const std::uint64_t pos_size = p.double_positions ? sizeof(double) : sizeof(float);
  // On the GPU, for the clean-up of a whole frame's host mesh: its
  // incidence, built on the device and downloaded with the mesh.
#if defined(KOKKOS_ENABLE_CUDA)
  constexpr bool is_cuda = std::is_same<ExecSpace, Kokkos::Cuda>::value;
#else
  constexpr bool is_cuda = false;
#endif
  // (An optimisation: left out where it would pass the memory budget, which
  // it counts twice, on the device (with its fill cursors) and the host.)
  const std::uint64_t mesh_bytes = r.vertices * 3 * (pos_size + (p.normals ? sizeof(float) : 0)) +
                                   r.triangles * 3 * sizeof(std::uint32_t);
  const bool prebuilt = is_cuda && p.prebuilt_incidence && !region_in && !mesh_on_device &&
                        DeviceIncidence<ExecSpace>::wanted(tracker, mesh_bytes, r.vertices, r.triangles);
  const std::uint64_t out_bytes =
      mesh_bytes + (prebuilt ? mesh::PrebuiltIncidence::words(r.vertices, r.triangles) * sizeof(std::uint32_t) : 0);
  tracker.require(out_bytes, "the mesh");
  if (!mesh_on_device) {
    mesh.f64 = p.double_positions;
    if (p.double_positions) mesh.positions64.resize(3 * r.vertices);
    else mesh.positions.resize(3 * r.vertices);
    mesh.normals.resize(p.normals ? 3 * r.vertices : 0);
    mesh.triangles.resize(3 * r.triangles);
  }
  // Counted while nbmc builds it; released on every exit (a cancel in the
  // last stages too), since the mesh then belongs to the caller or is freed.
  struct Counted {
    MemoryTracker& t;
    std::uint64_t b;
    ~Counted() { t.sub(b); }
  } counted{tracker, out_bytes};
  tracker.add(out_bytes);
  using Unmanaged = Kokkos::MemoryTraits<Kokkos::Unmanaged>;
  // A subdomain's piece: the keys that place its vertices and triangles in
  // the frame's mesh (host memory, like the rest of the piece).
  Kokkos::View<std::uint64_t*, Kokkos::HostSpace, Unmanaged> hvkeys, htkeys;
  Kokkos::View<std::uint8_t*, Kokkos::HostSpace, Unmanaged> haxes;
  if (region_in && region_in->piece) {
    Piece& pc = *region_in->piece;
    pc.vertex_keys.resize(r.vertices);
    pc.vertex_axes.resize(r.vertices);
    pc.triangle_cells.resize(r.triangles);
    hvkeys = decltype(hvkeys)(pc.vertex_keys.data(), pc.vertex_keys.size());
    haxes = decltype(haxes)(pc.vertex_axes.data(), pc.vertex_axes.size());
    htkeys = decltype(htkeys)(pc.triangle_cells.data(), pc.triangle_cells.size());
  }
  Kokkos::View<float*, Kokkos::HostSpace, Unmanaged> hnrm(mesh.normals.data(), mesh.normals.size());
  Kokkos::View<std::uint32_t*, Kokkos::HostSpace, Unmanaged> htri(mesh.triangles.data(), mesh.triangles.size());
  const Kokkos::View<const std::uint32_t*, MemSpace> cinfo = info.view(), cvoff = vert_offset.view();
  // The vertices and triangles, with Real (float or double) positions.
  auto triangulate = [&](auto* host_positions, std::size_t n_positions) {
    using Real = std::remove_pointer_t<decltype(host_positions)>;
    Kokkos::View<Real*, Kokkos::HostSpace, Unmanaged> hpos(host_positions, n_positions);
    if constexpr (std::is_same<MemSpace, Kokkos::HostSpace>::value) {
      compute_vertices(space, bv, n_words, g, cphi, cinfo, cvoff, Kokkos::View<Real*, MemSpace>(hpos),
                       Kokkos::View<float*, MemSpace>(hnrm), p.normals, Kokkos::View<std::uint64_t*, MemSpace>(hvkeys),
                       Kokkos::View<std::uint8_t*, MemSpace>(haxes));
      compute_triangles(space, bv, n_words, tables, cinfo, cvoff,
                        Kokkos::View<const std::uint32_t*, MemSpace>(tri_offset.view()),
                        Kokkos::View<std::uint32_t*, MemSpace>(htri), Kokkos::View<std::uint64_t*, MemSpace>(htkeys));
      lap(5);
    } else if (mesh_on_device) {
#if defined(KOKKOS_ENABLE_CUDA)
      allocate_device_mesh(mesh, r.vertices, r.triangles, p.normals);
      const std::size_t np = 3 * std::size_t(r.vertices), nn = p.normals ? np : 0, nt = 3 * std::size_t(r.triangles);
      Kokkos::View<float*, MemSpace, Unmanaged> dpos(mesh.d_positions, np), dnrm(mesh.d_normals, nn);
      Kokkos::View<std::uint32_t*, MemSpace, Unmanaged> dtri(mesh.d_triangles, nt);
      compute_vertices(space, bv, n_words, g, cphi, cinfo, cvoff, Kokkos::View<float*, MemSpace>(dpos),
                       Kokkos::View<float*, MemSpace>(dnrm), p.normals);
      compute_triangles(space, bv, n_words, tables, cinfo, cvoff,
                        Kokkos::View<const std::uint32_t*, MemSpace>(tri_offset.view()),
                        Kokkos::View<std::uint32_t*, MemSpace>(dtri));
      lap(5);
#else
      throw Error(7, "device memory needs the CUDA backend");
#endif
    } else {
      Buffer<Real, MemSpace> dpos(tracker, "mesh::positions", hpos.extent(0));
      Buffer<float, MemSpace> dnrm(tracker, "mesh::normals", hnrm.extent(0));
      Buffer<std::uint32_t, MemSpace> dtri(tracker, "mesh::triangles", htri.extent(0));
      Buffer<std::uint64_t, MemSpace> dvkeys(tracker, "mesh::vertex_keys", hvkeys.extent(0));
      Buffer<std::uint8_t, MemSpace> daxes(tracker, "mesh::vertex_axes", haxes.extent(0));
      Buffer<std::uint64_t, MemSpace> dtkeys(tracker, "mesh::triangle_cells", htkeys.extent(0));
      compute_vertices(space, bv, n_words, g, cphi, cinfo, cvoff, dpos.view(), dnrm.view(), p.normals, dvkeys.view(),
                       daxes.view());
      compute_triangles(space, bv, n_words, tables, cinfo, cvoff,
                        Kokkos::View<const std::uint32_t*, MemSpace>(tri_offset.view()), dtri.view(), dtkeys.view());
      lap(5);
#if defined(KOKKOS_ENABLE_CUDA)
      if constexpr (std::is_same<ExecSpace, Kokkos::Cuda>::value) {
        mesh::PrebuiltIncidence& inc = mesh.incidence;
        DeviceIncidence<ExecSpace> di;
        if (prebuilt && di.template build<Real>(space, tracker, dpos.view(), dtri.view(), r.vertices, r.triangles, inc)) {
          trace("incidence on the device", r.triangles);
          if (di.template move_rounds<Real>(space, tracker, dpos.view(), dtri.view(), r.vertices, r.triangles, inc))
            trace("moves on the device", inc.moves);
        }
        const DownloadSegment segments[] = {
            {hpos.data(), dpos.data(), hpos.extent(0) * sizeof(Real)},
            {hnrm.data(), dnrm.data(), hnrm.extent(0) * sizeof(float)},
            {htri.data(), dtri.data(), htri.extent(0) * sizeof(std::uint32_t)},
            {hvkeys.data(), dvkeys.data(), hvkeys.extent(0) * sizeof(std::uint64_t)},
            {haxes.data(), daxes.data(), haxes.extent(0) * sizeof(std::uint8_t)},
            {htkeys.data(), dtkeys.data(), htkeys.extent(0) * sizeof(std::uint64_t)},
            {inc.start.data(), di.start.data(), inc.start.size() * sizeof(std::uint32_t)},
            {inc.incident.data(), di.incident.data(), inc.incident.size() * sizeof(std::uint32_t)},
            {inc.maybe_bad.data(), di.bits.data(), inc.maybe_bad.size() * sizeof(std::uint32_t)}};
        download_segments(space, segments, sizeof(segments) / sizeof(segments[0]));
        return;
      }
#endif
      if (hvkeys.extent(0)) {
        Kokkos::deep_copy(space, hvkeys, dvkeys.view());
        Kokkos::deep_copy(space, haxes, daxes.view());
      }
      if (htkeys.extent(0)) Kokkos::deep_copy(space, htkeys, dtkeys.view());
      // The host vectors are fresh, uninitialised memory: touch their pages
      // with all host threads first (single-threaded page faults inside the
      // copy cost 20 ms for the 40 MB mesh of the 1.65 M frame at r/2).
      {
        using HostExec = Kokkos::DefaultHostExecutionSpace;
        auto touch = [](void* data, std::size_t bytes) {
          if (!bytes) return;
          char* base = static_cast<char*>(data);
          const std::size_t pages = (bytes + 4095) / 4096;
          Kokkos::parallel_for(
              "nbmc::mesh::first_touch", Kokkos::RangePolicy<HostExec>(0, pages),
              [=](const std::size_t q) { base[q * 4096] = 0; });
        };
        touch(hpos.data(), hpos.extent(0) * sizeof(Real));
        touch(hnrm.data(), hnrm.extent(0) * sizeof(float));
        touch(htri.data(), htri.extent(0) * sizeof(std::uint32_t));
        HostExec().fence();
      }
      Kokkos::deep_copy(space, hpos, dpos.view());
      Kokkos::deep_copy(space, hnrm, dnrm.view());
      Kokkos::deep_copy(space, htri, dtri.view());
    }
  };
  if (p.double_positions) triangulate(mesh.positions64.data(), mesh.positions64.size());
  else triangulate(mesh.positions.data(), mesh.positions.size());
  lap(6);
  st.total = total.seconds();
}

}  // namespace Details
}  // namespace nbmc
