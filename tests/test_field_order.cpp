// SPDX-License-Identifier: MIT
// The host backends must sum in the order the GPU does, so that CPU and GPU
// give the same mesh bit for bit (the CUDA build compiles without FMA
// contraction). The GPU evaluates each band vertex on its own
// (gather_words_direct -> eval_vertex_direct): the neighbour cells of
// cell_span(x, x, R) in z, y, x order, skipping cells whose box is R or
// farther, the particles of a cell in their sorted order, one plain float sum
// per accumulator. The surface-particle test sums, per particle i, over the
// cells around its cell in z, y, x order and their particles in order.
//
// These tests build the pipeline's stages on the host (Serial and OpenMP)
// and check, bit for bit, every band vertex's value from gather_field (the
// host tile path) and every surface flag against plain serial references
// written here, which follow that order literally; with per-particle radii
// too (the methods' radii variants, radii.hpp: each particle's own support).
#include <gtest/gtest.h>

#include "common.hpp"
#include "field_sph.hpp"
#include "field_ssp07.hpp"
#include "field_yt10.hpp"
#include "field_zb05.hpp"
#include "grid.hpp"
#include "narrow_band.hpp"
#include "neighbourhood.hpp"
#include "radii.hpp"
#include "scalar_field.hpp"
#include "sph_density.hpp"
#include "surface_particles.hpp"
#include "yt10_kernels.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

// The library's definition is not exported; the stages only report progress.
void nbmc::Progress::operator()(int, double) const {}

namespace {

using namespace nbmc;
using namespace nbmc::Details;
using Host = Kokkos::HostSpace;
using Points = std::vector<double>;

class KokkosEnv : public ::testing::Environment {
 public:
  void SetUp() override {
    Kokkos::InitArguments args;
    args.num_threads = 3;  // an odd split of the work on any machine
    Kokkos::initialize(args);
    // ctest's FieldOrder.EightLanes asks for 8 lanes: skipped where the CPU
    // cannot run them (host_simd_lanes gives fewer).
    const char* e = std::getenv("NBMC_HOST_SIMD");
    if (e && std::atoi(e) > host_simd_lanes())
      GTEST_SKIP() << "NBMC_HOST_SIMD=" << e << ": lanes not available on this CPU";
  }
  void TearDown() override { Kokkos::finalize(); }
};
const ::testing::Environment* const kokkos_env = ::testing::AddGlobalTestEnvironment(new KokkosEnv);

std::uint32_t bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

// ------------------------------------------------------------ particle sets
Points random_cloud(double r, std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  const double side = r * std::cbrt(double(n));  // about one particle per r^3
  std::uniform_real_distribution<double> u(0.0, side);
  Points p;
  for (std::size_t i = 0; i < 3 * n; ++i) p.push_back(u(rng) + 0.3);
  return p;
}

Points jittered_ball(double cx, double cy, double cz, double radius, double r, double jitter, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-jitter * r, jitter * r);
  Points p;
  const int m = int(std::ceil(radius / r));
  for (int k = -m; k <= m; ++k)
    for (int j = -m; j <= m; ++j)
      for (int i = -m; i <= m; ++i) {
        const double x = i * r, y = j * r, z = k * r;
        if (x * x + y * y + z * z > radius * radius) continue;
        p.insert(p.end(), {cx + x + u(rng), cy + y + u(rng), cz + z + u(rng)});
      }
  return p;
}

// A ball plus a clump of `crowd` particles within 0.2 r of a point on its
// surface: far beyond any tile's particle budget, and beyond kCrowdedCell.
Points crowded(double r, std::size_t crowd) {
  Points p = jittered_ball(0, 0, 0, 12 * r, r, 0.2, 7);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.2 * r, 0.2 * r);
  for (std::size_t i = 0; i < crowd; ++i) p.insert(p.end(), {12 * r + u(rng), u(rng), u(rng)});
  return p;
}

Points read_xyz(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::vector<float> v;
  if (!f) return {};
  f.seekg(0, std::ios::end);
  v.resize(std::size_t(f.tellg()) / 4);
  f.seekg(0);
  f.read(reinterpret_cast<char*>(v.data()), std::streamsize(v.size() * 4));
  return Points(v.begin(), v.end());
}

Params make_params(double r, double cell, int method) {
  Params p;  // the C API's defaults (src/capi.cpp), in absolute units
  p.spacing = r;
  p.cell_size = cell * r;
  p.influence_radius = 4 * r;
  p.band_width = 2 * r;
  p.surface_radius = 2 * r;
  p.iso_radius = r;
  p.max_distance = 1.5 * r;  // the distance guard (its k_max in every backend's sums)
  p.method = nbmc::Method(method);
  return p;
}

