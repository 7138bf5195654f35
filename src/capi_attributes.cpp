// SPDX-License-Identifier: MIT
// The particle-attribute section of include/nbmc.h: per-particle values set
// on a context, interpolated onto the final vertices of each reconstructed
// mesh on the context's backend (backends/kokkos/attributes.hpp; the host's
// io/attributes.cpp for vertices with no particle within R), and read back
// from the mesh.
#include "capi_attributes.hpp"

#include "backends.hpp"
#include "core/parallel.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <new>
#include <sstream>
#include <string>

#if defined(_OPENMP)
#include <omp.h>
#endif

using nbmc::Error;

namespace nbmc {

namespace {

// The largest magnitude an attribute value may have: its interpolated value
// is returned as float.
constexpr double kMaxValue = 1e38;

void check_name(const char* name, const char* fn) {
  if (!name) throw Error(NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": name is NULL");
  const std::size_t len = std::strlen(name);
  if (len == 0 || len > 255)
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": the name must have 1 to 255 bytes");
  for (std::size_t i = 0; i < len; ++i) {
    const unsigned char c = static_cast<unsigned char>(name[i]);
    if (c < 0x20 || c == 0x7f)
      throw Error(NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": the name holds a control character (byte " +
                                                   std::to_string(i) + ")");
  }
}

void remove_attribute(nbmc_context& ctx, const char* name) {
  auto& list = ctx.attributes;
  list.erase(std::remove_if(list.begin(), list.end(), [&](const io::Attribute& a) { return a.name == name; }),
             list.end());
}

// Validates the values (already copied to values, packed) and stores them
// under name, in the place of an attribute of that name.
template <class T>
void store(nbmc_context& ctx, const char* name, const T* packed, std::uint32_t components, std::uint64_t count,
           const char* fn) {
  io::Attribute a;
  a.name = name;
  a.components = int(components);
  const std::size_t nv = std::size_t(count) * components;
  a.values.resize(nv);
  std::uint64_t bad = 0, first_bad = UINT64_MAX;
  const std::int64_t n = std::int64_t(nv);
  const int threads = ctx.backend == NBMC_BACKEND_SERIAL ? 1 : std::max(0, int(ctx.num_threads));
  (void)threads;
#pragma omp parallel for schedule(static) reduction(+ : bad) reduction(min : first_bad) \
    if (n > 300000 && threads != 1) num_threads(threads > 0 ? threads : omp_get_max_threads())
  for (std::int64_t i = 0; i < n; ++i) {
    const double v = double(packed[i]);
    if (!(std::fabs(v) <= kMaxValue)) {
      ++bad;
      first_bad = std::min(first_bad, std::uint64_t(i));
    }
    a.values[std::size_t(i)] = v;
  }
  if (bad) {
    std::ostringstream s;
    s << fn << ": " << bad << " value(s) of attribute '" << name
      << "' are NaN, infinite or beyond 1e38 in magnitude (first at particle " << first_bad / components
      << ", component " << first_bad % components << ")";
    throw Error(NBMC_ERROR_INVALID_PARTICLES, s.str());
  }
  auto it = std::find_if(ctx.attributes.begin(), ctx.attributes.end(),
                         [&](const io::Attribute& b) { return b.name == a.name; });
  if (it != ctx.attributes.end()) *it = std::move(a);
  else ctx.attributes.push_back(std::move(a));
}

// The checks both setters share; returns the particle count.
template <class T>
std::uint64_t check_set(nbmc_context& ctx, const char* name, const T* data, std::uint32_t components,
                        std::uint64_t& byte_stride, const char* fn) {
  check_name(name, fn);
  if (!data) return 0;
  const std::uint64_t count = ctx.particle_count();
  if (count == 0)
    throw Error(NBMC_ERROR_NO_PARTICLES,
                std::string(fn) + ": no particles uploaded; upload the particles first (an upload removes all attributes)");
  if (components != 1 && components != 3)
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": components must be 1 (scalar) or 3 (vector), got " +
                                                 std::to_string(components));
  const std::uint64_t item = std::uint64_t(components) * sizeof(T);
  if (byte_stride == 0) byte_stride = item;
  if (byte_stride < item)
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": byte_stride " + std::to_string(byte_stride) +
                                                 " is smaller than one item (" + std::to_string(item) + " bytes)");
  return count;
}

}  // namespace

