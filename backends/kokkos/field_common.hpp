// SPDX-License-Identifier: MIT
// What every scalar-field method shares: the kernel k(s) = max(0, (1 - s^2)^3)
// of eq. (5), the constants of a field evaluation, and the value given to
// vertices that no particle reaches.
//
// A method is a type with
//   static constexpr int N;                       // accumulator size (floats, zero-initialised)
//   static constexpr int P;                       // floats of per-particle data it reads (below)
//   static constexpr bool radii;                  // per-particle kernel support (below)
//   static void add(float* a, dx, dy, dz, k, pd, q) // contribution of one particle, d = x_j - x,
//                                                 // k = max(0, 1 - |d|^2/R_j^2) (0: no contribution),
//                                                 // pd = particle j's P floats (nullptr if P = 0),
//                                                 // q = 1/R_j^2 (radii methods; else 1, unused)
//   static uint32_t accumulate(a, pos, PD, Q, b, e, x0, x1, x2, inv_R2)
//                                                 // the same for particles [b, e), in order
//                                                 // (pos(j, x, y, z): particle j's position,
//                                                 // SoaPositions or Aos4Positions below;
//                                                 // PD: the data, P floats per particle, nullptr if P = 0;
//                                                 // Q: the 1/R_j^2, nullptr if not radii)
//   static float value(const float* a, const FieldConstants&)  // phi(x); negative inside
// so the gather (narrow band, dense) and the scatter drivers are written once.
// A method's per-particle data come from a pass over the particles before the
// field (NeighbourView::pdata, P floats per particle in the sorted order; SPH:
// a weight, field_sph.hpp; YT10: a kernel, field_yt10.hpp); a particle that
// contributes nothing (k = 0) must add exactly +0 whatever its data (an
// accumulator is never -0), so that skipping it changes no sum: accumulate
// and the device gathers skip the particles with s2 >= 1.
//
// Per-particle radii (nbmc_context_set_radii_*, radii.hpp): each method has
// a variant (radii = true) in which particle j has its own kernel support
// R_j = R t_j, t_j = r_j / r_max <= 1, R the frame's influence radius (that
// of the largest particle): k_j = max(0, 1 - |d|^2 q_j), q_j = 1/R_j^2
// (NeighbourView::support, q_j >= 1/R^2 as floats, so every pruning by R
// stays exact). Without radii the variant is not instantiated and the
// uniform code is what it always was.
//
// Summation order: every backend adds a vertex's contributions one at a time,
// in the order of eval_vertex_direct (cells in z, y, x order, particles in
// their sorted order), with the same float operations in the same order, so
// that CPU and GPU give bit-identical values (the library is compiled without
// FMA contraction; the sums of products use the explicit fmadd below).
// `add` and `accumulate` must stay the same expression tree.
// The host vectorises across vertices (or particles i), never across the
// terms of one sum.
#pragma once

#include <Kokkos_Core.hpp>

#include <cstdint>
#include <cstring>
#include <type_traits>

// Whether the 8-lane kernels (AVX2, chosen at run time) are compiled: on
// x86-64 with GCC, or with any compiler that compiles the whole translation
// unit for AVX2 (-mavx2, -march=native). Clang rejects a 32-byte vector
// passed to a function not compiled for AVX even where that function is
// inlined into an AVX2 one, so a Clang build without -mavx2 uses 4 lanes
// (the same results: the lane count never changes a value). Under nvcc
// (a CUDA build compiles every file with it, the host backends' too) the
// host pass has them as well (checked with nvcc 13 and GCC 13); until
// session 23 they were left out there, so a CUDA build's OpenMP backend ran
// 4 lanes.
#if !defined(__CUDA_ARCH__) && defined(__x86_64__) && defined(__GNUC__) && (!defined(__clang__) || defined(__AVX2__))
#define NBMC_HOST_SIMD8 1
#endif
// The same for the 16-lane kernels (AVX-512F, chosen at run time): GCC on
// x86-64, or a compiler told -mavx512f.
#if !defined(__CUDA_ARCH__) && defined(__x86_64__) && defined(__GNUC__) && (!defined(__clang__) || defined(__AVX512F__))
#define NBMC_HOST_SIMD16 1
#endif
#if defined(NBMC_HOST_SIMD8) || defined(NBMC_HOST_SIMD16)
#include <immintrin.h>
#endif

