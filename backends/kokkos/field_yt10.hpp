// SPDX-License-Identifier: MIT
// Yu & Turk 2010 ("Reconstructing surfaces of particle-based fluids using
// anisotropic kernels"; docs/methods.md has the long form): the normalised
// SPH density of field_sph.hpp with one stretched kernel per particle,
//   f(x) = sum_j det(h G_j) W~(|G_j (x - xbar_j)|) / D_j,   phi = iso_threshold - f,
// W~ the cubic spline over its factor (support 1 in |G r|), h = R/2 the
// isotropic support, D_j = sum_k W~(|x_j - x_k| / h) the isotropic density
// (k = j included), and per particle j, from its neighbours within R with
// the weights w_jk = 1 - (|x_j - x_k| / R)^3:
//   x_w = sum_k w_jk x_k / sum_k w_jk                       (weighted mean)
//   C   = sum_k w_jk (x_k - x_w)(x_k - x_w)^T / sum_k w_jk   (weighted covariance)
//   C   = Q diag(sigma_1 >= sigma_2 >= sigma_3) Q^T          (Jacobi, below)
//   s_1 = clamp(k_s sigma_1 / sigma_0, k_n, 1.5),  s_2,3 = clamp(k_s sigma_2,3 / sigma_0, s_1 / k_r, s_1)
//         if the particle has more than N_eps neighbours within R, else s_1,2,3 = k_n
//   G_j = (1/h) Q diag(1/s_1, 1/s_2, 1/s_3) Q^T
//   xbar_j = x_j + lambda (x_w - x_j), moved at most 0.2 R
// sigma_0 = 3 R^2 / 20 is the covariance of a uniform fluid under these
// weights (the continuum limit; a particle deep inside gets sigma ~ sigma_0),
// so k_s is dimensionless and k_s = 1 gives such a particle the isotropic
// kernel, G = I / h (Yu & Turk's k_s = 1400 plays the part of 1 / sigma_0 in
// the units of their scenes). In a uniform fluid f = 1, as for the SPH
// density.
//
// Every kernel lies within 0.75 R + 0.2 R = 0.95 R of its particle
// (kYt10MaxAxis, kYt10MaxShift in src/core/params.hpp): inside the influence
// radius of the band, the neighbour search and the ghost layers (2R: a
// particle's kernel depends on its neighbours within R). The field visits
// the particles within R_f of a vertex, R_f the largest reach of any kernel
// (plus 2%), at most R: particles farther away add exactly 0, so R_f does not
// change a value (and subdomains, whose R_f differ, give the same field).
// Within R_f, a particle whose own reach the vertex lies beyond is skipped
// (it too would add exactly 0).
//
// The pass before the field (compute_yt10_kernels, yt10_kernels.hpp) sums
// each particle's moments like a band vertex's field (eval order of
// eval_vertex_direct) and decomposes C with a fixed number of cyclic Jacobi
// sweeps: no transcendental function but the IEEE square root and division,
// so every backend computes the same kernels bit for bit.
#pragma once

#include "field_common.hpp"
#include "field_sph.hpp"

#include <cstdint>
#include <cstring>
#include <type_traits>