std::vector<double, NoInitAllocator<double>> interpolate_at_vertices(nbmc_context& ctx, const double* xyz,
                                                                      bool on_device, std::size_t n,
                                                                      const std::vector<io::Attribute>& attributes,
                                                                      const float* vertices, const double* vertices64,
                                                                      std::size_t nv, double radius,
                                                                      const double* bounds, const double* scale) {
  std::size_t width = 0;
  for (const io::Attribute& a : attributes) {
    if (a.count() != n)
      throw Error(NBMC_ERROR_INTERNAL, "attribute '" + a.name + "' has " + std::to_string(a.count()) + " items for " +
                                           std::to_string(n) + " particles");
    width += std::size_t(a.components);
  }
  std::vector<double, NoInitAllocator<double>> result(nv * width);
  if (nv == 0 || width == 0) return result;
  if (n == 0) throw Error(NBMC_ERROR_NO_PARTICLES, "attribute interpolation: there are no particles");
  // All attributes side by side, particle-major.
  // (Host copies on the context's host threads: nbmc_context_reconstruct
  // sets the limit, one for a serial context.)
  std::vector<double, NoInitAllocator<double>> packed(n * width);
  for_chunks(n, chunk_count(n, 1 << 16), [&](std::size_t, std::size_t b, std::size_t e) {
    std::size_t off = 0;
    for (const io::Attribute& a : attributes) {
      const std::size_t c = std::size_t(a.components);
      for (std::size_t i = b; i < e; ++i)
        for (std::size_t k = 0; k < c; ++k) packed[i * width + off + k] = a.values[i * c + k];
      off += c;
    }
  });
  // The weighted means on the context's backend (the GPU too).
  std::vector<std::uint8_t> empty(nv, 0);
  AttributeJob job;
  job.xyz = xyz;
  job.on_device = on_device;
  job.count = n;
  job.values = packed.data();
  job.width = width;
  job.vertices = vertices64 ? nullptr : vertices;
  job.vertices64 = vertices64;
  job.vertex_count = nv;
  job.radius = radius;
  job.scale = scale;
  if (bounds) {
    job.use_bounds = true;
    for (int a = 0; a < 6; ++a) job.bounds[a] = bounds[a];
  }
  job.out = result.data();
  job.empty = empty.data();
  const bool all_host = !interpolate_attributes_on_backend(ctx, job);
  packed = {};
  // Vertices with no particle closer than R (and all of them where the
  // particles' box was too large for the backend's cell grid): the host's
  // implementation, which gives them the value of their nearest particle.
  std::vector<std::size_t> rest;
  for (std::size_t v = 0; v < nv; ++v)
    if (all_host || empty[v]) rest.push_back(v);
  if (rest.empty()) return result;
  ParticleVector pcopy;
  const double* hxyz = xyz;
  if (on_device) {
    pcopy.resize(3 * n);
    download_particles(xyz, n, pcopy.data());
    hxyz = pcopy.data();
  }
  const int threads = ctx.backend == NBMC_BACKEND_SERIAL ? 1 : std::max(0, int(ctx.num_threads));
  std::vector<io::Attribute> values;
  try {
    if (vertices64) {
      std::vector<double> sub(3 * rest.size());
      for (std::size_t i = 0; i < rest.size(); ++i)
        for (int a = 0; a < 3; ++a) sub[3 * i + a] = vertices64[3 * rest[i] + a];
      values = io::interpolate_attributes(hxyz, n, attributes, {}, sub.data(), rest.size(), radius, threads, scale);
    } else {
      std::vector<float> sub(3 * rest.size());
      for (std::size_t i = 0; i < rest.size(); ++i)
        for (int a = 0; a < 3; ++a) sub[3 * i + a] = vertices[3 * rest[i] + a];
      values = io::interpolate_attributes(hxyz, n, attributes, {}, sub.data(), rest.size(), radius, threads, scale);
    }
  } catch (const io::Error& e) {
    throw Error(NBMC_ERROR_INVALID_PARAMETER, std::string("attribute interpolation: ") + e.what());
  }
  std::size_t off = 0;
  for (const io::Attribute& a : values) {
    const std::size_t c = std::size_t(a.components);
    for (std::size_t i = 0; i < rest.size(); ++i)
      for (std::size_t k = 0; k < c; ++k) result[rest[i] * width + off + k] = a.values[i * c + k];
    off += c;
  }
  return result;
}

