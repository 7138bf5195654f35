// SPDX-License-Identifier: MIT
// The per-particle radii section of include/nbmc.h: the setters, and what a
// reconstruction takes from them (capi_radii.hpp). The kernels' side is
// backends/kokkos/radii.hpp; the parameters' scaling is scale_for_radii
// (src/core/params.hpp).
#include "capi_radii.hpp"

#include "backends.hpp"
#include "core/parallel.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <new>
#include <sstream>
#include <string>
#include <vector>

using nbmc::Error;

namespace nbmc {

namespace {

// The largest radius accepted (positions stop at 1e15 too).
constexpr double kMaxRadius = 1e15;

// The checks both setters share, before any value is read.
void check_set(const nbmc_context& ctx, std::uint64_t count, std::uint64_t& byte_stride, std::size_t value,
               const char* fn) {
  const std::uint64_t n = ctx.particle_count();
  if (n == 0 && !(ctx.collective && count == 0))
    throw Error(NBMC_ERROR_NO_PARTICLES,
                std::string(fn) + ": no particles uploaded; upload the particles first (an upload removes the radii)");
  if (count != n)
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": count is " + std::to_string(count) + ", but " +
                                                 std::to_string(n) + " particles are uploaded (one radius each)");
  if (byte_stride == 0) byte_stride = value;
  if (byte_stride < value)
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": byte_stride " + std::to_string(byte_stride) +
                                                 " is smaller than one radius (" + std::to_string(value) + " bytes)");
}

// Validates count packed radii into ctx.radii (with their smallest and
// largest), on the context's host threads; the same result for any count.
template <class T>
void store(nbmc_context& ctx, const T* packed, std::size_t n, const char* fn) {
  std::vector<double> r(n);
  const ScopedHostThreads limit(host_threads_of(ctx));
  const std::size_t chunks = chunk_count(n, 100000);
  std::vector<std::uint64_t> bad(chunks, 0), first(chunks, UINT64_MAX);
  std::vector<double> lo(chunks, std::numeric_limits<double>::infinity()), hi(chunks, 0);
  for_chunks(n, chunks, [&](std::size_t k, std::size_t b, std::size_t e) {
    for (std::size_t i = b; i < e; ++i) {
      const double v = double(packed[i]);
      if (!(v > 0 && v <= kMaxRadius)) {  // NaN fails too
        ++bad[k];
        first[k] = std::min(first[k], std::uint64_t(i));
        continue;
      }
      r[i] = v;
      lo[k] = std::min(lo[k], v);
      hi[k] = std::max(hi[k], v);
    }
  });
  std::uint64_t nbad = 0, first_bad = UINT64_MAX;
  double rmin = std::numeric_limits<double>::infinity(), rmax = 0;
  for (std::size_t k = 0; k < chunks; ++k) {
    nbad += bad[k];
    first_bad = std::min(first_bad, first[k]);
    rmin = std::min(rmin, lo[k]);
    rmax = std::max(rmax, hi[k]);
  }
  if (nbad) {
    std::ostringstream s;
    s << fn << ": " << nbad << " radi" << (nbad == 1 ? "us is" : "i are")
      << " NaN, infinite, not positive or beyond 1e15 (first at particle " << first_bad << ": "
      << double(packed[first_bad]) << ")";
    throw Error(NBMC_ERROR_INVALID_PARAMETER, s.str());
  }
  if (n && rmax > kMaxRadiusRatio * rmin) {
    std::ostringstream s;
    s << fn << ": the radii span more than a factor 1e6 (smallest " << rmin << ", largest " << rmax << ")";
    throw Error(NBMC_ERROR_INVALID_PARAMETER, s.str());
  }
  ctx.radii.swap(r);
  ctx.radius_min = n ? rmin : 0;
  ctx.radius_max = n ? rmax : 0;
}

void clear(nbmc_context& ctx) {
  std::vector<double>().swap(ctx.radii);
  ctx.radius_min = ctx.radius_max = 0;
}

