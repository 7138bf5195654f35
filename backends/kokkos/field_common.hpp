// SPDX-License-Identifier: MIT
// What every scalar-field method shares: the kernel k(s) = max(0, (1 - s^2)^3)
// of eq. (5), the constants of a field evaluation, and the value given to
// vertices that no particle reaches.
//
// A method is a type with
//   struct Acc;                                   // per-vertex accumulator, zero-initialised
//   static void add(Acc&, dx, dy, dz, s2, k)      // contribution of one particle, d = x_j - x,
//                                                 // s2 = |d|^2 / R^2 < 1, k = (1 - s2)
//   static float value(const Acc&, const FieldConstants&)  // phi(x); negative inside
// so the gather (narrow band, dense) and the scatter drivers are written once.
#pragma once

#include <Kokkos_Core.hpp>

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