void store_mesh_attributes(const std::vector<io::Attribute>& layout, const double* result, nbmc_mesh& out) {
  std::size_t width = 0;
  for (const io::Attribute& a : layout) width += std::size_t(a.components);
  const std::size_t nv = std::size_t(out.mesh.vertex_count());
  out.attributes.resize(layout.size());
  std::size_t off = 0;
  for (std::size_t i = 0; i < layout.size(); ++i) {
    MeshAttribute& d = out.attributes[i];
    d.name = layout[i].name;
    d.components = std::uint32_t(layout[i].components);
    d.values.resize(nv * d.components);
    for_chunks(nv, chunk_count(nv, 1 << 16), [&](std::size_t, std::size_t b, std::size_t e) {
      for (std::size_t v = b; v < e; ++v)
        for (std::size_t k = 0; k < d.components; ++k)
          d.values[v * d.components + k] = float(result[v * width + off + k]);
    });
    off += d.components;
  }
}

void interpolate_mesh_attributes(nbmc_context& ctx, const Params& p, nbmc_mesh& out, RunStats& st) {
  out.attributes.clear();
  if (ctx.attributes.empty()) return;
  const auto t0 = std::chrono::steady_clock::now();
  const HostMesh& m = out.mesh;
  const std::uint64_t nv = m.vertex_count();
  // Positions of the vertices, on the host.
  std::vector<float, NoInitAllocator<float>> vcopy;
  const float* vertices = m.positions.empty() ? nullptr : m.positions.data();
  if (m.on_device && nv) {
    vcopy.resize(3 * std::size_t(nv));
    download_mesh(m, vcopy.data(), nullptr, nullptr);
    vertices = vcopy.data();
  }
  const bool device_particles = ctx.device_particles.count != 0;
  const std::size_t n = device_particles ? ctx.device_particles.count : ctx.particles.size() / 3;
  const double* xyz =
      device_particles ? static_cast<const double*>(ctx.device_particles.data.get()) : ctx.particles.data();
  // Per-particle radii: particle j's kernel support is R r_j / r_max.
  std::vector<double> scale;
  if (p.radius_ref > 0) {
    if (ctx.radii.size() != n) throw Error(NBMC_ERROR_INTERNAL, "attribute interpolation: the radii do not match");
    scale.resize(n);
    for (std::size_t j = 0; j < n; ++j) scale[j] = ctx.radii[j] / p.radius_ref;
  }
  const auto result = interpolate_at_vertices(ctx, xyz, device_particles, n, ctx.attributes, vertices,
                                              m.f64 ? m.positions64.data() : nullptr, std::size_t(nv),
                                              p.influence_radius, nullptr, scale.empty() ? nullptr : scale.data());
  store_mesh_attributes(ctx.attributes, result.data(), out);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  st.stage[NBMC_STAGE_ATTRIBUTES] += s;
  st.total += s;
}

std::vector<io::Attribute> mesh_attributes_for_writer(const nbmc_mesh& mesh) {
  std::vector<io::Attribute> out(mesh.attributes.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    const MeshAttribute& a = mesh.attributes[i];
    out[i].name = a.name;
    out[i].components = int(a.components);
    out[i].values.assign(a.values.begin(), a.values.end());
  }
  return out;
}

}  // namespace nbmc

namespace {

int32_t fail(nbmc_context* ctx, int32_t status, const std::string& msg) {
  if (ctx) ctx->last_error = msg;
  return status;
}

template <class F> int32_t guarded(nbmc_context* ctx, const char* name, const char* fn, F&& f) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  ctx->last_error.clear();
  try {
    return f();
  } catch (const Error& e) {
    if (name) nbmc::remove_attribute(*ctx, name);
    return fail(ctx, e.status, e.what());
  } catch (const std::bad_alloc&) {
    if (name) nbmc::remove_attribute(*ctx, name);
    return fail(ctx, NBMC_ERROR_OUT_OF_MEMORY, std::string(fn) + ": out of memory");
  } catch (const std::exception& e) {
    if (name) nbmc::remove_attribute(*ctx, name);
    return fail(ctx, NBMC_ERROR_INTERNAL, std::string(fn) + ": internal error: " + e.what());
  } catch (...) {
    if (name) nbmc::remove_attribute(*ctx, name);
    return fail(ctx, NBMC_ERROR_INTERNAL, std::string(fn) + ": internal error: unknown exception");
  }
}