// ------------------------------------------------------ serial references
// Surface flags of the particles of neighbour cell `cell`, as
// surface_particles_of_cell defines them, with every sum in plain order.
// With radii (nb.scale): particle i's own h_i, each neighbour's volume t_j^3
// (scale is then (r_max / h)^3 * 945 / (32 pi), h_abs = h).
std::size_t reference_surface(const NeighbourView<Host>& nb, const std::vector<std::uint64_t>& keys, std::size_t cell,
                              int range, float h, float scale, float threshold, int min_neighbours,
                              std::vector<std::uint8_t>& flags, std::vector<float>& grad, double h_abs) {
  const std::uint32_t first = nb.cell_start(cell), last = nb.cell_start(cell + 1);
  if (last - first > kCrowdedCell) {
    for (std::uint32_t i = first; i < last; ++i) flags[i] = 1;
    return last - first;
  }
  std::vector<std::pair<std::uint32_t, std::uint32_t>> ranges;
  bool face_empty = false;
  std::int64_t cx, cy, cz;
  neighbour_cell_of_key(keys[cell], nb.nb_dims, cx, cy, cz);
  for (std::int64_t z = cz - range; z <= cz + range; ++z)
    for (std::int64_t y = cy - range; y <= cy + range; ++y)
      for (std::int64_t x = cx - range; x <= cx + range; ++x) {
        if (x < 0 || y < 0 || z < 0 || x >= nb.nb_dims[0] || y >= nb.nb_dims[1] || z >= nb.nb_dims[2]) continue;
        std::uint32_t b, e;
        if (nb.cell_range(x, y, z, b, e))
          ranges.emplace_back(b, e);
        else if (std::abs(x - cx) + std::abs(y - cy) + std::abs(z - cz) == 1)
          face_empty = true;
      }
  if (cx == 0 || cy == 0 || cz == 0 || cx + 1 >= nb.nb_dims[0] || cy + 1 >= nb.nb_dims[1] || cz + 1 >= nb.nb_dims[2])
    face_empty = true;
  const float* X = nb.pos.data();
  const float* Y = X + nb.n;
  const float* Z = Y + nb.n;
  const float h2 = h * h;
  const bool radii = nb.scale.extent(0) > 0;
  std::size_t surface = 0;
  for (std::uint32_t i = first; i < last; ++i) {
    float gx = 0, gy = 0, gz = 0;
    int count = 0;
    const float ti = radii ? nb.scale(i) : 1.f;
    const float inv_hi = float(1.0 / (h_abs * double(ti)));
    for (const auto& be : ranges)
      for (std::uint32_t j = be.first; j < be.second; ++j) {
        if (radii) {
          const float ex = (X[i] - X[j]) * inv_hi, ey = (Y[i] - Y[j]) * inv_hi, ez = (Z[i] - Z[j]) * inv_hi;
          const float e2 = ex * ex + ey * ey + ez * ez;
          const float q = e2 < 1.f ? 1.f - e2 : 0.f;
          const float tj = nb.scale(j);
          const float w = (q * q) * (tj * tj * tj);
          gx += w * ex;
          gy += w * ey;
          gz += w * ez;
          count += e2 < 1.f ? 1 : 0;
          continue;
        }
        const float dx = X[i] - X[j], dy = Y[i] - Y[j], dz = Z[i] - Z[j];
        const float d2 = dx * dx + dy * dy + dz * dz;
        const float q = d2 < h2 ? h2 - d2 : 0.f;
        const float w = q * q;
        gx += w * dx;
        gy += w * dy;
        gz += w * dz;
        count += d2 < h2 ? 1 : 0;
      }
    grad[i] = std::sqrt(gx * gx + gy * gy + gz * gz) * (radii ? scale / (ti * ti * ti) : scale);
    const bool s = count - 1 < min_neighbours || grad[i] > threshold;
    flags[i] = s ? 1 : 0;
    surface += s ? 1 : 0;
  }
  if (surface == 0 && face_empty) {
    for (std::uint32_t i = first; i < last; ++i) flags[i] = 1;
    surface = last - first;
  }
  return surface;
}

// The sums at x in the GPU's order (gather_words_direct / eval_vertex_direct).
template <class Method>
void reference_sums(const NeighbourView<Host>& nb, const float x[3], float S, const FieldConstants& fc, float* acc,
                    std::uint32_t& evals) {
  for (int q = 0; q < Method::N; ++q) acc[q] = 0.f;
  std::int64_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::int64_t(std::floor((x[a] - fc.R) * nb.inv_nb_cell));
    hi[a] = std::int64_t(std::floor((x[a] + fc.R) * nb.inv_nb_cell));
    if (lo[a] < 0) lo[a] = 0;
    if (hi[a] > nb.nb_dims[a] - 1) hi[a] = nb.nb_dims[a] - 1;
  }
  const float R2 = fc.R * fc.R;
  const float* X = nb.pos.data();
  const float* Y = X + nb.n;
  const float* Z = Y + nb.n;
  for (std::int64_t cz = lo[2]; cz <= hi[2]; ++cz)
    for (std::int64_t cy = lo[1]; cy <= hi[1]; ++cy)
      for (std::int64_t cx = lo[0]; cx <= hi[0]; ++cx) {
        std::uint32_t b, e;
        if (!nb.cell_range(cx, cy, cz, b, e)) continue;
        const float clo[3] = {float(cx) * S, float(cy) * S, float(cz) * S};
        float d2 = 0;
        for (int a = 0; a < 3; ++a) {
          const float below = clo[a] - x[a], above = x[a] - (clo[a] + S);
          const float d = below > 0 ? below : (above > 0 ? above : 0.f);
          d2 += d * d;
        }
        if (d2 >= R2) continue;
        for (std::uint32_t j = b; j < e; ++j) {
          const float dx = X[j] - x[0], dy = Y[j] - x[1], dz = Z[j] - x[2];
          const float q = Method::radii ? nb.support(j) : fc.inv_R2;
          const float s2 = std::fma(dz, dz, std::fma(dy, dy, dx * dx)) * q;  // scaled_distance2
          evals += s2 < 1.f ? 1 : 0;
          Method::add(acc, dx, dy, dz, s2 < 1.f ? 1.f - s2 : 0.f,
                      Method::P ? nb.pdata.data() + std::size_t(Method::P) * j : nullptr, q);
        }
      }
}

// The field at x in the GPU's order.
template <class Method>
float reference_field(const NeighbourView<Host>& nb, const float x[3], float S, const FieldConstants& fc,
                      std::uint64_t& evals) {
  float acc[Method::N];
  std::uint32_t count = 0;
  reference_sums<Method>(nb, x, S, fc, acc, count);
  evals += count;
  return Method::value(acc, fc);
}

// ------------------------------------------------------------ the check
struct Outcome {
  std::size_t particles = 0, surface = 0, band_vertices = 0, flag_mismatches = 0, field_mismatches = 0,
              direct_mismatches = 0, weight_mismatches = 0, reach_mismatches = 0, unreached = 0;
  std::uint64_t evals = 0, ref_evals = 0;
  std::string first;  // the first mismatch, described
};

