// SPDX-License-Identifier: MIT
// The normalised SPH density, the level set of splashsurf (docs/methods.md
// compares the two):
//   rho(x) = sum_j V_j W(|x - x_j|),  V_j = m / rho_j,  rho_j = m sum_k W(|x_j - x_k|)
// with the cubic spline kernel of compact support h = R (the influence radius),
//   W(q) = sigma (1 - 6 q^2 + 6 q^3)  for q = |d| / h <= 1/2,
//          sigma 2 (1 - q)^3           for 1/2 < q < 1, 0 beyond,
// and the surface rho(x) = iso_threshold (a fraction of the rest density).
// The mass m and sigma = 8 / (pi h^3) cancel: rho(x) = sum_j W~(x - x_j) / D_j
// with W~ = W / sigma and D_j = sum_k W~(x_j - x_k) (k = j included, so
// D_j >= W~(0) = 1). phi(x) = iso_threshold - rho(x): negative inside.
//
// The particles' 1 / D_j are their weights (NeighbourView::pdata), computed
// before the field, for the particles the band reaches, by SphWeights
// (sph_density.hpp) with the same kernel and the same summation order as a
// vertex's field value.
//
// Per-particle radii (Radii = true, field_common.hpp): particle j's smoothing
// length is h_j = R_j = R t_j. With masses m_j ~ r_j^3 (the particles' own
// volumes) and W(., h_j) = sigma_j W~, sigma_j ~ 1 / h_j^3, the masses and the
// sigmas cancel again: rho(x) = sum_j W~(|x - x_j| / h_j) / D_j with
// D_j = sum_k W~(|x_j - x_k| / h_k) -- the same sums with each particle's own
// support.
#pragma once

#include "field_common.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#if !defined(__CUDA_ARCH__) && defined(__SSE__)
#include <xmmintrin.h>
#endif
#if defined(NBMC_HOST_SIMD8) || defined(NBMC_HOST_SIMD16)  // field_common.hpp
#include <immintrin.h>
#endif
#if defined(NBMC_HOST_SIMD8)
#define NBMC_HOST_AVX_SQRT 1
#endif