template <class T>
int32_t set_attribute(nbmc_context* ctx, const char* name, const T* data, uint32_t components, uint64_t byte_stride,
                      const char* fn) {
  return guarded(ctx, name, fn, [&]() -> int32_t {
    const std::uint64_t count = nbmc::check_set(*ctx, name, data, components, byte_stride, fn);
    if (!data) {
      nbmc::remove_attribute(*ctx, name);
      return NBMC_OK;
    }
    const std::size_t nv = std::size_t(count) * components;
    if (byte_stride == std::uint64_t(components) * sizeof(T)) {
      nbmc::store(*ctx, name, data, components, count, fn);
    } else {
      std::vector<T> packed(nv);
      const unsigned char* base = reinterpret_cast<const unsigned char*>(data);
      for (std::uint64_t i = 0; i < count; ++i)
        std::memcpy(&packed[std::size_t(i) * components], base + i * byte_stride, components * sizeof(T));
      nbmc::store(*ctx, name, packed.data(), components, count, fn);
    }
    return NBMC_OK;
  });
}

template <class T>
int32_t set_attribute_device(nbmc_context* ctx, const char* name, const T* data, uint32_t components,
                             uint64_t byte_stride, const char* fn) {
  return guarded(ctx, name, fn, [&]() -> int32_t {
    if (ctx->backend != NBMC_BACKEND_CUDA)
      throw Error(NBMC_ERROR_BACKEND_UNAVAILABLE, std::string(fn) + ": the context uses the " +
                                                      nbmc::backend_name(ctx->backend) +
                                                      " backend; device pointers need the CUDA backend");
    const std::uint64_t count = nbmc::check_set(*ctx, name, data, components, byte_stride, fn);
    if (!data) {
      nbmc::remove_attribute(*ctx, name);
      return NBMC_OK;
    }
    std::vector<T> packed(std::size_t(count) * components);
    nbmc::run_on_kokkos_thread(*ctx, [&]() {
      nbmc::download_device_items(data, count, byte_stride, components * sizeof(T), sizeof(T), packed.data(), fn);
    });
    nbmc::store(*ctx, name, packed.data(), components, count, fn);
    return NBMC_OK;
  });
}

}  // namespace

extern "C" {

int32_t nbmc_context_set_attribute_f32(nbmc_context* ctx, const char* name, const float* data, uint32_t components,
                                       uint64_t byte_stride) {
  return set_attribute(ctx, name, data, components, byte_stride, "nbmc_context_set_attribute_f32");
}

int32_t nbmc_context_set_attribute_f64(nbmc_context* ctx, const char* name, const double* data, uint32_t components,
                                       uint64_t byte_stride) {
  return set_attribute(ctx, name, data, components, byte_stride, "nbmc_context_set_attribute_f64");
}

int32_t nbmc_context_set_attribute_device_f32(nbmc_context* ctx, const char* name, const float* data,
                                              uint32_t components, uint64_t byte_stride) {
  return set_attribute_device(ctx, name, data, components, byte_stride, "nbmc_context_set_attribute_device_f32");
}

int32_t nbmc_context_set_attribute_device_f64(nbmc_context* ctx, const char* name, const double* data,
                                              uint32_t components, uint64_t byte_stride) {
  return set_attribute_device(ctx, name, data, components, byte_stride, "nbmc_context_set_attribute_device_f64");
}

uint32_t nbmc_mesh_attribute_count(const nbmc_mesh* mesh) { return mesh ? uint32_t(mesh->attributes.size()) : 0; }

const char* nbmc_mesh_attribute_name(const nbmc_mesh* mesh, uint32_t i) {
  if (!mesh || i >= mesh->attributes.size()) return nullptr;
  return mesh->attributes[i].name.c_str();
}

const float* nbmc_mesh_attribute(const nbmc_mesh* mesh, const char* name, uint32_t* components) {
  if (components) *components = 0;
  try {
    if (!mesh || !name) {
      nbmc::set_thread_error(std::string("nbmc_mesh_attribute: ") + (mesh ? "name" : "mesh") + " is NULL");
      return nullptr;
    }
    for (const nbmc::MeshAttribute& a : mesh->attributes)
      if (a.name == name) {
        nbmc::set_thread_error("");
        if (components) *components = a.components;
        return a.values.empty() ? nullptr : a.values.data();
      }
    std::string have;
    for (const nbmc::MeshAttribute& a : mesh->attributes) have += (have.empty() ? "" : ", ") + a.name;
    nbmc::set_thread_error(std::string("nbmc_mesh_attribute: the mesh has no attribute '") + name +
                           "' (it has: " + (have.empty() ? std::string("none") : have) + ")");
  } catch (...) {
  }
  return nullptr;
}

}  // extern "C"
