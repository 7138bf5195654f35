// SPDX-License-Identifier: MIT
// Zhu & Bridson 2005: phi(x) = |x - xbar| - rbar, xbar the kernel-weighted mean
// of the neighbours (eq. 4 with the kernel of eq. 5), rbar the particle radius
// (uniform here: iso_radius).
#pragma once

#include "field_common.hpp"

#include <cstdint>

namespace nbmc {
namespace Details {

struct FieldZB05 {
  static constexpr const char* name = "zb05";
  // a[0] = sum k^3, a[1..3] = sum k^3 d
  static constexpr int P = 0;
  static constexpr int N = 4;
  // T is float, or a host SIMD vector of floats (same formula, lane-wise).
  template <class T>
  KOKKOS_INLINE_FUNCTION static void add(T* a, T dx, T dy, T dz, T k, const float* /*no particle data*/) {
    const T w = k * k * k;
    a[0] += w;
    a[1] += w * dx;
    a[2] += w * dy;
    a[3] += w * dz;
  }
  // Adds particles [b, e) (SoA coordinates) at vertex x, one after the other (the
  // order of the sums is part of the result: see field_common.hpp); returns how
  // many contribute. Same operations as add().
  KOKKOS_INLINE_FUNCTION static std::uint32_t accumulate(float* a, const float* X, const float* Y, const float* Z,
                                                         const float* /*no particle data*/, std::uint32_t b,
                                                         std::uint32_t e, float x0, float x1, float x2,
                                                         float inv_R2) {
    float a0 = a[0], a1 = a[1], a2 = a[2], a3 = a[3];
    std::uint32_t count = 0;
    for (std::uint32_t j = b; j < e; ++j) {
      const float dx = X[j] - x0, dy = Y[j] - x1, dz = Z[j] - x2;
      const float s2 = (dx * dx + dy * dy + dz * dz) * inv_R2;
      const float k = s2 < 1.f ? 1.f - s2 : 0.f;
      count += s2 < 1.f ? 1u : 0u;
      const float w = k * k * k;
      a0 += w;
      a1 += w * dx;
      a2 += w * dy;
      a3 += w * dz;
    }
    a[0] = a0; a[1] = a1; a[2] = a2; a[3] = a3;
    return count;
  }
  KOKKOS_INLINE_FUNCTION static float value(const float* a, const FieldConstants& c) {
    if (!(a[0] > 0)) return c.outside;
    const float inv = 1.f / a[0];
    const float x = a[1] * inv, y = a[2] * inv, z = a[3] * inv;
    return Kokkos::Experimental::sqrt(x * x + y * y + z * z) - c.iso_radius;
  }
};

}  // namespace Details
}  // namespace nbmc