namespace nbmc {
namespace Details {

// The IEEE square root, of a float or lane by lane of a host SIMD vector.
KOKKOS_INLINE_FUNCTION float sqrt_lanes(float x) { return Kokkos::Experimental::sqrt(x); }

// W / sigma at q = |d| / h from q and q^2, 0 <= q <= 1 (exactly 0 at q = 1):
// 1 - 6 q^2 + 6 q^3 up to 1/2, 2 (1 - q)^3 beyond. One expression for the
// device, the scalar host code and, lane by lane, the host SIMD vectors.
KOKKOS_INLINE_FUNCTION float cubic_spline(float q, float q2) {
  const float inner = (1.f - 6.f * q2) + (6.f * q2) * q;
  const float u = 1.f - q;
  const float outer = 2.f * (u * u * u);
  return q <= 0.5f ? inner : outer;
}

// W / sigma as a function of k = 1 - q^2 (what the drivers pass; k = 0 gives
// exactly 0).
KOKKOS_INLINE_FUNCTION float sph_kernel(float k) {
  const float q2 = 1.f - k;
  return cubic_spline(sqrt_lanes(q2), q2);
}

#if !defined(__CUDA_ARCH__)
#if defined(NBMC_HOST_AVX_SQRT) || defined(NBMC_HOST_SIMD16)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // 32- and 64-byte vectors never cross a call that is not inlined
#endif
#if defined(NBMC_HOST_AVX_SQRT)
// 8 lanes only run inside the AVX2 kernels (scalar_field.hpp), which inline
// this: one 256-bit IEEE square root instead of two 128-bit ones.
__attribute__((target("avx"))) inline HostSimd<8>::F sqrt_lanes(HostSimd<8>::F x) {
  __m256 v;
  std::memcpy(&v, &x, 32);
  v = _mm256_sqrt_ps(v);
  HostSimd<8>::F q;
  std::memcpy(&q, &v, 32);
  return q;
}
#endif
#if defined(NBMC_HOST_SIMD16)
// 16 lanes only run inside the AVX-512F kernels: one 512-bit square root.
__attribute__((target("avx512f"))) inline HostSimd<16>::F sqrt_lanes(HostSimd<16>::F x) {
  __m512 v;
  std::memcpy(&v, &x, 64);
  v = _mm512_sqrt_ps(v);
  HostSimd<16>::F q;
  std::memcpy(&q, &v, 64);
  return q;
}
#endif
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#endif
// Host SIMD vectors of any lane count (4; 8 and 16 have their own above).
template <class V>
inline V sqrt_lanes(V x) {
  V q;
#if defined(__SSE__)
  // IEEE square roots, 4 lanes per SSE instruction (the same results as the
  // scalar std::sqrt and the device's sqrt; SSE is part of x86-64).
  for (std::size_t l = 0; l < sizeof(V) / 16; ++l) {
    __m128 v;
    std::memcpy(&v, reinterpret_cast<const char*>(&x) + 16 * l, 16);
    v = _mm_sqrt_ps(v);
    std::memcpy(reinterpret_cast<char*>(&q) + 16 * l, &v, 16);
  }
#else
  for (int l = 0; l < int(sizeof(V) / sizeof(float)); ++l) q[l] = std::sqrt(x[l]);  // IEEE sqrt, as on the device
#endif
  return q;
}
template <class V>
inline V cubic_spline(V q, V q2) {
  const V one = lanes_of<V>(1.f), six = lanes_of<V>(6.f);
  const V inner = (one - six * q2) + (six * q2) * q;
  const V u = one - q;
  const V outer = lanes_of<V>(2.f) * (u * u * u);
  const auto m = q <= lanes_of<V>(0.5f);
  using I = decltype(m);
  return (V)(((I)inner & m) | ((I)outer & ~m));
}
template <class V>
inline V sph_kernel_lanes(V k) {
  const V q2 = lanes_of<V>(1.f) - k;
  return cubic_spline(sqrt_lanes(q2), q2);
}
inline HostVecF sph_kernel(HostVecF k) { return sph_kernel_lanes(k); }
#if defined(NBMC_HOST_SIMD8)
inline HostSimd<8>::F sph_kernel(HostSimd<8>::F k) { return sph_kernel_lanes(k); }
#endif
#if defined(NBMC_HOST_SIMD16)
inline HostSimd<16>::F sph_kernel(HostSimd<16>::F k) { return sph_kernel_lanes(k); }
#endif
#endif

template <bool Radii>
struct FieldSPHT {
  static constexpr const char* name = "sph";
  static constexpr int P = 1;  // the weight 1 / D_j
  static constexpr bool radii = Radii;
  // a[0] = sum_j W~_j / D_j, a[1] = the largest k (the distance guard)
  static constexpr int KM = 1;
  static constexpr int N = 2;
  // T is float, or a host SIMD vector of floats (same formula, lane-wise).
  template <class T>
  KOKKOS_INLINE_FUNCTION static void add(T* a, T /*dx*/, T /*dy*/, T /*dz*/, T k, const float* w,
                                         T /*q: in k already*/) {
    a[0] = fmadd(sph_kernel(k), lanes_of<T>(w[0]), a[0]);
    a[KM] = lane_max(a[KM], k);
  }
  // Adds particles [b, e) (SoA coordinates, weights W) at vertex x, one after
  // the other (see field_common.hpp); returns how many contribute. Same
  // operations as add().
  template <class Pos>
  KOKKOS_INLINE_FUNCTION static std::uint32_t accumulate(float* a, const Pos& P,
                                                         const float* W, const float* Q, std::uint32_t b,
                                                         std::uint32_t e, float x0, float x1, float x2,
                                                         float inv_R2) {
    float a0 = a[0], km = a[KM];
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
      a0 = fmadd(sph_kernel(k), W[j], a0);
      km = lane_max(km, k);
    }
    a[0] = a0;
    a[KM] = km;
    return count;
  }
  KOKKOS_INLINE_FUNCTION static float value(const float* a, const FieldConstants& c) {
    return distance_guard(c.iso_threshold - a[0], a[KM], 1.f, c);
  }
};
using FieldSPH = FieldSPHT<false>;

// D_j of one particle: the same sum with unit weights (not a field method
// of its own; SphWeights evaluates it at the particles the band reaches).
template <bool Radii>
struct SphDensityT {
  static constexpr const char* name = "sph-density";
  static constexpr int P = 0;
  static constexpr bool radii = Radii;
  static constexpr int N = 1;
  template <class T>
  KOKKOS_INLINE_FUNCTION static void add(T* a, T, T, T, T k, const float*, T) {
    a[0] += sph_kernel(k);
  }
  template <class Pos>
  KOKKOS_INLINE_FUNCTION static std::uint32_t accumulate(float* a, const Pos& P,
                                                         const float*, const float* Q, std::uint32_t b,
                                                         std::uint32_t e, float x0, float x1, float x2,
                                                         float inv_R2) {
    float a0 = a[0];
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
      a0 += sph_kernel(k);
    }
    a[0] = a0;
    return count;
  }
  KOKKOS_INLINE_FUNCTION static float value(const float* a, const FieldConstants&) { return a[0]; }
};
using SphDensity = SphDensityT<false>;

}  // namespace Details
}  // namespace nbmc