// radii: one per particle for the radii variants (p.radius_ref set), else empty.
// shrink: the grid is made for the particles' bounding box less this much on
// every side, so that the particles beyond it land in the boundary cells (as
// with a clipping box).
template <class Method, class Exec>
Outcome run(const Exec& space, const Points& xyz, const Params& p, bool dense, const std::vector<double>& radii,
            double shrink = 0) {
  Outcome out;
  MemoryTracker tracker;
  const std::size_t n = xyz.size() / 3;
  out.particles = n;
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], xyz[3 * i + a]);
      hi[a] = std::max(hi[a], xyz[3 * i + a]);
    }
  for (int a = 0; a < 3; ++a) {
    lo[a] += shrink;
    hi[a] -= shrink;
  }
  const Grid g = make_grid(lo, hi, p);
  Neighbourhood<Host> nbh;
  build_neighbourhood(space, tracker, xyz.data(), n, {}, g, nbh, Method::radii ? radii.data() : nullptr);
  FieldConstants fc =
      field_constants(p.influence_radius, p.iso_radius, p.t_low, p.t_high, p.iso_threshold, guard_ratio(p));
  if (Method::radii)
    attach_radii(space, tracker, Kokkos::View<const double*, Host>(radii.data(), radii.size()), p, nbh);
  const bool sph = p.method == nbmc::Method::SPH;
  if (sph) compute_sph_weights<Method::radii>(space, tracker, nbh, g, fc);
  if (std::is_same<Method, FieldYT10>::value) fc = compute_yt10_kernels(space, tracker, nbh, g, p, fc);
  const NeighbourView<Host> nb = view_of(nbh, g);
  if (sph) {
    // Each particle's weight: 1 / (its density summed in the serial order).
    std::uint64_t unused = 0;
    for (std::size_t j = 0; j < n; ++j) {
      const float x[3] = {nb.pos(j), nb.pos(n + j), nb.pos(2 * n + j)};
      const float ref = 1.f / reference_field<SphDensityT<Method::radii>>(nb, x, float(g.nb_cell), fc, unused);
      out.weight_mismatches += bits(nb.pdata(j)) != bits(ref);
    }
  }
  if (std::is_same<Method, FieldYT10>::value) {
    // Each particle's kernel from its moments summed in the serial order
    // (over R: fc's radius is now the field's).
    const FieldConstants fc0 = field_constants(p.influence_radius, p.iso_radius, p.t_low, p.t_high, p.iso_threshold);
    const Yt10Constants k = yt10_constants(p);
    for (std::size_t j = 0; j < n; ++j) {
      const float x[3] = {nb.pos(j), nb.pos(n + j), nb.pos(2 * n + j)};
      float a[Yt10Moments::N];
      std::uint32_t count = 0;
      reference_sums<Yt10Moments>(nb, x, float(g.nb_cell), fc0, a, count);
      float kern[kYt10Floats];
      yt10_kernel(a, count, k, kern);
      for (int q = 0; q < kYt10Floats; ++q)
        out.weight_mismatches += bits(nb.pdata(std::size_t(kYt10Floats) * j + q)) != bits(kern[q]);
    }
  }

  // Surface particles against the serial reference: with the parameters
  // given, then with the colour threshold set to the reference gradient of
  // one particle after another (and no neighbour criterion), so that a
  // gradient summed in another order flips that particle's flag.
  Kokkos::View<std::uint8_t*, Host> flags("flags", n), flags2("flags2", n);
  const Kokkos::View<const std::uint64_t*, Host> keys(nbh.cell_keys.view());
  out.surface = mark_surface_particles(space, nb, keys, nbh.n_cells, p, g, flags);
  {
    const float h = float(p.surface_radius);
    const int range = int(std::ceil(p.surface_radius / g.nb_cell));
    const double rh = p.spacing / p.surface_radius;
    const float scale =
        Method::radii
            ? float(rh * rh * rh * 945.0 / (32.0 * 3.14159265358979))
            : float(p.spacing * p.spacing * p.spacing * 945.0 / (32.0 * 3.14159265358979 * std::pow(p.surface_radius, 9)) *
                    p.surface_radius);
    const std::vector<std::uint64_t> hkeys(keys.data(), keys.data() + nbh.n_cells);
    auto compare = [&](const Params& q, const Kokkos::View<std::uint8_t*, Host>& got, std::size_t got_count,
                       std::vector<float>& grad) {
      std::vector<std::uint8_t> ref(n, 2);
      std::size_t ref_count = 0;
      for (std::size_t c = 0; c < nbh.n_cells; ++c)
        ref_count += reference_surface(nb, hkeys, c, range, h, scale, float(q.color_threshold), q.neighbour_threshold,
                                       ref, grad, p.surface_radius);
      std::size_t bad = ref_count != got_count;
      for (std::size_t i = 0; i < n; ++i) bad += got(i) != ref[i];
      return bad;
    };
    std::vector<float> grad(n, 0.f), unused(n);
    out.flag_mismatches += compare(p, flags, out.surface, grad);
    std::vector<float> probes;
    for (std::size_t i = 0; i < n; i += std::max<std::size_t>(1, n / 12))
      if (grad[i] > 0) probes.push_back(grad[i]);
    for (const float t : probes) {
      Params q = p;
      q.color_threshold = double(t);
      q.neighbour_threshold = 0;
      const std::size_t count = mark_surface_particles(space, nb, keys, nbh.n_cells, q, g, flags2);
      out.flag_mismatches += compare(q, flags2, count, unused);
    }
  }

  // The band, and the field on it.
  Band<Host> band;
  if (dense)
    build_dense_band(space, tracker, g, band);
  else
    build_narrow_band(space, tracker, g, p, Kokkos::View<const float*, Host>(nbh.pos.view()),
                      Kokkos::View<const std::uint8_t*, Host>(flags), n, band,
                      Kokkos::View<const float*, Host>(nbh.scale.view()));
  out.band_vertices = band.n_vertices;
  Kokkos::View<float*, Host> phi("phi", band.n_vertices);
  const BandView<Host> bv = view_of(band, g);
  out.evals = gather_field<Method>(space, nb, bv, band.n_blocks * 8, g, fc, phi, Progress{});

  const float c = float(g.cell), S = float(g.nb_cell);
  std::uint64_t direct_evals = 0;
  for (std::size_t w = 0; w < band.n_blocks * 8; ++w)
    bv.for_each_vertex(w, [&](const int bit, const std::int64_t index) {
      std::int64_t i, j, k;
      bv.vertex(w, bit, i, j, k);
      const float x[3] = {float(i) * c, float(j) * c, float(k) * c};
      const float ref = reference_field<Method>(nb, x, S, fc, out.ref_evals);
      const float direct = eval_vertex_direct<Method>(nb, x, S, fc, direct_evals);
      out.direct_mismatches += bits(direct) != bits(ref);
      if (bits(phi(index)) != bits(ref)) {
        if (!out.field_mismatches) {
          std::ostringstream s;
          s.precision(9);
          s << "vertex (" << i << ", " << j << ", " << k << "): gather_field " << phi(index) << ", serial " << ref;
          out.first = s.str();
        }
        ++out.field_mismatches;
      }
    });
  if (direct_evals != out.ref_evals) ++out.direct_mismatches;

  // SPH and YT10 on a narrow band, as the pipeline runs them: the weights or
  // kernels of the particles the band reaches only (ParticleReach). Each of
  // them the same bits as computed for every particle, and the field the
  // same bits (for YT10 with the R_f of the reached kernels).
  const bool yt10 = std::is_same<Method, FieldYT10>::value;
  if ((sph || yt10) && !dense) {
    const std::size_t per = sph ? 1 : std::size_t(kYt10Floats);
    std::vector<float> full(nbh.pdata.data(), nbh.pdata.data() + per * n);
    FieldConstants fc2 = fc;
    if constexpr (std::is_same<Method, FieldYT10>::value) {
      Yt10Kernels<typename Exec::memory_space> reach;
      reach.start(tracker, nbh, g, false);
      reach.add_words(space, bv, band.n_blocks * 8, {});
      fc2 = reach.update(space, nbh, g, p,
                         field_constants(p.influence_radius, p.iso_radius, p.t_low, p.t_high, p.iso_threshold));
    } else {
      SphWeights<typename Exec::memory_space> reach;
      reach.start(tracker, nbh, g, false);
      reach.add_words(space, bv, band.n_blocks * 8, {});
      reach.template update<Method::radii>(space, nbh, g, fc);
    }
    for (std::size_t j = 0; j < n; ++j) {
      bool zero = true;
      for (std::size_t q = 0; q < per; ++q) zero = zero && nbh.pdata.data()[per * j + q] == 0.f;
      if (zero) ++out.unreached;
      else
        for (std::size_t q = 0; q < per; ++q) out.reach_mismatches += bits(nbh.pdata.data()[per * j + q]) != bits(full[per * j + q]);
    }
    Kokkos::View<float*, Host> phi2("phi2", band.n_vertices);
    gather_field<Method>(space, view_of(nbh, g), bv, band.n_blocks * 8, g, fc2, phi2, Progress{});
    for (std::size_t v = 0; v < band.n_vertices; ++v) out.reach_mismatches += bits(phi2(v)) != bits(phi(v));
  }
  return out;
}

