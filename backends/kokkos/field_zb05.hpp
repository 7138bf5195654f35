// SPDX-License-Identifier: MIT
// Zhu & Bridson 2005: phi(x) = |x - xbar| - rbar, xbar the kernel-weighted mean
// of the neighbours (eq. 4 with the kernel of eq. 5), rbar the particle radius
// (uniform here: iso_radius).
#pragma once

#include "field_common.hpp"

namespace nbmc {
namespace Details {

struct FieldZB05 {
  static constexpr const char* name = "zb05";
  struct Acc {
    float w = 0, dx = 0, dy = 0, dz = 0;
  };
  KOKKOS_INLINE_FUNCTION static void add(Acc& a, float dx, float dy, float dz, float /*s2*/, float k) {
    const float w = k * k * k;
    a.w += w;
    a.dx += w * dx;
    a.dy += w * dy;
    a.dz += w * dz;
  }
  KOKKOS_INLINE_FUNCTION static float value(const Acc& a, const FieldConstants& c) {
    if (!(a.w > 0)) return c.outside;
    const float inv = 1.f / a.w;
    const float x = a.dx * inv, y = a.dy * inv, z = a.dz * inv;
    return Kokkos::Experimental::sqrt(x * x + y * y + z * z) - c.iso_radius;
  }
};

}  // namespace Details
}  // namespace nbmc