template <class F>
int32_t guarded(nbmc_context* ctx, const char* fn, F&& f) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  ctx->last_error.clear();
  std::string msg;
  int32_t status = NBMC_OK;
  try {
    return f();
  } catch (const Error& e) {
    status = e.status;
    msg = e.what();
  } catch (const std::bad_alloc&) {
    status = NBMC_ERROR_OUT_OF_MEMORY;
    msg = std::string(fn) + ": out of memory";
  } catch (const std::exception& e) {
    status = NBMC_ERROR_INTERNAL;
    msg = std::string(fn) + ": internal error: " + e.what();
  } catch (...) {
    status = NBMC_ERROR_INTERNAL;
    msg = std::string(fn) + ": internal error: unknown exception";
  }
  clear(*ctx);  // on failure the context keeps no radii
  ctx->last_error = msg;
  return status;
}

template <class T>
int32_t set_radii(nbmc_context* ctx, const T* radii, std::uint64_t count, std::uint64_t byte_stride, const char* fn) {
  return guarded(ctx, fn, [&]() -> int32_t {
    clear(*ctx);
    if (!radii) return NBMC_OK;
    check_set(*ctx, count, byte_stride, sizeof(T), fn);
    const std::size_t n = std::size_t(count);
    if (byte_stride == sizeof(T)) {
      store(*ctx, radii, n, fn);
    } else {
      std::vector<T> packed(n);
      const unsigned char* base = reinterpret_cast<const unsigned char*>(radii);
      for (std::size_t i = 0; i < n; ++i) std::memcpy(&packed[i], base + i * byte_stride, sizeof(T));
      store(*ctx, packed.data(), n, fn);
    }
    return NBMC_OK;
  });
}

template <class T>
int32_t set_radii_device(nbmc_context* ctx, const T* radii, std::uint64_t count, std::uint64_t byte_stride,
                         const char* fn) {
  return guarded(ctx, fn, [&]() -> int32_t {
    clear(*ctx);
    if (ctx->backend != NBMC_BACKEND_CUDA)
      throw Error(NBMC_ERROR_BACKEND_UNAVAILABLE, std::string(fn) + ": the context uses the " +
                                                      backend_name(ctx->backend) +
                                                      " backend; device pointers need the CUDA backend");
    if (!radii) return NBMC_OK;
    check_set(*ctx, count, byte_stride, sizeof(T), fn);
    std::vector<T> packed(static_cast<std::size_t>(count));
    run_on_kokkos_thread(*ctx, [&]() {
      download_device_items(radii, count, byte_stride, sizeof(T), sizeof(T), packed.data(), fn,
                            "nbmc_context_set_radii_f32/f64");
    });
    store(*ctx, packed.data(), packed.size(), fn);
    return NBMC_OK;
  });
}

}  // namespace

void apply_radii(const nbmc_context& ctx, Params& p) {
  if (ctx.radii.empty()) return;
  if (ctx.radii.size() != ctx.particle_count())
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_reconstruct: " + std::to_string(ctx.radii.size()) +
                                                 " radii for " + std::to_string(ctx.particle_count()) + " particles");
  scale_for_radii(p, ctx.radius_min, ctx.radius_max);
}

}  // namespace nbmc

extern "C" {

int32_t nbmc_context_set_radii_f32(nbmc_context* ctx, const float* radii, uint64_t count, uint64_t byte_stride) {
  return nbmc::set_radii(ctx, radii, count, byte_stride, "nbmc_context_set_radii_f32");
}

int32_t nbmc_context_set_radii_f64(nbmc_context* ctx, const double* radii, uint64_t count, uint64_t byte_stride) {
  return nbmc::set_radii(ctx, radii, count, byte_stride, "nbmc_context_set_radii_f64");
}

int32_t nbmc_context_set_radii_device_f32(nbmc_context* ctx, const float* radii, uint64_t count,
                                          uint64_t byte_stride) {
  return nbmc::set_radii_device(ctx, radii, count, byte_stride, "nbmc_context_set_radii_device_f32");
}

int32_t nbmc_context_set_radii_device_f64(nbmc_context* ctx, const double* radii, uint64_t count,
                                          uint64_t byte_stride) {
  return nbmc::set_radii_device(ctx, radii, count, byte_stride, "nbmc_context_set_radii_device_f64");
}

}  // extern "C"
