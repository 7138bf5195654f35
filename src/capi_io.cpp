// SPDX-License-Identifier: MIT
// The File I/O section of include/nbmc.h: particle files into a context,
// meshes to files, through the nbmc_io readers and writers. Nothing thrown
// crosses the boundary.
#include "nbmc.h"

#include "backends.hpp"
#include "capi_attributes.hpp"
#include "context.hpp"
#include "io/error.hpp"
#include "io/mesh.hpp"
#include "io/particles.hpp"

#include <new>
#include <string>

namespace {

thread_local std::string g_last_error;

int32_t status_of(const nbmc::io::Error& e) {
  switch (e.kind()) {
  case nbmc::io::Error::Kind::io: return NBMC_ERROR_IO;
  case nbmc::io::Error::Kind::argument: return NBMC_ERROR_INVALID_ARGUMENT;
  case nbmc::io::Error::Kind::format: break;
  }
  return NBMC_ERROR_FORMAT;
}

// Records msg where the caller will look for it.
int32_t fail(nbmc_context* ctx, int32_t status, const std::string& msg) {
  try {
    if (ctx)
      ctx->last_error = msg;
    else
      g_last_error = msg;
  } catch (...) {
  }
  return status;
}

// Runs f, mapping exceptions to a status and message.
template <class F> int32_t guarded(nbmc_context* ctx, const char* fn, F&& f) {
  try {
    return f();
  } catch (const nbmc::io::Error& e) {
    return fail(ctx, status_of(e), std::string(fn) + ": " + e.what());
  } catch (const std::bad_alloc&) {
    return fail(ctx, NBMC_ERROR_OUT_OF_MEMORY, std::string(fn) + ": out of memory");
  } catch (const std::exception& e) {
    return fail(ctx, NBMC_ERROR_INTERNAL, std::string(fn) + ": internal error: " + e.what());
  } catch (...) {
    return fail(ctx, NBMC_ERROR_INTERNAL, std::string(fn) + ": internal error: unknown exception");
  }
}

} // namespace

void nbmc::set_thread_error(const std::string& msg) { g_last_error = msg; }

extern "C" {

int32_t nbmc_context_load_particles(nbmc_context* ctx, const char* path, const char* format, uint64_t* count_out) {
  static const char* fn = "nbmc_context_load_particles";
  if (count_out) *count_out = 0;
  if (!ctx) {
    g_last_error = std::string(fn) + ": ctx is NULL";
    return NBMC_ERROR_INVALID_ARGUMENT;
  }
  ctx->last_error.clear();
  return guarded(ctx, fn, [&]() -> int32_t {
    ctx->particles.clear();  // the (pinned) buffer stays for the upload below
    ctx->device_particles = nbmc::DeviceParticles();
    ctx->clear_particle_values();  // attributes and radii belonged to the particles replaced
    if (!path) return fail(ctx, NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": path is NULL");
    nbmc::io::ReadOptions o;
    o.format = format ? format : "";
    o.attributes = false;
    nbmc::io::Particles p = nbmc::io::read_particles(path, o);
    const uint64_t n = p.count();
    // The upload path validates (NaN/Inf, count 0, size limits) and copies.
    const int32_t st = nbmc_context_set_particles_f64(ctx, p.xyz.empty() ? nullptr : p.xyz.data(), n, 0);
    if (st != NBMC_OK) {
      std::string detail = ctx->last_error;
      const std::string prefix = "nbmc_context_set_particles_f64: ";
      if (detail.rfind(prefix, 0) == 0) detail.erase(0, prefix.size());
      if (n == 0) detail = "the file holds no particles";
      return fail(ctx, st, std::string(fn) + ": " + path + ": " + detail);
    }
    if (count_out) *count_out = n;
    return NBMC_OK;
  });
}

int32_t nbmc_mesh_write(const nbmc_mesh* mesh, const char* path, const char* format) {
  static const char* fn = "nbmc_mesh_write";
  g_last_error.clear();
  if (!mesh) return fail(nullptr, NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": mesh is NULL");
  if (!path) return fail(nullptr, NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": path is NULL");
  return guarded(nullptr, fn, [&]() -> int32_t {
    nbmc::io::MeshView v;
    nbmc::HostMesh copy;  // a device mesh, brought to the host
    if (mesh->mesh.on_device) {
      copy.positions.resize(3 * mesh->mesh.vertex_count());
      copy.normals.resize(mesh->mesh.d_normals ? copy.positions.size() : 0);
      copy.triangles.resize(3 * mesh->mesh.triangle_count());
      nbmc::download_mesh(mesh->mesh, copy.positions.data(), copy.normals.empty() ? nullptr : copy.normals.data(),
                          copy.triangles.data());
    }
    const nbmc::HostMesh& m = mesh->mesh.on_device ? copy : mesh->mesh;
    v.vertex_count = m.vertex_count();
    v.triangle_count = m.triangles.size() / 3;
    if (m.f64) v.positions64 = m.positions64.empty() ? nullptr : m.positions64.data();  // doubles where the format can
    else v.positions = m.positions.empty() ? nullptr : m.positions.data();
    v.normals = m.normals.size() == 3 * v.vertex_count && !m.normals.empty() ? m.normals.data() : nullptr;
    v.triangles = m.triangles.empty() ? nullptr : m.triangles.data();
    const std::vector<nbmc::io::Attribute> attributes = nbmc::mesh_attributes_for_writer(*mesh);
    v.attributes = attributes.empty() ? nullptr : attributes.data();
    v.attribute_count = attributes.size();
    nbmc::io::write_mesh(path, v, format ? format : "");
    return NBMC_OK;
  });
}

const char* nbmc_last_error(void) { return g_last_error.c_str(); }

} // extern "C"
