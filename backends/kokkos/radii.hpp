// SPDX-License-Identifier: MIT
// Per-particle radii (nbmc_context_set_radii_*): the radius r_j of each
// uploaded particle, brought into the sorted order of the neighbourhood as
//   t_j = r_j / r_max  (p.radius_ref = r_max, the largest radius of the frame),
// with what the stages read from it:
//   - the field's kernel support R_j = R t_j, stored as 1 / R_j^2
//     (Neighbourhood::support; R = p.influence_radius is the largest
//     particle's, so every search and pruning by R stays exact);
//   - for the distance fields (SSP07, ZB05), each particle's radius
//     iso_radius t_j, the weight whose kernel-weighted mean is rbar of eq. (1)
//     (Neighbourhood::pdata, P = 1; the SPH density computes its own weights);
//   - t_j itself, which scales the surface-particle test and the band box.
// Every value is computed from t_j (a float) with the same double operations
// on every backend, and t_j from the particle's own radius and the frame's
// r_max, so a subdomain or an MPI rank gets the frame's values bit for bit.
// A particle with r_j = r_max has t_j = 1 and R_j = R exactly.
#pragma once

#include "common.hpp"
#include "neighbourhood.hpp"

namespace nbmc {
namespace Details {

// The radii of the uploaded particles (host memory, count of them) where the
// kernels read them: the host array itself, or a copy in device memory
// (held by `copy`).
template <class ExecSpace>
Kokkos::View<const double*, typename ExecSpace::memory_space> radii_view(
    const ExecSpace& space, MemoryTracker& tracker, const double* radii, std::size_t count,
    Buffer<double, typename ExecSpace::memory_space>& copy) {
  using MemSpace = typename ExecSpace::memory_space;
  if (!radii) throw Error(9 /*NBMC_ERROR_INTERNAL*/, "per-particle radii: no radii");
  using HostIn = Kokkos::View<const double*, Kokkos::HostSpace, Kokkos::MemoryTraits<Kokkos::Unmanaged>>;
  if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible) {
    (void)space;
    (void)tracker;
    (void)copy;
    return HostIn(radii, count);
  } else {
    copy = Buffer<double, MemSpace>(tracker, "radii::input", count);
    Kokkos::deep_copy(space, copy.view(), HostIn(radii, count));
    return copy.view();
  }
}

// in: the uploaded particles' radii (radii_view); nbh.perm indexes them.
template <class ExecSpace>
void attach_radii(const ExecSpace& space, MemoryTracker& tracker,
                  const Kokkos::View<const double*, typename ExecSpace::memory_space>& in, const Params& p,
                  Neighbourhood<typename ExecSpace::memory_space>& nbh) {
  using MemSpace = typename ExecSpace::memory_space;
  ScopedRegion region("nbmc::radii");
  if (!(p.radius_ref > 0)) throw Error(9 /*NBMC_ERROR_INTERNAL*/, "per-particle radii: no r_max");
  const std::size_t n = nbh.n;
  nbh.scale = Buffer<float, MemSpace>(tracker, "radii::scale", n);
  nbh.support = Buffer<float, MemSpace>(tracker, "radii::support", n);
  const bool iso = p.method != Method::SPH;
  if (iso) nbh.pdata = Buffer<float, MemSpace>(tracker, "radii::iso_radii", n);
  const auto perm = nbh.perm.view();
  const auto scale = nbh.scale.view(), support = nbh.support.view(), weight = nbh.pdata.view();
  const double ref = p.radius_ref, R = p.influence_radius, iso_radius = p.iso_radius;
  Kokkos::parallel_for(
      "nbmc::radii::sort", Kokkos::RangePolicy<ExecSpace>(space, 0, n), KOKKOS_LAMBDA(const std::size_t j) {
        const float tf = float(in(perm(j)) / ref);
        const double t = double(tf);
        const double Rj = R * t;
        scale(j) = tf;
        support(j) = float(1.0 / (Rj * Rj));
        if (iso) weight(j) = float(iso_radius * t);
      });
  space.fence();
}

}  // namespace Details
}  // namespace nbmc