// radii (the radii variants): one per particle, as nbmc_context_set_radii
// takes them; the parameters are scaled for them as the C API does.
template <class Method>
void check(const char* name, const Points& xyz, double r, double cell, bool dense = false,
           std::size_t min_surface = 1, const std::vector<double>& radii = {}, double shrink = 0) {
  const std::string m = Method::name;
  Params p = make_params(r, cell,
                         m == "zb05"   ? NBMC_METHOD_ZB05
                         : m == "sph"  ? NBMC_METHOD_SPH
                         : m == "yt10" ? NBMC_METHOD_YT10
                                       : NBMC_METHOD_SSP07);
  if (Method::radii) {
    ASSERT_EQ(radii.size(), xyz.size() / 3);
    scale_for_radii(p, *std::min_element(radii.begin(), radii.end()), *std::max_element(radii.begin(), radii.end()));
    ASSERT_GT(p.radius_ref, 0);
  }
  for (int backend = 0; backend < 2; ++backend) {
    const Outcome o = backend == 0 ? run<Method>(Kokkos::Serial(), xyz, p, dense, radii, shrink)
#if defined(KOKKOS_ENABLE_OPENMP)
                                   : run<Method>(Kokkos::OpenMP(), xyz, p, dense, radii, shrink);
#else
                                   : run<Method>(Kokkos::Serial(), xyz, p, dense, radii, shrink);
#endif
    const std::string what = std::string(name) + " (" + Method::name + (Method::radii ? " with radii" : "") +
                             ", cell " + std::to_string(cell) + "r, " + (backend == 0 ? "Serial" : "OpenMP") + ")";
    ASSERT_GT(o.band_vertices, 0u) << what;
    EXPECT_GE(o.surface, min_surface) << what;
    EXPECT_EQ(o.flag_mismatches, 0u) << what << ": surface flags differ from the serial reference";
    EXPECT_EQ(o.field_mismatches, 0u) << what << ": " << o.field_mismatches << " of " << o.band_vertices
                                      << " field values differ from the serial per-vertex order; first: " << o.first;
    EXPECT_EQ(o.direct_mismatches, 0u) << what << ": eval_vertex_direct does not sum in plain serial order";
    EXPECT_EQ(o.weight_mismatches, 0u) << what << ": SPH weights or YT10 kernels differ from the serial order";
    EXPECT_EQ(o.evals, o.ref_evals) << what << ": contributing-particle count";
    EXPECT_EQ(o.reach_mismatches, 0u) << what << ": the weights or kernels of the band's reach only differ ("
                                      << o.unreached << " of " << o.particles << " particles unreached)";
  }
}

const double kR = 0.05;

}  // namespace

TEST(FieldOrder, RandomCloud) {
  const Points p = random_cloud(kR, 6000, 1);
  for (double cell : {1.0, 0.5}) {
    check<FieldSSP07>("random cloud", p, kR, cell);
    check<FieldZB05>("random cloud", p, kR, cell);
    check<FieldSPH>("random cloud", p, kR, cell);
    check<FieldYT10>("random cloud", p, kR, cell);
  }
}

TEST(FieldOrder, JitteredLatticeBall) {
  const Points p = jittered_ball(0.1, -0.2, 0.3, 0.5, kR, 0.25, 3);
  for (double cell : {1.0, 0.5, 0.7}) {
    check<FieldSSP07>("jittered ball", p, kR, cell);
    check<FieldZB05>("jittered ball", p, kR, cell);
    check<FieldSPH>("jittered ball", p, kR, cell);
    check<FieldYT10>("jittered ball", p, kR, cell);
  }
}

