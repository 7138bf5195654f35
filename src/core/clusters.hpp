// SPDX-License-Identifier: MIT
// The isolated-particle filter (nbmc_params.isolated = NBMC_ISOLATED_DROP):
// clusters are the connected components of the graph that links particles
// closer than a radius (the surface radius); clusters of fewer than
// min_cluster particles produce no surface. Plain C++, on the host, before
// any backend runs, so a whole frame, its subdomains and every backend see
// the same particles.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace nbmc {

struct ClusterFilter {
  std::vector<std::uint32_t> kept;  // indices of the particles kept, in input order
  std::uint64_t dropped_particles = 0, dropped_clusters = 0;
};

// xyz: n particles, 3 doubles each (finite). radius > 0, min_cluster >= 1.
// Throws Error(NBMC_ERROR_DOMAIN_TOO_LARGE) when the particles span more than
// 2^21 - 1 radii along an axis.
ClusterFilter drop_small_clusters(const double* xyz, std::size_t n, double radius, std::uint32_t min_cluster);

}  // namespace nbmc
