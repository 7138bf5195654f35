// SPDX-License-Identifier: MIT
// Solenthaler, Schlaefli & Pajarola 2007, as used by the paper (eq. 1-5):
//   phi(x) = |x - xbar| - rbar * f,  f = 1 if EVmax < t_low, else g^3 - 3g^2 + 3g,
//   g = (t_high - EVmax) / (t_high - t_low), clamped to [0, 1] (so f = 0 beyond t_high),
// with EVmax the largest eigenvalue of the Jacobian d xbar / d x. With d_j = x_j - x,
// W = sum k_j and grad k_j = 6 (1 - s_j^2)^2 d_j / R^2:
//   d xbar_a / d x_b = (sum_j d_ja (grad k_j)_b - dbar_a sum_j (grad k_j)_b) / W.
// The Jacobian is not symmetric in general; we take the largest eigenvalue of its
// symmetric part (real, and an upper bound of the real parts of its eigenvalues).
// In a uniform particle distribution the Jacobian is the identity (EVmax = 1).
#pragma once

#include "field_common.hpp"

namespace nbmc {
namespace Details {

// Largest eigenvalue of the symmetric matrix [[a, d, e], [d, b, f], [e, f, c]].
KOKKOS_INLINE_FUNCTION float largest_eigenvalue_sym3(float a, float b, float c, float d, float e, float f) {
  const float p1 = d * d + e * e + f * f;
  const float q = (a + b + c) / 3.f;
  const float aa = a - q, bb = b - q, cc = c - q;
  const float p2 = aa * aa + bb * bb + cc * cc + 2.f * p1;
  if (!(p2 > 1e-20f)) return q;
  const float p = Kokkos::Experimental::sqrt(p2 / 6.f);
  const float inv = 1.f / p;
  // det((S - qI) / p) / 2
  const float ba = aa * inv, bb2 = bb * inv, bc = cc * inv, bd = d * inv, be = e * inv, bf = f * inv;
  float r = 0.5f * (ba * (bb2 * bc - bf * bf) - bd * (bd * bc - bf * be) + be * (bd * bf - bb2 * be));
  r = r < -1.f ? -1.f : (r > 1.f ? 1.f : r);
  const float phi = Kokkos::Experimental::acos(r) / 3.f;
  return q + 2.f * p * Kokkos::Experimental::cos(phi);
}

struct FieldSSP07 {
  static constexpr const char* name = "ssp07";
  struct Acc {
    float w = 0, dx = 0, dy = 0, dz = 0;
    float gx = 0, gy = 0, gz = 0;
    float m[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};  // sum d_a g_b, row-major
  };
  KOKKOS_INLINE_FUNCTION static void add(Acc& a, float dx, float dy, float dz, float /*s2*/, float k) {
    const float k2 = k * k;
    const float w = k2 * k;
    a.w += w;
    a.dx += w * dx;
    a.dy += w * dy;
    a.dz += w * dz;
    // grad k without the 6 / R^2 factor (applied in value()).
    const float gx = k2 * dx, gy = k2 * dy, gz = k2 * dz;
    a.gx += gx;
    a.gy += gy;
    a.gz += gz;
    a.m[0] += dx * gx; a.m[1] += dx * gy; a.m[2] += dx * gz;
    a.m[3] += dy * gx; a.m[4] += dy * gy; a.m[5] += dy * gz;
    a.m[6] += dz * gx; a.m[7] += dz * gy; a.m[8] += dz * gz;
  }
  KOKKOS_INLINE_FUNCTION static float eigenvalue(const Acc& a, const FieldConstants& c) {
    const float inv = 1.f / a.w;
    const float s = 6.f * c.inv_R2 * inv;
    const float db[3] = {a.dx * inv, a.dy * inv, a.dz * inv};
    const float g[3] = {a.gx, a.gy, a.gz};
    float J[9];
    for (int r = 0; r < 3; ++r)
      for (int q = 0; q < 3; ++q) J[3 * r + q] = s * (a.m[3 * r + q] - db[r] * g[q]);
    return largest_eigenvalue_sym3(J[0], J[4], J[8], 0.5f * (J[1] + J[3]), 0.5f * (J[2] + J[6]),
                                   0.5f * (J[5] + J[7]));
  }
  KOKKOS_INLINE_FUNCTION static float value(const Acc& a, const FieldConstants& c) {
    if (!(a.w > 0)) return c.outside;
    const float inv = 1.f / a.w;
    const float x = a.dx * inv, y = a.dy * inv, z = a.dz * inv;
    const float ev = eigenvalue(a, c);
    float f = 1.f;
    if (!(ev < c.t_low)) {
      float g = (c.t_high - ev) / (c.t_high - c.t_low);
      g = g < 0.f ? 0.f : (g > 1.f ? 1.f : g);
      f = g * g * g - 3.f * g * g + 3.f * g;
    }
    return Kokkos::Experimental::sqrt(x * x + y * y + z * z) - c.iso_radius * f;
  }
};

}  // namespace Details
}  // namespace nbmc