// SPH's weights and YT10's kernels are computed for the particles the band
// reaches only (ParticleReach): a ball of radius 28 r has a core that no
// band vertex reaches, and the field is still every band vertex's serial sum.
template <class Method>
void check_reach(int method) {
  const Points p = jittered_ball(0, 0, 0, 28 * kR, kR, 0.05, 5);
  for (double cell : {1.0, 0.5}) {
    const Params prm = make_params(kR, cell, method);
#if defined(KOKKOS_ENABLE_OPENMP)
    const Outcome o = run<Method>(Kokkos::OpenMP(), p, prm, false, {});
#else
    const Outcome o = run<Method>(Kokkos::Serial(), p, prm, false, {});
#endif
    const std::string what = std::string(Method::name) + ", ball of radius 28 r, cell " + std::to_string(cell) + " r";
    EXPECT_GT(o.unreached, o.particles / 50) << what << ": the core's weights are computed too";
    EXPECT_EQ(o.reach_mismatches, 0u) << what;
    EXPECT_EQ(o.field_mismatches, 0u) << what << ": " << o.first;
    EXPECT_EQ(o.weight_mismatches, 0u) << what;
  }
}
TEST(FieldOrder, SphWeightsOfTheBandsReachOnly) { check_reach<FieldSPH>(NBMC_METHOD_SPH); }
TEST(FieldOrder, Yt10KernelsOfTheBandsReachOnly) { check_reach<FieldYT10>(NBMC_METHOD_YT10); }

TEST(ParticleReach, HostRangesTakeEachCellComputedNowOnce) {
  // Occupied cells of four rows of 21 (not a multiple of the runs' 8, so a
  // row ends inside a run), random states; the host passes' work items must
  // cover the particles of exactly the cells computed now, each once, in
  // ascending ranges within one row's run.
  const std::uint64_t row = 21;
  std::mt19937 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<std::uint64_t> keys;
    for (std::uint64_t k = 0; k < 4 * row; ++k)
      if (rng() % 3 != 0) keys.push_back(k);
    const std::size_t n_cells = keys.size();
    Kokkos::View<std::uint64_t*, Host> kv("keys", n_cells);
    Kokkos::View<std::uint32_t*, Host> sv("starts", n_cells + 1);
    Kokkos::View<std::uint8_t*, Host> st("state", n_cells);
    sv(0) = 0;
    for (std::size_t q = 0; q < n_cells; ++q) {
      kv(q) = keys[q];
      sv(q + 1) = sv(q) + 1 + rng() % 12;
      st(q) = std::uint8_t(rng() % 3);
    }
    for (bool every : {false, true}) {
      std::vector<int> taken(sv(n_cells), 0);
      for (std::size_t q = 0; q < n_cells; ++q) {
        ParticleRanges r;
        ParticleReach<Host>::host_ranges(st, every, kv, sv, row, q, r);
        for (int i = 0; i < r.n; ++i) {
          ASSERT_LT(r.b[i], r.e[i]);
          if (i > 0) ASSERT_LT(r.e[i - 1], r.b[i]) << "touching ranges are one";
          for (std::uint32_t j = r.b[i]; j < r.e[i]; ++j) ++taken[j];
        }
        if (r.n > 0) {
          // One row, one run of 8.
          const std::size_t last = std::size_t(std::upper_bound(&sv(0), &sv(0) + n_cells + 1, r.e[r.n - 1] - 1) - &sv(0)) - 1;
          EXPECT_EQ(kv(q) / row, kv(last) / row);
          EXPECT_EQ(kv(q) % row / kRunCells, kv(last) % row / kRunCells);
        }
      }
      for (std::size_t q = 0; q < n_cells; ++q)
        for (std::uint32_t j = sv(q); j < sv(q + 1); ++j)
          ASSERT_EQ(taken[j], every || st(q) == 1 ? 1 : 0) << "trial " << trial << ", cell key " << kv(q);
    }
  }
}

