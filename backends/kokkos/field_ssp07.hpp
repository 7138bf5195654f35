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
template <class T>
KOKKOS_INLINE_FUNCTION T cos_third_acos(T r) {
  const T s = lane_sqrt((1.f + r) * 0.5f);
  const T t = 2.f * s - 1.f;
  T h = lanes_of<T>(6.96938741e-07f);
  h = fmadd(h, t, lanes_of<T>(-2.4961721e-06f));
  h = fmadd(h, t, lanes_of<T>(7.41952726e-06f));
  h = fmadd(h, t, lanes_of<T>(-2.84990274e-05f));
  h = fmadd(h, t, lanes_of<T>(0.000116469746f));
  h = fmadd(h, t, lanes_of<T>(-0.000504277996f));
  h = fmadd(h, t, lanes_of<T>(0.0024663473f));
  h = fmadd(h, t, lanes_of<T>(-0.0155091695f));
  h = fmadd(h, t, lanes_of<T>(0.247409061f));
  return fmadd(h, t, lanes_of<T>(0.766044438f));
}

// Largest eigenvalue of the symmetric matrix [[a, d, e], [d, b, f], [e, f, c]]
// (T: a float, or lanes of them, as lane_sqrt; every lane the float's bits).
template <class T>
KOKKOS_INLINE_FUNCTION T largest_eigenvalue_sym3(T a, T b, T c, T d, T e, T f) {
  const T p1 = d * d + e * e + f * f;
  const T q = (a + b + c) / 3.f;
  const T aa = a - q, bb = b - q, cc = c - q;
  const T p2 = aa * aa + bb * bb + cc * cc + 2.f * p1;
  const T p = lane_sqrt(p2 / 6.f);
  const T inv = 1.f / p;
  // det((S - qI) / p) / 2
  const T ba = aa * inv, bb2 = bb * inv, bc = cc * inv, bd = d * inv, be = e * inv, bf = f * inv;
  T r = 0.5f * (ba * (bb2 * bc - bf * bf) - bd * (bd * bc - bf * be) + be * (bd * bf - bb2 * be));
  r = lane_select(r < -1.f, lanes_of<T>(-1.f), lane_select(r > 1.f, lanes_of<T>(1.f), r));
  // a (nearly) scalar matrix: q (computed for every lane, kept where p2 > 1e-20)
  return lane_select(p2 > 1e-20f, q + 2.f * p * cos_third_acos(r), q);
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
  // The value from the sums, for T a float or (with GCC, on the host) 8 lanes
  // of them (value_lanes in scalar_field.hpp): the same operations in every
  // lane, each lane the scalar's bits; the branches are selects (both sides
  // computed, the one taken kept).
  template <class T>
  KOKKOS_INLINE_FUNCTION static T eigenvalue(const T* a, const FieldConstants& c) {
    const T inv = 1.f / a[0];
    // With radii the sums carry their 1/R_j^2 already.
    const T s = Radii ? 6.f * inv : 6.f * c.inv_R2 * inv;
    const T db[3] = {a[1] * inv, a[2] * inv, a[3] * inv};
    const T g[3] = {a[4], a[5], a[6]};
    // sum d_a k^2 d_b is symmetric (one sum per pair, a[7..12]); the
    // Jacobian is not, through dbar_a (grad k)_b.
    const int m[9] = {7, 8, 9, 8, 10, 11, 9, 11, 12};
    T J[9];
    for (int r = 0; r < 3; ++r)
      for (int q = 0; q < 3; ++q) J[3 * r + q] = s * (a[m[3 * r + q]] - db[r] * g[q]);
    return largest_eigenvalue_sym3(J[0], J[4], J[8], 0.5f * (J[1] + J[3]), 0.5f * (J[2] + J[6]),
                                   0.5f * (J[5] + J[7]));
  }
  static constexpr bool lane_value = true;
  template <class T>
  KOKKOS_INLINE_FUNCTION static T value_t(const T* a, const FieldConstants& c) {
    const T inv = 1.f / a[0];
    const T x = a[1] * inv, y = a[2] * inv, z = a[3] * inv;
    const T ev = eigenvalue(a, c);
    T g = (c.t_high - ev) / (c.t_high - c.t_low);
    g = lane_select(g < 0.f, lanes_of<T>(0.f), lane_select(g > 1.f, lanes_of<T>(1.f), g));
    const T f = lane_select(ev < c.t_low, lanes_of<T>(1.f), g * g * g - 3.f * g * g + 3.f * g);
    T rbar;
    if constexpr (Radii) rbar = a[RS] * inv;
    else rbar = lanes_of<T>(c.iso_radius);
    const T phi = distance_guard(lane_sqrt(x * x + y * y + z * z) - rbar * f, a[KM], c.R, c);
    return lane_select(a[0] > 0.f, phi, lanes_of<T>(c.outside));
  }
  KOKKOS_INLINE_FUNCTION static float value(const float* a, const FieldConstants& c) { return value_t(a, c); }
};
using FieldSSP07 = FieldSSP07T<false>;

}  // namespace Details
}  // namespace nbmc
