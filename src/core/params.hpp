// SPDX-License-Identifier: MIT
// Resolved parameters of a reconstruction and the error type of the core:
// plain C++ (no Kokkos, no MPI), shared by the Kokkos stages, the subdomain
// runner and the MPI layer.
#pragma once

#include "nbmc.h"
#include "host_cache.hpp"

#include <cstdint>
#include <cstdio>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

namespace nbmc {

// Status carried by exceptions thrown inside the pipeline; the C API maps it.
struct Error : std::runtime_error {
  int32_t status;
  // A limit of one run that splitting the frame into subdomains avoids
  // (NBMC_SUBDOMAINS_AUTO then splits, or splits further).
  bool split_helps = false;
  Error(int32_t s, const std::string& msg, bool split = false)
      : std::runtime_error(msg), status(s), split_helps(split) {}
};

// A std::allocator that leaves new elements uninitialised, for large arrays
// whose every element is written right after (particle uploads, meshes): no
// zeroing pass, and the pages are first touched where they are filled.
// Blocks of 4 MiB or more (HostBlockCache::kMinBytes) come from
// HostBlockCache (host_cache.hpp), which keeps freed ones, already faulted
// in, for the next frame.
template <class T>
struct NoInitAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = NoInitAllocator<U>;
  };
  NoInitAllocator() = default;
  template <class U>
  NoInitAllocator(const NoInitAllocator<U>&) noexcept {}
  static bool cached(std::size_t n) {
    return n >= HostBlockCache::kMinBytes / sizeof(T) && HostBlockCache::enabled();
  }
  T* allocate(std::size_t n) {
    if (cached(n)) return static_cast<T*>(HostBlockCache::instance().allocate(n * sizeof(T)));
    return std::allocator<T>::allocate(n);
  }
  void deallocate(T* p, std::size_t n) noexcept {
    if (cached(n)) HostBlockCache::instance().deallocate(p);
    else std::allocator<T>::deallocate(p, n);
  }
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... A>
  void construct(U* p, A&&... a) {
    ::new (static_cast<void*>(p)) U(std::forward<A>(a)...);
  }
};

// A fixed array of n uninitialised elements of a trivial type (atomics
// included, which a std::vector cannot resize), from NoInitAllocator: a
// large one comes from the host cache with its pages already there, where
// operator new[] maps fresh pages for every frame (the clean-up's 81 MB of
// per-vertex slots on the 13.2 M frame: about 20,000 page faults a frame).
template <class T>
class NoInitArray {
  static_assert(std::is_trivially_default_constructible<T>::value && std::is_trivially_destructible<T>::value,
                "NoInitArray holds trivial types only");

 public:
  NoInitArray() = default;
  explicit NoInitArray(std::size_t n) : p_(n ? NoInitAllocator<T>().allocate(n) : nullptr), n_(n) {}
  NoInitArray(const NoInitArray&) = delete;
  NoInitArray& operator=(const NoInitArray&) = delete;
  NoInitArray(NoInitArray&& o) noexcept : p_(o.p_), n_(o.n_) { o.p_ = nullptr, o.n_ = 0; }
  NoInitArray& operator=(NoInitArray&& o) noexcept {
    std::swap(p_, o.p_);
    std::swap(n_, o.n_);
    return *this;
  }
  ~NoInitArray() {
    if (p_) NoInitAllocator<T>().deallocate(p_, n_);
  }
  T& operator[](std::size_t i) { return p_[i]; }
  const T& operator[](std::size_t i) const { return p_[i]; }
  T* data() { return p_; }
  const T* data() const { return p_; }
  std::size_t size() const { return n_; }
  explicit operator bool() const { return p_ != nullptr; }

 private:
  T* p_ = nullptr;
  std::size_t n_ = 0;
};

// The field method (the kernel of the scalar field): one value per
// NBMC_METHOD_*; backends/kokkos/field_methods.hpp maps it to a kernel type.
enum class Method : int32_t {
  SSP07 = NBMC_METHOD_SSP07,
  ZB05 = NBMC_METHOD_ZB05,
  SPH = NBMC_METHOD_SPH,
  YT10 = NBMC_METHOD_YT10
};
// Where the field is evaluated: the narrow band (the method of the paper) or
// one of its baselines.
enum class FieldKind : int32_t {
  NarrowBand = NBMC_FIELD_NARROW_BAND,
  Dense = NBMC_FIELD_DENSE,
  Scatter = NBMC_FIELD_SCATTER
};