namespace nbmc {
namespace Details {

// A particle's kernel as the field reads it (NeighbourView::pdata, P = 11
// floats): the offset xbar_j - x_j (3), G_j's upper triangle g00 g01 g02
// g11 g12 g22 (6), det(h G_j) / D_j (1), and the square of a bound of its
// reach (1): a vertex at |x - x_j|^2 >= that gets exactly 0 from it, so the
// kernel is not evaluated there (that skip changes no value).
constexpr int kYt10Floats = 11;
// The reach bound's margin over h s_1 + |xbar - x| (rounding of G and of
// the distances is below 1e-5 of them).
constexpr float kYt10ReachMargin = 1.002f;
// Cyclic Jacobi sweeps over the three off-diagonal entries: float converges
// in 4 or 5; a fixed count keeps every backend in step.
constexpr int kYt10JacobiSweeps = 6;

// The cubic spline over its factor (field_sph.hpp's cubic_spline) at q,
// given q and q^2, and exactly +0 from q = 1 on and where k = 0 (a particle
// beyond the visited radius: the drivers need +0 from a particle that does
// not contribute). The callers have q at hand: no square root of 1 - k as in
// sph_kernel.
KOKKOS_INLINE_FUNCTION float yt10_spline(float q, float q2, float k) {
  return q < 1.f && k > 0.f ? cubic_spline(q, q2) : 0.f;
}
#if !defined(__CUDA_ARCH__)
template <class V>
inline V yt10_spline(V q, V q2, V k) {
  const auto in = (q < lanes_of<V>(1.f)) & (k > lanes_of<V>(0.f));
  using I = decltype(in);
  return (V)((I)cubic_spline(q, q2) & in);
}
#if defined(NBMC_HOST_SIMD16)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // 64-byte vectors never cross a call that is not inlined
#endif
// The same for 16 lanes, the mask in intrinsics (field_common.hpp, above
// lanes_of<HostSimd<16>::F>: GCC 12 compiles the two comparisons of the
// generic form lane by lane). Ordered comparisons, as the vector operators.
__attribute__((target("avx512f"))) inline HostSimd<16>::F yt10_spline(HostSimd<16>::F q, HostSimd<16>::F q2,
                                                                       HostSimd<16>::F k) {
  const HostSimd<16>::F s = cubic_spline(q, q2);
  __m512 vq, vk, vs;
  std::memcpy(&vq, &q, 64);
  std::memcpy(&vk, &k, 64);
  std::memcpy(&vs, &s, 64);
  const __mmask16 in = _mm512_cmp_ps_mask(vq, _mm512_set1_ps(1.f), _CMP_LT_OQ) &
                       _mm512_cmp_ps_mask(vk, _mm512_setzero_ps(), _CMP_GT_OQ);
  vs = _mm512_maskz_mov_ps(in, vs);  // +0 where not in, as the generic form's AND
  HostSimd<16>::F r;
  std::memcpy(&r, &vs, 64);
  return r;
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#endif
#endif

// Whether |d|^2 < reach2 (in any lane).
KOKKOS_INLINE_FUNCTION bool yt10_within(float dx, float dy, float dz, float reach2) {
  return (dx * dx + dy * dy) + dz * dz < reach2;
}
#if !defined(__CUDA_ARCH__)
template <class V>
inline bool yt10_within(V dx, V dy, V dz, float reach2) {
  return host_any_of((dx * dx + dy * dy) + dz * dz < lanes_of<V>(reach2));
}
#endif

struct FieldYT10 {
  static constexpr const char* name = "yt10";
  static constexpr int P = kYt10Floats;
  static constexpr bool radii = false;  // no radii variant (refused, params.hpp)
  // a[0] = sum_j det(h G_j) W~(|G_j e_j|) / D_j
  static constexpr int N = 1;
  // T is float, or a host SIMD vector of floats (same formula, lane-wise).
  // d = x_j - x; e = d + (xbar_j - x_j) = xbar_j - x (|G e| = |G (x - xbar_j)|).
  template <class T>
  KOKKOS_INLINE_FUNCTION static void add(T* a, T dx, T dy, T dz, T k, const float* pd, T /*q: uniform*/) {
    if (!yt10_within(dx, dy, dz, pd[10])) return;  // exactly 0 in every lane
    const T ex = dx + lanes_of<T>(pd[0]), ey = dy + lanes_of<T>(pd[1]), ez = dz + lanes_of<T>(pd[2]);
    const T g00 = lanes_of<T>(pd[3]), g01 = lanes_of<T>(pd[4]), g02 = lanes_of<T>(pd[5]);
    const T g11 = lanes_of<T>(pd[6]), g12 = lanes_of<T>(pd[7]), g22 = lanes_of<T>(pd[8]);
    const T ux = (g00 * ex + g01 * ey) + g02 * ez;
    const T uy = (g01 * ex + g11 * ey) + g12 * ez;
    const T uz = (g02 * ex + g12 * ey) + g22 * ez;
    const T q2 = (ux * ux + uy * uy) + uz * uz;
    a[0] = fmadd(yt10_spline(sqrt_lanes(q2), q2, k), lanes_of<T>(pd[9]), a[0]);
  }
  // Adds particles [b, e) (SoA coordinates, kernels PD) at vertex x, one after
  // the other (see field_common.hpp); returns how many lie within R. The
  // operations of add(), which it calls.
  template <class Pos>
  KOKKOS_INLINE_FUNCTION static std::uint32_t accumulate(float* a, const Pos& P,
                                                         const float* PD, const float* /*Q: uniform*/, std::uint32_t b,
                                                         std::uint32_t e, float x0, float x1, float x2, float inv_R2) {
    float acc[1] = {a[0]};
    std::uint32_t count = 0;
    for (std::size_t j = b; j < e; ++j) {
      float px, py, pz;
      P(j, px, py, pz);
      const float dx = px - x0, dy = py - x1, dz = pz - x2;
      const float s2 = scaled_distance2(dx, dy, dz, inv_R2);
      if (!(s2 < 1.f)) continue;  // it would add exactly +0 (field_common.hpp)
      const float k = s2 < 1.f ? 1.f - s2 : 0.f;
      count += s2 < 1.f ? 1u : 0u;
      add(acc, dx, dy, dz, k, PD + std::size_t(kYt10Floats) * j, 1.f);
    }
    a[0] = acc[0];
    return count;
  }
  KOKKOS_INLINE_FUNCTION static float value(const float* a, const FieldConstants& c) {
    return c.iso_threshold - a[0];
  }
};

// The moments of one particle's neighbourhood (not a field method of its
// own; the pass before the field sums them at every particle, d = x_k - x_j,
// s = |d| / R):
//   a[0] = sum w, a[1..3] = sum w d, a[4..9] = sum w d d^T (xx xy xz yy yz zz),
//   a[10] = D = sum W~(2 s), the isotropic density with support h = R/2.
struct Yt10Moments {
  static constexpr const char* name = "yt10-moments";
  static constexpr int P = 0;
  static constexpr bool radii = false;
  static constexpr int N = 11;
  // T is float, or a host SIMD vector of floats (the host's pass runs
  // across particles, like the band tiles across vertices). Everything from
  // k: s^2 = 1 - k, which is 1 where the particle does not contribute, and
  // then w = 1 - 1 * 1 and the density term are exactly 0.
  template <class T>
  KOKKOS_INLINE_FUNCTION static void add(T* a, T dx, T dy, T dz, T k, const float* /*no particle data*/,
                                         T /*q: uniform*/) {
    const T one = lanes_of<T>(1.f), two = lanes_of<T>(2.f);
    const T s2 = one - k;
    const T s = sqrt_lanes(s2);
    const T w = one - s2 * s;
    a[10] += yt10_spline(two * s, lanes_of<T>(4.f) * s2, k);  // q = |d| / h = 2 s
    const T wx = w * dx, wy = w * dy, wz = w * dz;
    a[0] += w;
    a[1] += wx;
    a[2] += wy;
    a[3] += wz;
    a[4] = fmadd(wx, dx, a[4]); a[5] = fmadd(wx, dy, a[5]); a[6] = fmadd(wx, dz, a[6]);
    a[7] = fmadd(wy, dy, a[7]); a[8] = fmadd(wy, dz, a[8]);
    a[9] = fmadd(wz, dz, a[9]);
  }
  // The same for particles [b, e), one after the other (add's operations).
  template <class Pos>
  KOKKOS_INLINE_FUNCTION static std::uint32_t accumulate(float* a, const Pos& P,
                                                         const float*, const float*, std::uint32_t b, std::uint32_t e,
                                                         float x0, float x1, float x2, float inv_R2) {
    float acc[N];
    for (int q = 0; q < N; ++q) acc[q] = a[q];
    std::uint32_t count = 0;
    for (std::size_t j = b; j < e; ++j) {
      float px, py, pz;
      P(j, px, py, pz);
      const float dx = px - x0, dy = py - x1, dz = pz - x2;
      const float s2 = scaled_distance2(dx, dy, dz, inv_R2);
      if (!(s2 < 1.f)) continue;  // it would add exactly +0 (field_common.hpp)
      const float k = s2 < 1.f ? 1.f - s2 : 0.f;
      count += s2 < 1.f ? 1u : 0u;
      add(acc, dx, dy, dz, k, nullptr, 1.f);
    }
    for (int q = 0; q < N; ++q) a[q] = acc[q];
    return count;
  }
  KOKKOS_INLINE_FUNCTION static float value(const float* a, const FieldConstants&) { return a[10]; }
};

// The constants of the pass before the field (from Params; field_yt10.hpp's
// header states the formulas).
struct Yt10Constants {
  float h = 0;            // isotropic support, R / 2
  float ks = 0;           // k_s / sigma_0
  float kr_inv = 0.25f;   // 1 / k_r
  float kn = 0.5f;
  float max_axis = 1.5f;  // kYt10MaxAxis
  float lambda = 0.3f;
  float max_shift = 0;    // kYt10MaxShift R
  std::uint32_t neighbours = 25;  // N_eps
};

// |x| lane-wise (T a float or a host SIMD vector of them): the sign bit
// cleared, as fabs.
template <class T>
KOKKOS_INLINE_FUNCTION T lane_abs(T x) {
  if constexpr (std::is_same<T, float>::value) {
    return Kokkos::Experimental::fabs(x);
  } else {
    using I = decltype(x < x);
    return (T)((I)x & 0x7fffffff);
  }
}

// Eigen-decomposition of the symmetric 3x3 matrix A: cyclic Jacobi
// rotations (Numerical Recipes' form, with square roots and divisions only),
// kYt10JacobiSweeps sweeps over (0,1), (0,2), (1,2). On return A's diagonal
// holds the eigenvalues and V's columns the eigenvectors (V starts as I).
// T: a float, or a host SIMD vector of them (the host's pass, eight
// particles at a time): every lane gets the float's bits. A rotation whose
// entry is 0 leaves A and V as they are (computed and not taken: lanes).
template <class T>
KOKKOS_INLINE_FUNCTION void jacobi_eigen_sym3(T A[3][3], T V[3][3]) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) V[i][j] = lanes_of<T>(i == j ? 1.f : 0.f);
  for (int sweep = 0; sweep < kYt10JacobiSweeps; ++sweep)
    for (int r = 0; r < 3; ++r) {
      const int p = r == 2 ? 1 : 0, q = r == 0 ? 1 : 2, o = 3 - p - q;
      const T apq = A[p][q];
      if constexpr (std::is_same<T, float>::value) {
        if (apq == 0.f) continue;
      }
      const auto turn = apq != 0.f;
      const T theta = (A[q][q] - A[p][p]) / (2.f * apq);
      // t = tan of the rotation angle, the smaller root; theta^2 may overflow
      // to inf, which gives t = 0 (no rotation), as it should.
      const T t = lane_select(theta >= 0.f, lanes_of<T>(1.f), lanes_of<T>(-1.f)) /
                  (lane_abs(theta) + lane_sqrt(theta * theta + 1.f));
      const T c = 1.f / lane_sqrt(t * t + 1.f), s = t * c;
      A[p][p] = lane_select(turn, A[p][p] - t * apq, A[p][p]);
      A[q][q] = lane_select(turn, A[q][q] + t * apq, A[q][q]);
      A[p][q] = A[q][p] = lane_select(turn, lanes_of<T>(0.f), A[p][q]);
      const T aop = A[o][p], aoq = A[o][q];
      A[o][p] = A[p][o] = lane_select(turn, c * aop - s * aoq, aop);
      A[o][q] = A[q][o] = lane_select(turn, s * aop + c * aoq, aoq);
      for (int i = 0; i < 3; ++i) {
        const T vp = V[i][p], vq = V[i][q];
        V[i][p] = lane_select(turn, c * vp - s * vq, vp);
        V[i][q] = lane_select(turn, s * vp + c * vq, vq);
      }
    }
}

// Entry (i, j) of V diag(is) V^T.
template <class T>
KOKKOS_INLINE_FUNCTION T yt10_entry(const T V[3][3], const T is[3], int i, int j) {
  return (V[i][0] * V[j][0] * is[0] + V[i][1] * V[j][1] * is[1]) + V[i][2] * V[j][2] * is[2];
}

// x clamped to [lo, hi] (lo <= hi); NaN gives lo.
template <class T>
KOKKOS_INLINE_FUNCTION T yt10_clamp(T x, T lo, T hi) {
  return lane_select(x >= lo, lane_select(x > hi, hi, x), lo);
}

// One particle's kernel (kYt10Floats floats to out[q], lane-wise for T a
// host SIMD vector) from its moments a (Yt10Moments) and whether it has
// more than N_eps neighbours within R (`crowd`, a mask of T's comparisons
// for vectors); returns the kernel's reach: how far from the particle it is
// non-zero (h s_1 + |xbar - x|, at most 0.95 R). Every lane gets the
// float's bits: the same operations, and where a float takes a branch the
// lanes compute both sides and select.
template <class T, class M>
KOKKOS_INLINE_FUNCTION T yt10_kernel_t(const T* a, M crowd, const Yt10Constants& k, T* out) {
  const T inv = 1.f / a[0];  // a[0] >= 1: the particle itself
  const T m0 = a[1] * inv, m1 = a[2] * inv, m2 = a[3] * inv;  // x_w - x_j
  T s[3] = {lanes_of<T>(k.kn), lanes_of<T>(k.kn), lanes_of<T>(k.kn)};
  T V[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) V[i][j] = lanes_of<T>(i == j ? 1.f : 0.f);
  bool any = true;
  if constexpr (std::is_same<T, float>::value) any = crowd;
  if (any) {
    // The covariance about the weighted mean, times k_s / sigma_0.
    T A[3][3], Q[3][3];
    A[0][0] = (a[4] * inv - m0 * m0) * k.ks;
    A[0][1] = A[1][0] = (a[5] * inv - m0 * m1) * k.ks;
    A[0][2] = A[2][0] = (a[6] * inv - m0 * m2) * k.ks;
    A[1][1] = (a[7] * inv - m1 * m1) * k.ks;
    A[1][2] = A[2][1] = (a[8] * inv - m1 * m2) * k.ks;
    A[2][2] = (a[9] * inv - m2 * m2) * k.ks;
    jacobi_eigen_sym3(A, Q);
    const T e[3] = {A[0][0], A[1][1], A[2][2]};
    // The largest eigenvalue (the first of equal ones); the others are
    // clamped alike, so their order does not matter.
    const auto b01 = e[0] >= e[1], b02 = e[0] >= e[2], b12 = e[1] >= e[2];
    const auto big0 = b01 && b02, big1 = !b01 && b12;  // else 2 (bools, or GCC vector masks)
    const T ebig = lane_select(big0, e[0], lane_select(big1, e[1], e[2]));
    const T s1 = yt10_clamp(ebig, lanes_of<T>(k.kn), lanes_of<T>(k.max_axis));
    const T lo = s1 * k.kr_inv;
    const T c0 = lane_select(big0, s1, yt10_clamp(e[0], lo, s1));
    const T c1 = lane_select(big1, s1, yt10_clamp(e[1], lo, s1));
    const T c2 = lane_select(big0 || big1, yt10_clamp(e[2], lo, s1), s1);
    s[0] = lane_select(crowd, c0, s[0]);
    s[1] = lane_select(crowd, c1, s[1]);
    s[2] = lane_select(crowd, c2, s[2]);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) V[i][j] = lane_select(crowd, Q[i][j], V[i][j]);
  }
  // G = (1/h) V diag(1/s) V^T
  const T is[3] = {1.f / (k.h * s[0]), 1.f / (k.h * s[1]), 1.f / (k.h * s[2])};
  // The smoothed centre, moved at most max_shift.
  T o0 = k.lambda * m0, o1 = k.lambda * m1, o2 = k.lambda * m2;
  const T len2 = (o0 * o0 + o1 * o1) + o2 * o2;
  T len = lane_sqrt(len2);
  const auto far = len > k.max_shift;
  bool shift = true;
  if constexpr (std::is_same<T, float>::value) shift = far;
  if (shift) {
    const T f = k.max_shift / len;
    o0 = lane_select(far, o0 * f, o0);
    o1 = lane_select(far, o1 * f, o1);
    o2 = lane_select(far, o2 * f, o2);
    len = lane_select(far, lanes_of<T>(k.max_shift), len);
  }
  out[0] = o0;
  out[1] = o1;
  out[2] = o2;
  out[3] = yt10_entry(V, is, 0, 0);
  out[4] = yt10_entry(V, is, 0, 1);
  out[5] = yt10_entry(V, is, 0, 2);
  out[6] = yt10_entry(V, is, 1, 1);
  out[7] = yt10_entry(V, is, 1, 2);
  out[8] = yt10_entry(V, is, 2, 2);
  out[9] = 1.f / (((s[0] * s[1]) * s[2]) * a[10]);  // det(h G) / D
  const T longest = lane_select(s[0] > s[1], lane_select(s[0] > s[2], s[0], s[2]), lane_select(s[1] > s[2], s[1], s[2]));
  const T reach = k.h * longest + len;
  const T bound = reach * kYt10ReachMargin;
  out[10] = bound * bound;
  return reach;
}

// One particle's kernel (the float case, every backend) from its moments
// and the number of particles within R (itself included).
KOKKOS_INLINE_FUNCTION float yt10_kernel(const float* a, std::uint32_t count, const Yt10Constants& k, float* out) {
  return yt10_kernel_t<float>(a, count - 1 > k.neighbours, k, out);
}

}  // namespace Details
}  // namespace nbmc
