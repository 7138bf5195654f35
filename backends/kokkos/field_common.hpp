// SPDX-License-Identifier: MIT
// What every scalar-field method shares: the kernel k(s) = max(0, (1 - s^2)^3)
// of eq. (5), the constants of a field evaluation, and the value given to
// vertices that no particle reaches.
//
// A method is a type with
//   static constexpr int N;                       // accumulator size (floats, zero-initialised)
//   static void add(float* a, dx, dy, dz, k)      // contribution of one particle, d = x_j - x,
//                                                 // k = max(0, 1 - |d|^2/R^2) (0: no contribution)
//   static uint32_t accumulate(a, X, Y, Z, b, e, x0, x1, x2, inv_R2)
//                                                 // the same for particles [b, e), vectorised
//   static float value(const float* a, const FieldConstants&)  // phi(x); negative inside
// so the gather (narrow band, dense) and the scatter drivers are written once.
#pragma once

#include <Kokkos_Core.hpp>

// Vectorisation of the particle loops on the host (explicit reduction order,
// fixed per build, so results stay deterministic).
#if defined(_OPENMP) && !defined(__CUDA_ARCH__)
#define NBMC_PRAGMA(x) _Pragma(#x)
#define NBMC_SIMD_REDUCTION(...) NBMC_PRAGMA(omp simd reduction(+ : __VA_ARGS__))
#else
#define NBMC_SIMD_REDUCTION(...)
#endif

namespace nbmc {
namespace Details {

struct FieldConstants {
  float R = 0;           // influence radius
  float inv_R2 = 0;      // 1 / R^2
  float iso_radius = 0;  // r-bar
  float t_low = 0.4f, t_high = 3.5f;
  float outside = 0;     // phi where no particle contributes
};

inline FieldConstants field_constants(double R, double iso_radius, double t_low, double t_high) {
  FieldConstants f;
  f.R = float(R);
  f.inv_R2 = float(1.0 / (R * R));
  f.iso_radius = float(iso_radius);
  f.t_low = float(t_low);
  f.t_high = float(t_high);
  f.outside = float(R);
  return f;
}

}  // namespace Details
}  // namespace nbmc