// Parameters with every length in absolute units (see nbmc_params).
struct Params {
  double spacing = 0;          // r
  double cell_size = 0;        // c
  double influence_radius = 0; // R
  double band_width = 0;       // half width of the band box
  double surface_radius = 0;   // neighbourhood radius of the surface test
  double iso_radius = 0;       // r-bar
  Method method = Method::SSP07;
  FieldKind field = FieldKind::NarrowBand;
  double t_low = 0.4, t_high = 3.5;
  double iso_threshold = 0.6;  // SPH, YT10: iso level of the normalised density
  // YT10: Yu & Turk's anisotropy (nbmc_params.aniso_*; backends/kokkos/field_yt10.hpp)
  double aniso_kr = 4, aniso_ks = 1, aniso_kn = 0.5, aniso_lambda = 0.3;
  int aniso_neighbours = 25;
  // The distance guard's rho (nbmc_params.max_distance), absolute; 0: off
  // (backends/kokkos/field_common.hpp).
  double max_distance = 0;
  bool drop_isolated = false;  // NBMC_ISOLATED_DROP
  std::uint32_t min_cluster = 10;
  double color_threshold = 0.75;
  int neighbour_threshold = 25;
  bool normals = true;
  bool double_positions = false;  // mesh positions in double (HostMesh::positions64)
  bool use_bbox = false;
  double bbox_min[3] = {0, 0, 0}, bbox_max[3] = {0, 0, 0};
  // Per-particle radii (nbmc_context_set_radii_*): the largest radius r_max
  // of the frame, 0 without radii. The lengths above are then those of a
  // particle of radius r_max (spacing = r_max; scale_for_radii), and
  // particle j's are t_j = r_j / r_max times them (backends/kokkos/radii.hpp);
  // the cell size is the frame's.
  double radius_ref = 0;
  // The clean-up will run on this mesh first (the C API, with
  // nbmc_params.cleanup): the CUDA pipeline then builds its incidence on
  // the GPU (HostMesh::incidence, mesh_incidence.hpp).
  bool prebuilt_incidence = false;
};

// YT10's bounds (backends/kokkos/field_yt10.hpp): a kernel's longest axis is
// at most kYt10MaxAxis h = 0.75 R (h = R/2, the isotropic support), and its
// centre moves at most kYt10MaxShift R, so that every kernel lies within
// 0.95 R of its particle: inside the influence radius that the band, the
// neighbour search and the ghost layers use.
constexpr double kYt10MaxAxis = 1.5;
constexpr double kYt10MaxShift = 0.2;

// The distance guard's rho / R for the field kernels (FieldConstants::
// guard_ratio; 0: none). YT10 has no guard; rho >= R would never raise a
// value to the outside (every particle the field sees lies within R), so it
// is off there too.
inline double guard_ratio(const Params& p) {
  if (p.method == Method::YT10 || !(p.max_distance > 0) || !(p.max_distance < p.influence_radius)) return 0;
  return p.max_distance / p.influence_radius;
}

// The normalised-density fields (SPH, YT10): a pass over the particles
// before the field, whose per-particle values (SPH: the density; YT10: the
// density, the smoothed centre and the anisotropy) are sums over the
// particles within R; they have no iso_radius.
inline bool is_density_field(Method m) { return m == Method::SPH || m == Method::YT10; }

// The largest ratio between the largest and the smallest per-particle radius.
constexpr double kMaxRadiusRatio = 1e6;

// Per-particle radii, the smallest r_min and the largest r_max (absolute,
// validated): p's lengths, resolved for a particle of radius p.spacing,
// become those of the largest particle -- influence radius, band width,
// surface radius and iso radius times r_max / p.spacing; the cell size stays
// the frame's -- and spacing becomes r_max. Unless every radius is the same,
// the per-particle path is on (radius_ref = r_max: particle j's lengths are
// r_j / r_max times these). Equal radii make a uniform frame of spacing r_max,
// which takes the path without radii (r_max == p.spacing leaves p as it is).
// YT10 has no per-particle radii (its anisotropic kernels are fitted at one
// support h = R/2): differing radii are refused; equal radii are a uniform
// frame, as for every method.
inline void scale_for_radii(Params& p, double r_min, double r_max) {
  if (p.method == Method::YT10 && r_min < r_max)
    throw Error(NBMC_ERROR_INVALID_PARAMETER,
                "per-particle radii are not supported with method yt10 (use ssp07, zb05 or sph, or no radii)");
  if (!(r_min > 0) || !(r_max >= r_min))
    throw Error(NBMC_ERROR_INTERNAL, "per-particle radii: no valid smallest and largest radius");
  if (r_max > kMaxRadiusRatio * r_min) {
    char msg[160];
    std::snprintf(msg, sizeof msg, "the per-particle radii span more than a factor 1e6 (smallest %g, largest %g)",
                  r_min, r_max);
    throw Error(NBMC_ERROR_INVALID_PARAMETER, msg);
  }
  const double f = r_max / p.spacing;
  p.influence_radius *= f;
  p.band_width *= f;
  p.surface_radius *= f;
  p.iso_radius *= f;
  p.max_distance *= f;
  p.spacing = r_max;
  p.radius_ref = r_min < r_max ? r_max : 0;
}

// How far from a point the particles that change its field value can lie:
// R, or 2R for the SPH density and YT10, whose value at a point also depends
// on per-particle values of the particles within R of it (each a sum over R
// around that particle). Ghost layers and the particles kept around a
// clipping box are this wide.
inline double particle_reach(const Params& p) {
  return is_density_field(p.method) ? 2 * p.influence_radius : p.influence_radius;
}

// How far beyond the particles the iso-surface can lie: iso_radius for the
// distance-like fields (SSP07, ZB05), R for the SPH density (zero beyond R)
// and YT10 (a kernel's support, plus its centre's displacement, is at most
// 0.95 R: field_yt10.hpp).
inline double surface_reach(const Params& p) {
  return is_density_field(p.method) ? p.influence_radius : p.iso_radius;
}

}  // namespace nbmc