TEST(ParticleReach, SelectReachesEveryCellWithinROfABandTile) {
  // The reach's margins, directly: random band tiles (4x4x4 grid vertices
  // each) on random grids, every neighbour cell occupied. A gather from a
  // band vertex visits the cells whose box lies within R of it (an edge
  // cell's box unbounded outward: particles outside the grid are clamped
  // into it), so select() must mark each cell within R of a vertex of a
  // tile that is set (any of its vertices may be a band vertex). The
  // distance here: per axis, the smallest gap between the cell's interval
  // and the tile's vertex coordinates (a lattice point is nearest on each
  // axis alone), checked against R (1 + 1e-6), stricter than the gathers'
  // float test. Also: not every cell is reached (the test would pass on an
  // "every cell" reach).
  using Space = Kokkos::DefaultHostExecutionSpace;
  const Space space;
  std::mt19937 rng(11);
  std::size_t unreached_cells = 0, near_misses = 0;
  for (int trial = 0; trial < 60; ++trial) {
    Grid g;
    const double R = 1.0;
    const double cells[] = {0.25, 0.125, 0.2, 0.37, 0.5, 0.0931};
    g.cell = cells[trial % 6];
    g.nb_cell = R * (0.5 + 0.5 * double(rng() % 1000) / 1000.0);  // S in [R/2, R]
    const double extent[3] = {2.0 + double(rng() % 60) / 10, 2.0 + double(rng() % 60) / 10,
                              2.0 + double(rng() % 60) / 10};
    for (int a = 0; a < 3; ++a) {
      g.dims[a] = std::int64_t(std::floor(extent[a] / g.cell)) + 2;
      g.nb_dims[a] = std::int64_t(std::floor(extent[a] / g.nb_cell)) + 2;
    }
    const std::size_t n_cells = std::size_t(g.nb_dims[0] * g.nb_dims[1] * g.nb_dims[2]);
    MemoryTracker tracker;
    Neighbourhood<Host> nbh;
    nbh.n_cells = n_cells;
    nbh.cell_keys = Buffer<std::uint64_t, Host>(tracker, "keys", n_cells);
    for (std::size_t q = 0; q < n_cells; ++q) nbh.cell_keys.view()(q) = q;
    ParticleReach<Host> reach;
    reach.start(tracker, n_cells, g, false);
    ASSERT_FALSE(reach.all);
    const std::int64_t* td = reach.tdims;
    // A few tiles, some at the grid's edges.
    std::vector<std::array<std::int64_t, 3>> set;
    const int n_tiles = 1 + int(rng() % 4);
    for (int i = 0; i < n_tiles; ++i) {
      std::array<std::int64_t, 3> t;
      for (int a = 0; a < 3; ++a) {
        const std::int64_t last = (g.dims[a] - 1) / 4;  // the last tile with a grid vertex
        const int r = int(rng() % 8);
        t[a] = r == 0 ? 0 : r == 1 ? last : std::int64_t(rng() % std::uint64_t(last + 1));
      }
      set.push_back(t);
      const std::uint64_t b = std::uint64_t(t[0]) + std::uint64_t(td[0]) * (std::uint64_t(t[1]) + std::uint64_t(td[1]) * std::uint64_t(t[2]));
      reach.tiles.view()(b >> 5) |= std::uint32_t(1) << (b & 31);
    }
    reach.select(space, nbh, g, R);
    space.fence();
    const auto st = reach.state.view();
    const double S = g.nb_cell, c = g.cell, R2 = R * R * (1 + 2e-6);
    for (std::size_t q = 0; q < n_cells; ++q) {
      std::int64_t x[3];
      neighbour_cell_of_key(q, g.nb_dims, x[0], x[1], x[2]);
      double best = HUGE_VAL;
      for (const auto& t : set) {
        double d2 = 0;
        for (int a = 0; a < 3; ++a) {
          const double lo = x[a] == 0 ? -HUGE_VAL : double(x[a]) * S;
          const double hi = x[a] == g.nb_dims[a] - 1 ? HUGE_VAL : double(x[a] + 1) * S;
          double m = HUGE_VAL;
          for (std::int64_t v = 4 * t[a]; v <= std::min(4 * t[a] + 3, g.dims[a] - 1); ++v) {
            const double p = double(v) * c, gap = p < lo ? lo - p : p > hi ? p - hi : 0.0;
            m = std::min(m, gap * gap);
          }
          d2 += m;
        }
        best = std::min(best, d2);
      }
      if (best < R2) {
        ASSERT_EQ(st(q), 1) << "trial " << trial << ": cell (" << x[0] << ", " << x[1] << ", " << x[2]
                            << ") lies " << std::sqrt(best) / R << " R from a band tile, unreached (cell " << c
                            << ", S " << S << ")";
        if (best > 0.81 * R2) ++near_misses;  // (the margins are exercised)
      } else if (st(q) == 0) {
        ++unreached_cells;
      }
    }
  }
  EXPECT_GT(near_misses, 500u);
  EXPECT_GT(unreached_cells, 1000u);
}

TEST(FieldOrder, LatticeBall) {
  // Particles on a lattice commensurate with the grid: many cell-box and
  // particle distances equal R up to rounding, where the visit decisions
  // must match the GPU's exactly.
  const Points p = jittered_ball(0, 0, 0, 0.45, kR, 0.0, 1);
  for (double cell : {1.0, 0.5, 0.8}) {
    check<FieldSSP07>("lattice ball", p, kR, cell);
    check<FieldZB05>("lattice ball", p, kR, cell);
    check<FieldSPH>("lattice ball", p, kR, cell);
    check<FieldYT10>("lattice ball", p, kR, cell);
  }
}

TEST(FieldOrder, DenseGridWithEmptyVertices) {
  // Every grid vertex, most of them with no particle within R.
  const Points p = jittered_ball(0, 0, 0, 0.3, kR, 0.25, 5);
  check<FieldSSP07>("dense grid", p, kR, 1.0, true);
  check<FieldZB05>("dense grid", p, kR, 1.0, true);
  check<FieldSPH>("dense grid", p, kR, 1.0, true);
  check<FieldYT10>("dense grid", p, kR, 1.0, true);
}

TEST(FieldOrder, CrowdedTile) {
  // 12,000 particles in one neighbour cell: the tile path's per-tile
  // particle buffer overflows (per-vertex fallback), the surface test marks
  // the crowded cell wholesale.
  const Points p = crowded(kR, 12000);
  check<FieldSSP07>("crowded tile", p, kR, 1.0);
  check<FieldZB05>("crowded tile", p, kR, 0.5);
  check<FieldSPH>("crowded tile", p, kR, 0.5);
  check<FieldYT10>("crowded tile", p, kR, 0.5);
}

TEST(FieldOrder, CoarseCells) {
  // Cells larger than R: a tile's neighbour cells do not fit the cell list
  // (collect_cells fails), every vertex is evaluated on its own.
  const Points p = jittered_ball(0, 0, 0, 0.6, kR, 0.25, 9);
  check<FieldSSP07>("coarse cells", p, kR, 6.0);
  check<FieldZB05>("coarse cells", p, kR, 6.0);
  check<FieldSPH>("coarse cells", p, kR, 6.0);
  check<FieldYT10>("coarse cells", p, kR, 6.0);
}

TEST(FieldOrder, ParticlesBeyondTheGrid) {
  // A grid smaller than the particles' box by 3 r on every side (as with a
  // clipping box): the particles beyond it lie in the boundary cells, outside
  // those cells' boxes. Every gather must still sum them as the serial
  // reference does (any pruning or trimming by cell boxes must allow for
  // them; a row trimming by the cells' y and z gaps, tried in session 25,
  // was checked with this test).
  const Points p = random_cloud(kR, 6000, 5);
  for (double cell : {1.0, 0.5}) {
    check<FieldSSP07>("particles beyond the grid", p, kR, cell, false, 1, {}, 3 * kR);
    check<FieldSPH>("particles beyond the grid", p, kR, cell, false, 1, {}, 3 * kR);
  }
}

