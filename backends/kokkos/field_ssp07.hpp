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

#include <cstdint>

namespace nbmc {
namespace Details {

// cos(acos(r) / 3) for r in [-1, 1], the largest root of 4c^3 - 3c = r:
// a polynomial of degree 9 in t = 2s - 1, s = sqrt((1 + r) / 2) (with
// u = acos(s), the function is cos(2u/3), analytic in s on [0, 1]; its
// Chebyshev interpolant at 10 nodes, monomial coefficients rounded to
// float), Horner with fused multiply-adds. Only IEEE operations (+, *, the
// square root, fma), so the CPU and the GPU give the same bits, which
// glibc's and CUDA's acosf and cosf did not always. Every float r in
// [-1, 1], sampled every 997th, against a long double reference: at most
// 1.08 ulp (mean 0.27); cosf(acosf(r) / 3) of glibc 2.36: 1.53 ulp (mean
// 0.27). On the CPU it replaces two calls into the C library (8 % of a
// 1.65 M frame's time at cell r/2, R = 2r, perf on the dev VM).
KOKKOS_INLINE_FUNCTION float cos_third_acos(float r) {
  const float s = Kokkos::Experimental::sqrt((1.f + r) * 0.5f);
  const float t = 2.f * s - 1.f;
  float h = 6.96938741e-07f;
  h = fmadd(h, t, -2.4961721e-06f);
  h = fmadd(h, t, 7.41952726e-06f);
  h = fmadd(h, t, -2.84990274e-05f);
  h = fmadd(h, t, 0.000116469746f);
  h = fmadd(h, t, -0.000504277996f);
  h = fmadd(h, t, 0.0024663473f);
  h = fmadd(h, t, -0.0155091695f);
  h = fmadd(h, t, 0.247409061f);
  return fmadd(h, t, 0.766044438f);
}

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
  return q + 2.f * p * cos_third_acos(r);
}

// Radii = true: per-particle support R_j and radius r_j (field_common.hpp):
// the gradient terms carry each particle's own 1/R_j^2 (grad k_j =
// 6 k_j^2 d_j / R_j^2), and rbar = sum w_j r_j / sum w_j, eq. (1)'s weighted
// average radius, with w_j = k_j^3 the weights of xbar (NeighbourView::weight
// holds r_j = iso_radius t_j).
template <bool Radii>
struct FieldSSP07T {
  static constexpr const char* name = "ssp07";
  // a[0] = W = sum k^3, a[1..3] = sum k^3 d, a[4..6] = sum k^2 d (grad k without 6/R^2),
  // a[7..12] = sum d_a k^2 d_b, a symmetric matrix: its upper triangle, (a, b) =
  // 00, 01, 02, 11, 12, 22; radii: a[4..12] times q_j, a[13] = sum k^3 r_j
  static constexpr int P = Radii ? 1 : 0;  // radii: the particle's radius r_j
  static constexpr bool radii = Radii;
  static constexpr int RS = 13;                // radii: sum k^3 r_j
  static constexpr int KM = Radii ? 14 : 13;   // largest k (the distance guard)
  static constexpr int N = KM + 1;
  // T is float, or a host SIMD vector of floats (same formula, lane-wise).
  template <class T>
  KOKKOS_INLINE_FUNCTION static void add(T* a, T dx, T dy, T dz, T k, const float* pd, T q) {
    T k2 = k * k;
    const T w = k2 * k;
    a[0] += w;
    a[1] = fmadd(w, dx, a[1]);
    a[2] = fmadd(w, dy, a[2]);
    a[3] = fmadd(w, dz, a[3]);
    if constexpr (Radii) {
      a[RS] = fmadd(w, lanes_of<T>(pd[0]), a[RS]);
      k2 = k2 * q;
    } else {
      (void)pd;
      (void)q;
    }
    a[KM] = lane_max(a[KM], k);
    const T gx = k2 * dx, gy = k2 * dy, gz = k2 * dz;
    a[4] += gx;
    a[5] += gy;
    a[6] += gz;
    a[7] = fmadd(dx, gx, a[7]); a[8] = fmadd(dx, gy, a[8]); a[9] = fmadd(dx, gz, a[9]);
    a[10] = fmadd(dy, gy, a[10]); a[11] = fmadd(dy, gz, a[11]);
    a[12] = fmadd(dz, gz, a[12]);
  }
  // Adds particles [b, e) (SoA coordinates) at vertex x, one after the other (the
  // order of the sums is part of the result: see field_common.hpp); returns how
  // many contribute. Same operations as add().
  template <class Pos>
  KOKKOS_INLINE_FUNCTION static std::uint32_t accumulate(float* a, const Pos& P,
                                                         const float* Rj, const float* Q, std::uint32_t b,
                                                         std::uint32_t e, float x0, float x1, float x2,
                                                         float inv_R2) {
    float w0 = a[0], d0 = a[1], d1 = a[2], d2 = a[3], g0 = a[4], g1 = a[5], g2 = a[6];
    float m00 = a[7], m01 = a[8], m02 = a[9], m11 = a[10], m12 = a[11], m22 = a[12];
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
      float k2 = k * k;
      const float w = k2 * k;
      w0 += w;
      d0 = fmadd(w, dx, d0);
      d1 = fmadd(w, dy, d1);
      d2 = fmadd(w, dz, d2);
      if constexpr (Radii) {
        rs = fmadd(w, Rj[j], rs);
        k2 = k2 * q;
      }
      const float gx = k2 * dx, gy = k2 * dy, gz = k2 * dz;
      g0 += gx;
      g1 += gy;
      g2 += gz;
      m00 = fmadd(dx, gx, m00); m01 = fmadd(dx, gy, m01); m02 = fmadd(dx, gz, m02);
      m11 = fmadd(dy, gy, m11); m12 = fmadd(dy, gz, m12);
      m22 = fmadd(dz, gz, m22);
      km = lane_max(km, k);
    }
    a[0] = w0; a[1] = d0; a[2] = d1; a[3] = d2; a[4] = g0; a[5] = g1; a[6] = g2;
    a[7] = m00; a[8] = m01; a[9] = m02; a[10] = m11; a[11] = m12; a[12] = m22;
    if constexpr (Radii) a[RS] = rs;
    a[KM] = km;
    (void)Rj;
    return count;
  }
  KOKKOS_INLINE_FUNCTION static float eigenvalue(const float* a, const FieldConstants& c) {
    const float inv = 1.f / a[0];
    // With radii the sums carry their 1/R_j^2 already.
    const float s = Radii ? 6.f * inv : 6.f * c.inv_R2 * inv;
    const float db[3] = {a[1] * inv, a[2] * inv, a[3] * inv};
    const float g[3] = {a[4], a[5], a[6]};
    // sum d_a k^2 d_b is symmetric (one sum per pair, a[7..12]); the
    // Jacobian is not, through dbar_a (grad k)_b.
    const int m[9] = {7, 8, 9, 8, 10, 11, 9, 11, 12};
    float J[9];
    for (int r = 0; r < 3; ++r)
      for (int q = 0; q < 3; ++q) J[3 * r + q] = s * (a[m[3 * r + q]] - db[r] * g[q]);
    return largest_eigenvalue_sym3(J[0], J[4], J[8], 0.5f * (J[1] + J[3]), 0.5f * (J[2] + J[6]),
                                   0.5f * (J[5] + J[7]));
  }
  KOKKOS_INLINE_FUNCTION static float value(const float* a, const FieldConstants& c) {
    if (!(a[0] > 0)) return c.outside;
    const float inv = 1.f / a[0];
    const float x = a[1] * inv, y = a[2] * inv, z = a[3] * inv;
    const float ev = eigenvalue(a, c);
    float f = 1.f;
    if (!(ev < c.t_low)) {
      float g = (c.t_high - ev) / (c.t_high - c.t_low);
      g = g < 0.f ? 0.f : (g > 1.f ? 1.f : g);
      f = g * g * g - 3.f * g * g + 3.f * g;
    }
    const float rbar = Radii ? a[RS] * inv : c.iso_radius;
    return distance_guard(Kokkos::Experimental::sqrt(x * x + y * y + z * z) - rbar * f, a[KM], c.R, c);
  }
};
using FieldSSP07 = FieldSSP07T<false>;

}  // namespace Details
}  // namespace nbmc