namespace nbmc {
namespace Details {

// v in every lane of T (a float, or a host SIMD vector of floats); v - (+0)
// is v for every v, -0 included.
template <class T>
KOKKOS_INLINE_FUNCTION T lanes_of(float v) {
  return v - T{};
}

#if !defined(__CUDA_ARCH__)
// Host SIMD vectors (GCC/Clang vector extensions), one lane per vertex or
// particle; lane-wise IEEE operations, so every lane computes exactly what the
// scalar code computes.
constexpr int kHostLanes = 4;
typedef float HostVecF __attribute__((vector_size(4 * kHostLanes)));
typedef std::int32_t HostVecI __attribute__((vector_size(4 * kHostLanes)));

static_assert(kHostLanes == 4, "host_splat and host_any are written for 4 lanes");
inline HostVecF host_splat(float v) { return HostVecF{v, v, v, v}; }
// Whether any lane of a comparison mask is set.
inline bool host_any(HostVecI m) {
  std::uint64_t u[2];
  std::memcpy(u, &m, sizeof m);
  return (u[0] | u[1]) != 0;
}

// The same for L lanes (4, 8 or 16), for kernels templated on the lane
// count. 8 lanes are only used inside functions compiled for AVX2, 16 inside
// functions compiled for AVX-512F, chosen at run time (host_simd_lanes in
// scalar_field.hpp); each lane still does the scalar code's IEEE operations
// (nbmc compiles without FMA contraction; the only fused operations are the
// explicit fmadd below, the same in every lane and on every backend), so the
// lane count never changes a result. (GCC's -Wpsabi
// note on 32- and 64-byte vectors does not apply: they never cross a call
// that is not inlined.)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"
#endif
template <int L>
struct HostSimd;
template <>
struct HostSimd<4> {
  typedef HostVecF F;
  typedef HostVecI I;
};
template <>
struct HostSimd<8> {
  typedef float F __attribute__((vector_size(32)));
  typedef std::int32_t I __attribute__((vector_size(32)));
};
template <>
struct HostSimd<16> {
  typedef float F __attribute__((vector_size(64)));
  typedef std::int32_t I __attribute__((vector_size(64)));
};
#if defined(NBMC_HOST_SIMD16)
// GCC 12 with its default tuning (-mtune=generic) compiles some operations
// on 64-byte vectors lane by lane even inside AVX-512F functions: a float
// in every lane of the generic lanes_of (v - T{}, folded to {v, ..., v})
// becomes 16 masked broadcasts, for every particle of the tile kernel (16
// lanes were 1.45x slower than 8), two comparisons ANDed become 32 scalar
// ones, and host_any_of's OR of the words a chain of extracts. So the 16
// lanes have these in intrinsics (the same bits: a broadcast keeps -0).
// A tune= in the kernels' target attribute would also do, but GCC inlines
// no function tuned otherwise into them.
template <>
__attribute__((target("avx512f"))) inline HostSimd<16>::F lanes_of<HostSimd<16>::F>(float v) {
  const __m512 b = _mm512_set1_ps(v);
  HostSimd<16>::F r;
  std::memcpy(&r, &b, 64);
  return r;
}
#endif
template <class M>
inline bool host_any_of(M m) {
  std::uint64_t u[sizeof(M) / 8];
  std::memcpy(u, &m, sizeof m);
  std::uint64_t o = 0;
  for (std::size_t q = 0; q < sizeof(M) / 8; ++q) o |= u[q];
  return o != 0;
}
#if defined(NBMC_HOST_SIMD16)
template <>
__attribute__((target("avx512f"))) inline bool host_any_of<HostSimd<16>::I>(HostSimd<16>::I m) {
  __m512i v;
  std::memcpy(&v, &m, 64);
  return _mm512_test_epi32_mask(v, v) != 0;
}
#endif
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

#endif

// a * b + c rounded once (IEEE fused multiply-add), for a float or a host
// SIMD vector of floats (lane-wise). The methods' sums of products, c +=
// a * b, are written with it: the library is compiled without FMA
// contraction, so these are the only fused operations, and they are the same
// on every backend (an explicit FMA is exactly specified: CUDA's fmaf, the
// host's vfmadd or, without one, the C library's fmaf), which keeps CPU and
// GPU bit-identical. One instruction instead of two, in the inner loops of
// the field on both (SSP07: 9 of about 40 operations per particle).
KOKKOS_INLINE_FUNCTION float fmadd(float a, float b, float c) {
#if defined(__CUDA_ARCH__)
  return __fmaf_rn(a, b, c);
#else
  return __builtin_fmaf(a, b, c);
#endif
}
#if !defined(__CUDA_ARCH__)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"
#endif
// Host vectors: lane by lane (4 lanes, chosen only where the CPU has no
// AVX2; the C library's fmaf is exact everywhere) ...
template <class T>
inline T fmadd(T a, T b, T c) {
  T r;
  for (std::size_t l = 0; l < sizeof(T) / sizeof(float); ++l) r[l] = __builtin_fmaf(a[l], b[l], c[l]);
  return r;
}
// ... and one instruction in the 8- and 16-lane kernels (compiled for FMA
// and AVX-512F, chosen at run time: scalar_field.hpp's host_simd_lanes).
#if defined(NBMC_HOST_SIMD8)
template <>
__attribute__((target("avx2,fma"))) inline HostSimd<8>::F fmadd<HostSimd<8>::F>(HostSimd<8>::F a, HostSimd<8>::F b,
                                                                              HostSimd<8>::F c) {
  __m256 x, y, z;
  std::memcpy(&x, &a, 32);
  std::memcpy(&y, &b, 32);
  std::memcpy(&z, &c, 32);
  const __m256 r = _mm256_fmadd_ps(x, y, z);
  HostSimd<8>::F o;
  std::memcpy(&o, &r, 32);
  return o;
}
#endif
#if defined(NBMC_HOST_SIMD16)
template <>
__attribute__((target("avx512f"))) inline HostSimd<16>::F fmadd<HostSimd<16>::F>(HostSimd<16>::F a, HostSimd<16>::F b,
                                                                                HostSimd<16>::F c) {
  __m512 x, y, z;
  std::memcpy(&x, &a, 64);
  std::memcpy(&y, &b, 64);
  std::memcpy(&z, &c, 64);
  const __m512 r = _mm512_fmadd_ps(x, y, z);
  HostSimd<16>::F o;
  std::memcpy(&o, &r, 64);
  return o;
}
#endif
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#endif

// s^2 = |d|^2 q, a particle's squared distance from the vertex over its
// squared support (q = 1 / R^2, or 1 / R_j^2 with radii), the same on every
// backend and in every method's sums: fma(dz, dz, fma(dy, dy, dx * dx)) * q,
// two fused operations (one instruction each, two fewer per particle visit
// than the sum of three products). Every rounding step is monotone, so s^2
// is at least fl(fl(dx^2) q): the row trims and the skipped runs of the
// gathers (scalar_field.hpp) test that.
template <class T>
KOKKOS_INLINE_FUNCTION T scaled_distance2(T dx, T dy, T dz, T q) {
  return fmadd(dz, dz, fmadd(dy, dy, dx * dx)) * q;
}

// Particle positions for accumulate(): three arrays (the neighbourhood's
// layout, and the team gather's staging), or one float4 per particle (x, y,
// z, unused; Neighbourhood::pos4, the device gathers: one 16-byte load
// instead of three). The same floats either way.
struct SoaPositions {
  const float* X;
  const float* Y;
  const float* Z;
  KOKKOS_INLINE_FUNCTION void operator()(std::size_t j, float& x, float& y, float& z) const {
    x = X[j];
    y = Y[j];
    z = Z[j];
  }
};
struct Aos4Positions {
  const float* P;  // 16-byte aligned
  KOKKOS_INLINE_FUNCTION void operator()(std::size_t j, float& x, float& y, float& z) const {
#if defined(__CUDA_ARCH__)
    const float4 p = reinterpret_cast<const float4*>(P)[j];
    x = p.x;
    y = p.y;
    z = p.z;
#else
    x = P[4 * j];
    y = P[4 * j + 1];
    z = P[4 * j + 2];
#endif
  }
};

// 1/R_j^2 of particle j in accumulate(): its own (Q[j]) for the radii
// variants, the frame's inv_R2 otherwise.
template <bool Radii>
KOKKOS_INLINE_FUNCTION float inv_support2(const float* Q, std::size_t j, float inv_R2) {
  if constexpr (Radii) {
    (void)inv_R2;
    return Q[j];
  } else {
    (void)Q;
    (void)j;
    return inv_R2;
  }
}

struct FieldConstants {
  float R = 0;           // influence radius
  float inv_R2 = 0;      // 1 / R^2
  float iso_radius = 0;  // r-bar
  float t_low = 0.4f, t_high = 3.5f;
  float iso_threshold = 0.6f;  // SPH, YT10: iso level of the normalised density
  float outside = 0;     // phi where no particle contributes
  // The distance guard (nbmc_params.max_distance): rho / R, 0 = off.
  float guard_ratio = 0;
};

// The distance guard. A method with a guard keeps, besides its sums, the
// largest k of a vertex, k_max = 1 - |d|^2 / R_j^2 of its nearest particle
// (with radii, of the particle nearest in units of its own support). Where
// no particle lies within rho (rho_j = rho R_j / R with radii, rho / R =
// guard_ratio), that is where sqrt(1 - k_max) > rho / R, phi is raised to
// the guard's value, so that the surface stays within about rho of the
// particles (bench/RESULTS.md: within rho + 0.4 r at cell r). In units of
// R the guard is u = sqrt(1 - k_max) - rho / R, the distance to that
// particle minus rho over R: the distance methods (SSP07, ZB05) compare R u
// with their phi, the SPH density (dimensionless) u itself. The guard is a
// maximum (an intersection of the surface with the union of the balls of
// radius rho around the particles): exact, the same on every backend.

// max(a, b) lane-wise (T a float or a host SIMD vector of floats). It is
// exact and does not depend on the order; a particle that does not
// contribute (k = 0) leaves k_max (never below +0) as it is, as every sum.
template <class T>
KOKKOS_INLINE_FUNCTION T lane_max(T a, T b) {
#if defined(__CUDA_ARCH__)
  // One FMNMX instead of a compare and a select: the same value where
  // neither is NaN (k_max starts at +0 and takes only k > 0).
  return fmaxf(a, b);
#elif defined(__GNUC__) && !defined(__clang__)
  return b > a ? b : a;  // vectors too: GCC's vector ?: (one maxps)
#else
  if constexpr (std::is_same<T, float>::value) {
    return b > a ? b : a;
  } else {
    const auto m = b > a;
    using I = decltype(m);
    return (T)(((I)b & m) | ((I)a & ~m));
  }
#endif
}

// The IEEE square root in every lane (T a float, or with GCC a host SIMD
// vector of 8 floats: one vsqrtps), and m ? a : b lane-wise (GCC's vector
// ?: for vectors, m a comparison of them). For the methods' values computed
// on lanes (value_t), which must give each lane the scalar code's bits.
template <class T>
KOKKOS_INLINE_FUNCTION T lane_sqrt(T v) {
  return Kokkos::Experimental::sqrt(v);
}
#if defined(NBMC_HOST_SIMD8)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"
#endif
template <>
__attribute__((target("avx2,fma"))) inline HostSimd<8>::F lane_sqrt<HostSimd<8>::F>(HostSimd<8>::F v) {
  __m256 x;
  std::memcpy(&x, &v, 32);
  const __m256 r = _mm256_sqrt_ps(x);
  HostSimd<8>::F o;
  std::memcpy(&o, &r, 32);
  return o;
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#endif
template <class M, class T>
KOKKOS_INLINE_FUNCTION T lane_select(M m, T a, T b) {
  return m ? a : b;
}

// phi raised to the guard (scale: R for the distance methods, 1 for the
// density) where the guard is on. T: as lane_sqrt.
template <class T>
KOKKOS_INLINE_FUNCTION T distance_guard(T phi, T k_max, float scale, const FieldConstants& c) {
  if (!(c.guard_ratio > 0.f)) return phi;
  const T g = scale * (lane_sqrt(1.f - k_max) - c.guard_ratio);
  return lane_select(g > phi, g, phi);
}

// guard_ratio: max_distance / R (Params, guard_ratio()), 0 = no guard.
inline FieldConstants field_constants(double R, double iso_radius, double t_low, double t_high,
                                      double iso_threshold = 0.6, double guard_ratio = 0) {
  FieldConstants f;
  f.R = float(R);
  f.inv_R2 = float(1.0 / (R * R));
  f.iso_radius = float(iso_radius);
  f.t_low = float(t_low);
  f.t_high = float(t_high);
  f.iso_threshold = float(iso_threshold);
  f.outside = float(R);
  f.guard_ratio = float(guard_ratio);
  return f;
}

}  // namespace Details
}  // namespace nbmc