TEST(FieldOrder, RealFrame) {
  const std::string f = std::string(NBMC_DATA_DIR) + "/xyz/cbd46k_t050_46250.xyz";
  const Points p = read_xyz(f);
  if (p.empty()) GTEST_SKIP() << f << " not present";
  check<FieldSSP07>("cbd46k", p, 0.0156, 1.0, false, 1000);
  check<FieldSPH>("cbd46k", p, 0.0156, 1.0, false, 1000);
  check<FieldYT10>("cbd46k", p, 0.0156, 1.0, false, 1000);
}

namespace {

// Radii between lo * r and r, drawn per particle.
std::vector<double> random_radii(const Points& p, double r, double lo, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(lo * r, r);
  std::vector<double> out(p.size() / 3);
  for (double& v : out) v = u(rng);
  return out;
}

template <bool Radii>
void check_all(const char* name, const Points& p, double cell, const std::vector<double>& radii, bool dense = false) {
  check<FieldSSP07T<Radii>>(name, p, kR, cell, dense, 1, radii);
  check<FieldZB05T<Radii>>(name, p, kR, cell, dense, 1, radii);
  check<FieldSPHT<Radii>>(name, p, kR, cell, dense, 1, radii);
}

}  // namespace

// Per-particle radii (each particle's own kernel support, rbar from the
// radii, the surface test and the band scaled per particle): the host tile
// path sums in the GPU's per-vertex order too.
TEST(FieldOrder, RadiiRandomCloud) {
  const Points p = random_cloud(kR, 6000, 2);
  for (double cell : {1.0, 0.5}) check_all<true>("random cloud, radii 0.3r..r", p, cell, random_radii(p, kR, 0.3, 4));
}

TEST(FieldOrder, RadiiTwoResolutions) {
  // A ball of spacing r next to one of spacing r/4, each with its own radius.
  Points p = jittered_ball(0, 0, 0, 0.4, kR, 0.25, 3);
  const std::size_t coarse = p.size() / 3;
  const Points fine = jittered_ball(0.6, 0, 0, 0.1, kR / 4, 0.25, 5);
  p.insert(p.end(), fine.begin(), fine.end());
  std::vector<double> radii(p.size() / 3, kR / 4);
  std::fill(radii.begin(), radii.begin() + std::ptrdiff_t(coarse), kR);
  check_all<true>("two resolutions", p, 0.5, radii);
  check_all<true>("two resolutions, dense", p, 1.0, radii, true);
}

TEST(FieldOrder, RadiiCoarseCells) {
  const Points p = jittered_ball(0, 0, 0, 0.6, kR, 0.25, 9);
  check_all<true>("coarse cells, radii", p, 6.0, random_radii(p, kR, 0.5, 6));
}

// The lane count of the host field (host_simd_lanes): the widest the CPU
// runs (16 with AVX-512F, 8 with AVX2, else 4), or NBMC_HOST_SIMD's where
// the CPU has it.
TEST(HostSimdLanes, Dispatch) {
  const char* e = std::getenv("NBMC_HOST_SIMD");
  const std::string saved = e ? e : "";
  unsetenv("NBMC_HOST_SIMD");
  const int best = host_simd_lanes();
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
  const bool fma = __builtin_cpu_supports("fma");
  EXPECT_EQ(best, __builtin_cpu_supports("avx512f") && fma ? 16 : __builtin_cpu_supports("avx2") && fma ? 8 : 4);
#endif
  for (int asked : {4, 8, 16}) {
    setenv("NBMC_HOST_SIMD", std::to_string(asked).c_str(), 1);
    EXPECT_EQ(host_simd_lanes(), std::min(asked, best)) << "NBMC_HOST_SIMD=" << asked;
  }
  setenv("NBMC_HOST_SIMD", "32", 1);  // not a width: the default
  EXPECT_EQ(host_simd_lanes(), best);
  if (e) setenv("NBMC_HOST_SIMD", saved.c_str(), 1);
  else unsetenv("NBMC_HOST_SIMD");
}

// The surface particles' colour-gradient sums of a group of particles at 4,
// 8 and 16 lanes (surface_sums_host picks the width per group; each lane
// must do the scalar loop's operations in its order): against that loop,
// bit for bit, for groups of every size up to 16 and one spanning the
// cell's end (lanes past `last` repeat its last particle).
TEST(SurfaceSums, EveryLaneCountGivesTheScalarSums) {
  std::mt19937 rng(14);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  const std::uint32_t n = 300;
  std::vector<float> X(n), Y(n), Z(n);
  for (std::uint32_t q = 0; q < n; ++q) {
    X[q] = u(rng);
    Y[q] = u(rng);
    Z[q] = u(rng);
  }
  // Three "cells": ranges of particles in an order the scalar loop follows.
  const std::uint32_t begin[3] = {0, 120, 200}, end[3] = {90, 200, 300};
  const float h = 0.7f, h2 = h * h;
  auto scalar = [&](std::uint32_t i, float g[3], int& count) {
    float gx = 0, gy = 0, gz = 0;
    count = 0;
    for (int c = 0; c < 3; ++c)
      for (std::uint32_t j = begin[c]; j < end[c]; ++j) {
        const float dx = X[i] - X[j], dy = Y[i] - Y[j], dz = Z[i] - Z[j];
        const float d2 = dx * dx + dy * dy + dz * dz;
        const float q = d2 < h2 ? h2 - d2 : 0.f;
        const float w = q * q;
        gx += w * dx;
        gy += w * dy;
        gz += w * dz;
        count += d2 < h2 ? 1 : 0;
      }
    g[0] = gx;
    g[1] = gy;
    g[2] = gz;
  };
  const int best = host_simd_lanes();
  std::size_t checked = 0;
  for (int lanes : {4, 8, 16}) {
    if (lanes > best) continue;  // the CPU lacks them
    for (std::uint32_t first : {0u, 37u, 91u})
      for (std::uint32_t size = 1; size <= 17; ++size) {
        const std::uint32_t last = first + size;
        for (std::uint32_t i0 = first; i0 < last;) {
          float gx[16], gy[16], gz[16];
          int count[16];
          const int L = surface_sums_host(X.data(), Y.data(), Z.data(), begin, end, 3, i0, last, h2, lanes, gx, gy,
                                          gz, count);
          EXPECT_LE(L, lanes);
          for (int l = 0; l < L && i0 + std::uint32_t(l) < last; ++l) {
            float g[3];
            int c = 0;
            scalar(i0 + std::uint32_t(l), g, c);
            EXPECT_EQ(bits(gx[l]), bits(g[0])) << lanes << " lanes, particle " << i0 + l;
            EXPECT_EQ(bits(gy[l]), bits(g[1])) << lanes << " lanes, particle " << i0 + l;
            EXPECT_EQ(bits(gz[l]), bits(g[2])) << lanes << " lanes, particle " << i0 + l;
            EXPECT_EQ(count[l], c) << lanes << " lanes, particle " << i0 + l;
            ++checked;
          }
          i0 += std::uint32_t(L);
        }
      }
  }
  EXPECT_GT(checked, 0u);
  // Groups of 9 or more particles take 16 lanes where the CPU has them, of 5
  // to 8 take 8 (AVX2): the wide paths were the ones checked above.
  float gx[16], gy[16], gz[16];
  int count[16];
  EXPECT_EQ(surface_sums_host(X.data(), Y.data(), Z.data(), begin, end, 3, 0, 12, h2, best, gx, gy, gz, count),
            best);
  EXPECT_EQ(surface_sums_host(X.data(), Y.data(), Z.data(), begin, end, 3, 0, 3, h2, best, gx, gy, gz, count), 4);
}

