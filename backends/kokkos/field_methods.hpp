// SPDX-License-Identifier: MIT
// The one place where a field method (Method) becomes a kernel type: every
// stage that evaluates the field calls with_field_method(p.method, f) and
// gets f(FieldSSP07{}), f(FieldZB05{}), f(FieldSPH{}) or f(FieldYT10{}) (with
// per-particle radii, the radii variants of the first three; YT10 has none).
// A new method is a new file field_<name>.hpp with its kernel type and one
// case in each function here.
#pragma once

#include "common.hpp"
#include "field_sph.hpp"
#include "field_ssp07.hpp"
#include "field_yt10.hpp"
#include "field_zb05.hpp"

namespace nbmc {
namespace Details {

template <class F>
auto with_field_method(Method m, F&& f) {
  switch (m) {
    case Method::ZB05: return f(FieldZB05{});
    case Method::SPH: return f(FieldSPH{});
    case Method::YT10: return f(FieldYT10{});
    case Method::SSP07: break;
  }
  return f(FieldSSP07{});
}

// The same with per-particle radii (radii = true: the methods' radii
// variants, field_common.hpp).
template <class F>
auto with_field_method(Method m, bool radii, F&& f) {
  if (!radii) return with_field_method(m, f);
  switch (m) {
    case Method::ZB05: return f(FieldZB05T<true>{});
    case Method::SPH: return f(FieldSPHT<true>{});
    case Method::YT10:  // refused by the parameter check (params.hpp); never reached
      throw Error(2 /*NBMC_ERROR_INVALID_PARAMETER*/, "method yt10 does not support per-particle radii");
    case Method::SSP07: break;
  }
  return f(FieldSSP07T<true>{});
}

// Floats of per-vertex state a method's scatter baseline keeps.
inline int field_state_floats(Method m, bool radii = false) {
  return with_field_method(m, radii, [](auto k) { return int(decltype(k)::N); });
}

}  // namespace Details
}  // namespace nbmc
