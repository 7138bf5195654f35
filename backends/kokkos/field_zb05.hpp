// SPDX-License-Identifier: MIT
// Zhu & Bridson 2005: phi(x) = |x - xbar| - rbar, xbar the kernel-weighted mean
// of the neighbours (eq. 4 with the kernel of eq. 5), rbar the particle radius:
// iso_radius, or with per-particle radii (Radii = true, field_common.hpp) the
// mean of the particles' radii r_j with the weights of xbar, as ZB05 define it.
#pragma once

#include "field_common.hpp"

#include <cstdint>

namespace nbmc {
namespace Details {

template <bool Radii>
struct FieldZB05T {
  static constexpr const char* name = "zb05";
  // a[0] = sum k^3, a[1..3] = sum k^3 d; radii: a[4] = sum k^3 r_j
  static constexpr int P = Radii ? 1 : 0;  // radii: the particle's radius r_j
  static constexpr bool radii = Radii;
  static constexpr int RS = 4;                 // radii: sum k^3 r_j
  static constexpr int KM = Radii ? 5 : 4;     // largest k (the distance guard)
  static constexpr int N = KM + 1;
  // T is float, or a host SIMD vector of floats (same formula, lane-wise).
  template <class T>
  KOKKOS_INLINE_FUNCTION static void add(T* a, T dx, T dy, T dz, T k, const float* pd, T /*q: in k already*/) {
    const T w = k * k * k;
    a[0] += w;
    a[1] = fmadd(w, dx, a[1]);
    a[2] = fmadd(w, dy, a[2]);
    a[3] = fmadd(w, dz, a[3]);
    if constexpr (Radii) a[RS] = fmadd(w, lanes_of<T>(pd[0]), a[RS]);
    else (void)pd;
    a[KM] = lane_max(a[KM], k);
  }
  // Adds particles [b, e) (SoA coordinates) at vertex x, one after the other (the
  // order of the sums is part of the result: see field_common.hpp); returns how
  // many contribute. Same operations as add().
  template <class Pos>
  KOKKOS_INLINE_FUNCTION static std::uint32_t accumulate(float* a, const Pos& P,
                                                         const float* Rj, const float* Q, std::uint32_t b,
                                                         std::uint32_t e, float x0, float x1, float x2,
                                                         float inv_R2) {
    float a0 = a[0], a1 = a[1], a2 = a[2], a3 = a[3];
    float rs = Radii ? a[RS] : 0.f;
    float km = a[KM];
    std::uint32_t count = 0;
    for (std::size_t j = b; j < e; ++j) {
      float px, py, pz;
      P(j, px, py, pz);
      const float dx = px - x0, dy = py - x1, dz = pz - x2;
      const float q = inv_support2<Radii>(Q, j, inv_R2);
      const float s2 = scaled_distance2(dx, dy, dz, q);
      if (!(s2 < 1.f)) continue;  // it would add exactly +0 (field_common.hpp)
      const float k = s2 < 1.f ? 1.f - s2 : 0.f;
      count += s2 < 1.f ? 1u : 0u;
      const float w = k * k * k;
      a0 += w;
      a1 = fmadd(w, dx, a1);
      a2 = fmadd(w, dy, a2);
      a3 = fmadd(w, dz, a3);
      if constexpr (Radii) rs = fmadd(w, Rj[j], rs);
      km = lane_max(km, k);
    }
    a[0] = a0; a[1] = a1; a[2] = a2; a[3] = a3;
    if constexpr (Radii) a[RS] = rs;
    a[KM] = km;
    (void)Rj;
    return count;
  }
  KOKKOS_INLINE_FUNCTION static float value(const float* a, const FieldConstants& c) {
    if (!(a[0] > 0)) return c.outside;
    const float inv = 1.f / a[0];
    const float x = a[1] * inv, y = a[2] * inv, z = a[3] * inv;
    const float rbar = Radii ? a[RS] * inv : c.iso_radius;
    return distance_guard(Kokkos::Experimental::sqrt(x * x + y * y + z * z) - rbar, a[KM], c.R, c);
  }
};
using FieldZB05 = FieldZB05T<false>;

}  // namespace Details
}  // namespace nbmc