// SSP07's largest eigenvalue takes cos(acos(r) / 3) from a polynomial with
// IEEE operations only (field_ssp07.hpp), so that CPU and GPU agree bit for
// bit. Its accuracy against a long double reference, over floats of [-1, 1]
// (every 4099th bit pattern of each sign, and both ends): within 1.5 ulps
// of the result (measured: 1.08).
TEST(Ssp07Eigenvalue, CosThirdAcosWithinOneAndAHalfUlps) {
  double worst = 0;
  float worst_r = 0;
  std::size_t n = 0;
  auto check = [&](float r) {
    const long double ref = std::cos(std::acos(static_cast<long double>(r)) / 3.0L);
    const float got = cos_third_acos(r);
    const float rf = static_cast<float>(ref);
    const double ulp = double(std::nextafter(rf, 2.f) - rf);
    const double err = double(std::fabs(static_cast<long double>(got) - ref)) / ulp;
    if (err > worst) {
      worst = err;
      worst_r = r;
    }
    ++n;
  };
  for (std::uint32_t b = 0; b < 0x3f800000u; b += 4099) {
    float r;
    std::memcpy(&r, &b, 4);
    check(r);
    check(-r);
  }
  check(1.f);
  check(-1.f);
  EXPECT_LE(worst, 1.5) << "at r = " << worst_r;
  EXPECT_GT(n, 500000u);
  EXPECT_GE(cos_third_acos(-1.f), 0.5f - 1e-7f);  // a double largest eigenvalue
  EXPECT_LE(cos_third_acos(1.f), 1.f);
}

// The largest eigenvalue of random symmetric 3x3 matrices (R D R^T, with
// random rotations R and eigenvalues D, some of them repeated): within 1e-5
// of the largest |eigenvalue| where the eigenvalues are apart; where the
// largest is (nearly) double, r is near -1 and the closed form loses half
// the digits with any cos(acos(r) / 3) (an error of 1e-7 in r moves the
// root by about 3e-4): there no farther from the truth than the same formula
// with the C library's acosf and cosf, give or take 2e-6.
TEST(Ssp07Eigenvalue, LargestOfRandomSymmetricMatrices) {
  std::mt19937 rng(30);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int separated = 0, within = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    double D[3] = {3 * u(rng), 3 * u(rng), 3 * u(rng)};
    if (trial % 4 == 1) D[1] = D[0];  // a repeated eigenvalue
    if (trial % 4 == 2) D[2] = D[1] = D[0] + 1e-3 * u(rng);
    // a random rotation from a unit quaternion
    double q[4] = {u(rng), u(rng), u(rng), u(rng)};
    const double l = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (double& v : q) v /= l;
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    const double Rm[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                             {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                             {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
    double S[3][3] = {};
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) S[i][j] += Rm[i][k] * D[k] * Rm[j][k];
    const double want = std::max(D[0], std::max(D[1], D[2]));
    const double scale = std::max(std::fabs(D[0]), std::max(std::fabs(D[1]), std::fabs(D[2])));
    const float got = largest_eigenvalue_sym3(float(S[0][0]), float(S[1][1]), float(S[2][2]), float(S[0][1]),
                                              float(S[0][2]), float(S[1][2]));
    const double tol = 1e-5 * std::max(1.0, scale);
    // the same steps as largest_eigenvalue_sym3, with the C library
    const float a = float(S[0][0]), b = float(S[1][1]), c = float(S[2][2]), d = float(S[0][1]), e = float(S[0][2]),
                f = float(S[1][2]);
    const float p1 = d * d + e * e + f * f, qm = (a + b + c) / 3.f;
    const float aa = a - qm, bb = b - qm, cc = c - qm;
    const float p2 = aa * aa + bb * bb + cc * cc + 2.f * p1;
    float libm = qm;
    if (p2 > 1e-20f) {
      const float p = std::sqrt(p2 / 6.f), inv = 1.f / p;
      const float ba = aa * inv, bb2 = bb * inv, bc = cc * inv, bd = d * inv, be = e * inv, bf = f * inv;
      float r = 0.5f * (ba * (bb2 * bc - bf * bf) - bd * (bd * bc - bf * be) + be * (bd * bf - bb2 * be));
      r = r < -1.f ? -1.f : (r > 1.f ? 1.f : r);
      libm = qm + 2.f * p * std::cos(std::acos(r) / 3.f);
    }
    const double err = std::fabs(got - want);
    ASSERT_TRUE(err <= tol || err <= std::fabs(libm - want) + 0.2 * tol)
        << "trial " << trial << ": " << got << " against " << want << " (C library: " << libm << ")";
    separated += std::fabs(libm - want) <= tol ? 1 : 0;
    within += err <= tol ? 1 : 0;
  }  // The distinct cases (half the trials and most of the others) within 1e-5.
  EXPECT_GE(within, separated);
  EXPECT_GT(within, 10000);
}
