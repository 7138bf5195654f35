// SPDX-License-Identifier: MIT
// The C ABI of include/nbmc.h over the C++/Kokkos core. Every entry point is
// wrapped in NBMC_CAPI_BEGIN/END: no exception, Kokkos error or abort crosses
// the boundary; user input is validated here before any kernel runs.
#include "nbmc.h"

#include "backends.hpp"
#include "collective.h"
#include "capi_attributes.hpp"
#include "capi_mesh.hpp"
#include "capi_radii.hpp"
#include "context.hpp"

#include "core/parallel.hpp"
#include "core/trace.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <new>
#include <sstream>
#include <string>
#include <vector>

using nbmc::Error;

namespace {

thread_local std::string g_create_error;

int32_t fail(nbmc_context* ctx, int32_t status, const std::string& msg) {
  if (ctx) ctx->last_error = msg;
  else g_create_error = msg;
  return status;
}

}  // namespace

#define NBMC_CAPI_BEGIN(ctx)                 \
  nbmc_context* nbmc_capi_ctx_ = (ctx);      \
  if (nbmc_capi_ctx_) nbmc_capi_ctx_->last_error.clear(); \
  try {
#define NBMC_CAPI_END                                                                     \
  }                                                                                       \
  catch (const Error& e) {                                                                \
    return fail(nbmc_capi_ctx_, e.status, e.what());                                      \
  }                                                                                       \
  catch (const std::bad_alloc&) {                                                         \
    return fail(nbmc_capi_ctx_, NBMC_ERROR_OUT_OF_MEMORY, "out of memory");               \
  }                                                                                       \
  catch (const std::exception& e) {                                                       \
    const std::string what = e.what();                                                    \
    if (what.find("allocat") != std::string::npos || what.find("memory") != std::string::npos) \
      return fail(nbmc_capi_ctx_, NBMC_ERROR_OUT_OF_MEMORY, "out of memory: " + what);    \
    return fail(nbmc_capi_ctx_, NBMC_ERROR_INTERNAL, "internal error: " + what);          \
  }                                                                                       \
  catch (...) {                                                                           \
    return fail(nbmc_capi_ctx_, NBMC_ERROR_INTERNAL, "internal error: unknown exception"); \
  }

extern "C" {

uint32_t nbmc_version(void) { return NBMC_VERSION; }

const char* nbmc_version_string(void) { return nbmc::version_string(); }

const char* nbmc_status_string(int32_t status) {
  switch (status) {
    case NBMC_OK: return "ok";
    case NBMC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case NBMC_ERROR_INVALID_PARTICLES: return "invalid particles";
    case NBMC_ERROR_NO_PARTICLES: return "no particles";
    case NBMC_ERROR_INVALID_PARAMETER: return "invalid parameter";
    case NBMC_ERROR_DOMAIN_TOO_LARGE: return "domain too large";
    case NBMC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case NBMC_ERROR_BACKEND_UNAVAILABLE: return "backend unavailable";
    case NBMC_ERROR_IO: return "i/o error";
    case NBMC_ERROR_INTERNAL: return "internal error";
    case NBMC_ERROR_MEMORY_BUDGET: return "memory budget exceeded";
    case NBMC_ERROR_CANCELLED: return "cancelled";
    case NBMC_ERROR_FORMAT: return "malformed or unsupported file";
    default: return "unknown status";
  }
}

const char* nbmc_stage_name(int32_t stage) {
  static const char* const names[NBMC_STAGE_COUNT] = {"upload", "neighbourhood", "surface particles", "band",
                                                      "field", "triangulation", "output"};
  if (stage == NBMC_STAGE_POSTPROCESS) return "postprocess";
  if (stage == NBMC_STAGE_ATTRIBUTES) return "attributes";
  return stage >= 0 && stage < NBMC_STAGE_COUNT ? names[stage] : nullptr;
}

int32_t nbmc_backend_available(int32_t backend) { return nbmc::backend_available(backend) ? 1 : 0; }

void nbmc_context_desc_init(nbmc_context_desc* desc) {
  if (!desc) return;
  std::memset(desc, 0, sizeof(*desc));
  desc->struct_size = sizeof(nbmc_context_desc);
  desc->backend = NBMC_BACKEND_AUTO;
}

int32_t nbmc_context_create(const nbmc_context_desc* desc, nbmc_context** out) {
  g_create_error.clear();
  if (!out) return fail(nullptr, NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_create: out is NULL");
  *out = nullptr;
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  if (desc) {
    if (desc->struct_size < sizeof(nbmc_context_desc))
      return fail(nullptr, NBMC_ERROR_INVALID_ARGUMENT,
                  "nbmc_context_create: desc->struct_size is " + std::to_string(desc->struct_size) +
                      "; fill the struct with nbmc_context_desc_init()");
    d = *desc;
  }
  if (d.backend < NBMC_BACKEND_AUTO || d.backend > NBMC_BACKEND_CUDA)
    return fail(nullptr, NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_create: unknown backend " + std::to_string(d.backend));
  if (d.num_threads < 0 || d.num_threads > 65536)
    return fail(nullptr, NBMC_ERROR_INVALID_ARGUMENT,
                "nbmc_context_create: num_threads must be in [0, 65536] (larger counts are clamped to 4x the cores)");
  if (d.flags & ~uint32_t(NBMC_CONTEXT_KOKKOS_ON_CALLING_THREAD))
    return fail(nullptr, NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_create: unknown flags");
  try {
    int32_t backend = d.backend;
    if (backend == NBMC_BACKEND_AUTO) backend = nbmc::auto_backend();
    if (!nbmc::backend_available(backend))
      return fail(nullptr, NBMC_ERROR_BACKEND_UNAVAILABLE,
                  std::string("backend '") + nbmc::backend_name(backend) +
                      "' is not available (compiled-in backends: " + nbmc::version_string() + ")");
    auto ctx = std::make_unique<nbmc_context>();  // freed if the runtime cannot start
    ctx->backend = backend;
    ctx->num_threads = d.num_threads;
    ctx->device_id = d.device_id;
    ctx->flags = d.flags;
    nbmc::runtime_acquire(*ctx);
    *out = ctx.release();
    return NBMC_OK;
  } catch (const Error& e) {
    return fail(nullptr, e.status, e.what());
  } catch (const std::bad_alloc&) {
    return fail(nullptr, NBMC_ERROR_OUT_OF_MEMORY, "out of memory");
  } catch (const std::exception& e) {
    return fail(nullptr, NBMC_ERROR_INTERNAL, std::string("internal error: ") + e.what());
  } catch (...) {
    return fail(nullptr, NBMC_ERROR_INTERNAL, "internal error: unknown exception");
  }
}

}  // extern "C"

nbmc_context::~nbmc_context() { nbmc::release_host_particles(*this); }

extern "C" {

void nbmc_context_destroy(nbmc_context* ctx) {
  if (!ctx) return;
  try {
    nbmc::runtime_release(*ctx);
  } catch (...) {
  }
  delete ctx;
}

const char* nbmc_context_last_error(const nbmc_context* ctx) {
  return ctx ? ctx->last_error.c_str() : g_create_error.c_str();
}

int32_t nbmc_context_backend(const nbmc_context* ctx, int32_t* backend) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  auto* c = const_cast<nbmc_context*>(ctx);
  if (!backend) return fail(c, NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_backend: backend is NULL");
  c->last_error.clear();
  *backend = ctx->backend;
  return NBMC_OK;
}

}  // extern "C"

// The argument checks both uploads share (count, pointer, stride, size).
template <class T>
static void check_upload(const T* xyz, uint64_t count, uint64_t byte_stride, const char* fn) {
  if (count == 0) throw Error(NBMC_ERROR_NO_PARTICLES, std::string(fn) + ": count is 0");
  if (!xyz) throw Error(NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": xyz is NULL");
  if (byte_stride != 0 && byte_stride < 3 * sizeof(T))
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, std::string(fn) + ": byte_stride " + std::to_string(byte_stride) +
                                                 " is smaller than one position (" + std::to_string(3 * sizeof(T)) +
                                                 " bytes)");
  if (count > uint64_t(UINT32_MAX) - 1)
    throw Error(NBMC_ERROR_DOMAIN_TOO_LARGE, std::string(fn) + ": at most 4294967294 particles are supported");
}

template <class T>
static int32_t set_particles_impl(nbmc_context* ctx, const T* xyz, uint64_t count, uint64_t byte_stride,
                                  const char* fn) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  NBMC_CAPI_BEGIN(ctx)
  ctx->particles.clear();  // keeps the (pinned) buffer for the next upload
  ctx->device_particles = nbmc::DeviceParticles();
  check_upload(xyz, count, byte_stride, fn);
  if (byte_stride == 0) byte_stride = 3 * sizeof(T);
  nbmc::host_trace("set_particles: start", count);
  double* out = nbmc::prepare_host_particles(*ctx, 3 * std::size_t(count));
  nbmc::host_trace("set_particles: buffer", count);
  const unsigned char* base = reinterpret_cast<const unsigned char*>(xyz);
  // Parallel over the particles on host threads (1.65 M took 70 ms on one
  // thread; the CUDA build has no OpenMP): a count and the smallest bad
  // index per chunk, which do not depend on the thread count. Threads as the
  // context's (a serial context: one; 0: every hardware thread).
  const std::size_t n = std::size_t(count);
  const nbmc::ScopedHostThreads limit(nbmc::host_threads_of(*ctx));
  const std::size_t chunks = nbmc::chunk_count(n, 100000);
  std::vector<std::uint64_t> chunk_bad(chunks, 0), chunk_first(chunks, UINT64_MAX);
  nbmc::for_chunks(n, chunks, [&](std::size_t k, std::size_t b, std::size_t e) {
    std::uint64_t nbad = 0, first = UINT64_MAX;
    for (std::size_t i = b; i < e; ++i) {
      T v[3];
      std::memcpy(v, base + std::uint64_t(i) * byte_stride, sizeof v);
      for (int a = 0; a < 3; ++a) {
        if (!std::isfinite(v[a]) || std::fabs(double(v[a])) > 1e15) {
          ++nbad;
          first = std::min(first, std::uint64_t(i));
        }
        out[3 * i + a] = double(v[a]);
      }
    }
    chunk_bad[k] = nbad;
    chunk_first[k] = first;
  });
  nbmc::host_trace("set_particles: copy, check", count);
  std::uint64_t bad = 0, first_bad = UINT64_MAX;
  for (std::size_t k = 0; k < chunks; ++k) {
    bad += chunk_bad[k];
    first_bad = std::min(first_bad, chunk_first[k]);
  }
  if (bad) {
    ctx->particles.clear();
    std::ostringstream s;
    s << fn << ": " << bad << " coordinate(s) are NaN, infinite or beyond 1e15 in magnitude (first at particle "
      << first_bad << ")";
    throw Error(NBMC_ERROR_INVALID_PARTICLES, s.str());
  }
  nbmc::pin_host_particles(*ctx);
  nbmc::host_trace("set_particles: pin", count);
  return NBMC_OK;
  NBMC_CAPI_END
}


// A context bound to several processes (libnbmc_mpi) may hold no particles
// (a rank that owns none), and remembers a failed upload so that the next
// collective reconstruction fails on every rank instead of leaving this
// rank's particles out.
template <class Impl>
static int32_t collective_upload(nbmc_context* ctx, uint64_t count, const Impl& impl) {
  // Attributes and radii belong to the particles uploaded last: every
  // upload, even a failed one, removes them.
  if (ctx) ctx->clear_particle_values();
  if (ctx && ctx->collective) {
    ctx->pending_status = 0;
    ctx->pending_error.clear();
    if (count == 0) {
      nbmc::release_host_particles(*ctx);
      ctx->device_particles = nbmc::DeviceParticles();
      ctx->last_error.clear();
      return NBMC_OK;
    }
  }
  const int32_t st = impl();
  if (st != NBMC_OK && ctx && ctx->collective) {
    ctx->pending_status = st;
    ctx->pending_error = ctx->last_error;
  }
  return st;
}

template <class T>
static int32_t set_particles(nbmc_context* ctx, const T* xyz, uint64_t count, uint64_t byte_stride, const char* fn) {
  return collective_upload(ctx, count, [&] { return set_particles_impl(ctx, xyz, count, byte_stride, fn); });
}

extern "C" {

int32_t nbmc_context_set_particles_f32(nbmc_context* ctx, const float* xyz, uint64_t count, uint64_t byte_stride) {
  return set_particles(ctx, xyz, count, byte_stride, "nbmc_context_set_particles_f32");
}

int32_t nbmc_context_set_particles_f64(nbmc_context* ctx, const double* xyz, uint64_t count, uint64_t byte_stride) {
  return set_particles(ctx, xyz, count, byte_stride, "nbmc_context_set_particles_f64");
}

}  // extern "C"

template <class T>
static int32_t set_particles_device_impl(nbmc_context* ctx, const T* xyz, uint64_t count, uint64_t byte_stride,
                                         const char* fn) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  NBMC_CAPI_BEGIN(ctx)
  nbmc::release_host_particles(*ctx);
  ctx->device_particles = nbmc::DeviceParticles();
  if (ctx->backend != NBMC_BACKEND_CUDA)
    throw Error(NBMC_ERROR_BACKEND_UNAVAILABLE, std::string(fn) + ": the context uses the " +
                                                    nbmc::backend_name(ctx->backend) +
                                                    " backend; device pointers need the CUDA backend");
  check_upload(xyz, count, byte_stride, fn);
  nbmc::DeviceParticles d;
  nbmc::run_on_kokkos_thread(*ctx, [&]() {
    d = nbmc::upload_device_particles(xyz, sizeof(T) == sizeof(float), count, byte_stride, fn);
  });
  ctx->device_particles = std::move(d);
  return NBMC_OK;
  NBMC_CAPI_END
}

template <class T>
static int32_t set_particles_device(nbmc_context* ctx, const T* xyz, uint64_t count, uint64_t byte_stride,
                                    const char* fn) {
  return collective_upload(ctx, count, [&] { return set_particles_device_impl(ctx, xyz, count, byte_stride, fn); });
}

extern "C" {

int32_t nbmc_context_set_particles_device_f32(nbmc_context* ctx, const float* xyz, uint64_t count,
                                              uint64_t byte_stride) {
  return set_particles_device(ctx, xyz, count, byte_stride, "nbmc_context_set_particles_device_f32");
}

int32_t nbmc_context_set_particles_device_f64(nbmc_context* ctx, const double* xyz, uint64_t count,
                                              uint64_t byte_stride) {
  return set_particles_device(ctx, xyz, count, byte_stride, "nbmc_context_set_particles_device_f64");
}

int32_t nbmc_context_set_mesh_memory(nbmc_context* ctx, int32_t memory) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  NBMC_CAPI_BEGIN(ctx)
  if (memory != NBMC_MEMORY_HOST && memory != NBMC_MEMORY_DEVICE)
    throw Error(NBMC_ERROR_INVALID_ARGUMENT,
                "nbmc_context_set_mesh_memory: memory " + std::to_string(memory) + " is not an NBMC_MEMORY_* value");
  if (memory == NBMC_MEMORY_DEVICE && ctx->backend != NBMC_BACKEND_CUDA)
    throw Error(NBMC_ERROR_BACKEND_UNAVAILABLE, std::string("nbmc_context_set_mesh_memory: the context uses the ") +
                                                    nbmc::backend_name(ctx->backend) +
                                                    " backend; device meshes need the CUDA backend");
  ctx->mesh_memory = memory;
  return NBMC_OK;
  NBMC_CAPI_END
}

int32_t nbmc_context_set_progress(nbmc_context* ctx, nbmc_progress_fn fn, void* user) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  ctx->last_error.clear();
  ctx->progress_fn = fn;
  ctx->progress_user = user;
  return NBMC_OK;
}

int32_t nbmc_context_set_memory_budget(nbmc_context* ctx, uint64_t bytes) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  ctx->last_error.clear();
  ctx->memory.budget = bytes;
  return NBMC_OK;
}

}  // extern "C"

namespace {
// double_positions: host meshes only (a device mesh has float arrays).
void check_double_positions(const nbmc_context& ctx, const nbmc_params& p, const char* fn) {
  if (p.double_positions && ctx.mesh_memory == NBMC_MEMORY_DEVICE)
    throw Error(NBMC_ERROR_INVALID_PARAMETER, std::string(fn) +
                                                  ": double_positions needs host meshes (nbmc_context_set_mesh_memory "
                                                  "is NBMC_MEMORY_DEVICE; device meshes are float only)");
}
}  // namespace

const float* nbmc_mesh::float_positions() const {
  if (!mesh.f64) return mesh.positions.empty() ? nullptr : mesh.positions.data();
  std::call_once(rounded, [this] {
    auto& m = const_cast<nbmc::HostMesh&>(mesh);
    std::vector<float, nbmc::NoInitAllocator<float>> f(m.positions64.size());
    for (std::size_t i = 0; i < f.size(); ++i) f[i] = float(m.positions64[i]);
    m.positions.swap(f);
  });
  return mesh.positions.empty() ? nullptr : mesh.positions.data();
}

extern "C" {

void nbmc_params_init(nbmc_params* p) {
  if (!p) return;
  std::memset(p, 0, sizeof(*p));
  p->struct_size = sizeof(nbmc_params);
  p->length_unit = NBMC_UNIT_SPACING;
  p->spacing = 0;
  p->cell_size = 0.5;
  p->influence_radius = 4;
  p->band_width = 2;
  p->surface_radius = 2;
  p->iso_radius = 1;
  p->method = NBMC_METHOD_SSP07;
  p->field = NBMC_FIELD_NARROW_BAND;
  p->t_low = 0.4;
  p->t_high = 3.5;
  p->color_threshold = 0.75;
  p->neighbour_threshold = 25;
  p->compute_normals = 1;
  p->cleanup = 1;
  p->iso_threshold = 0.6;
  p->isolated = NBMC_ISOLATED_KEEP;
  p->min_cluster = 10;
  p->decimate_fraction = 1;
  p->smooth_weighting = NBMC_SMOOTH_UNIFORM;
  p->aniso_kr = 4;
  p->aniso_ks = 1;
  p->aniso_kn = 0.5;
  p->aniso_lambda = 0.3;
  p->aniso_neighbours = 25;
  p->max_distance = 1.5;
}

int32_t nbmc_context_reconstruct(nbmc_context* ctx, const nbmc_params* params, nbmc_mesh** mesh) {
  if (mesh) *mesh = nullptr;
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  NBMC_CAPI_BEGIN(ctx)
  if (!params) throw Error(NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_reconstruct: params is NULL");
  if (!mesh) throw Error(NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_reconstruct: mesh is NULL");
  // Callers built before `cleanup` was appended pass the shorter struct;
  // the fields it lacks keep their defaults.
  if (params->struct_size < offsetof(nbmc_params, cleanup))
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_reconstruct: params->struct_size is " +
                                                 std::to_string(params->struct_size) +
                                                 "; fill the struct with nbmc_params_init()");
  nbmc_params full;
  nbmc_params_init(&full);
  std::memcpy(&full, params, std::min<std::size_t>(params->struct_size, sizeof full));
  full.struct_size = sizeof full;
  params = &full;
  check_double_positions(*ctx, full, "nbmc_context_reconstruct");
  nbmc::check_postprocess_params(full);
  if (ctx->particles.empty() && ctx->device_particles.count == 0)
    throw Error(NBMC_ERROR_NO_PARTICLES, "nbmc_context_reconstruct: no particles uploaded");
  nbmc::Params p = nbmc::resolve_params(*params);
  nbmc::apply_radii(*ctx, p);
  nbmc::check_domain(p);
  p.prebuilt_incidence = full.cleanup != 0;  // (taken by postprocess_mesh's clean-up)
  // The post-processing and the attributes run on this thread's host
  // threads: no more than the context was given.
  const nbmc::ScopedHostThreads host_threads(nbmc::host_threads_of(*ctx));
  auto m = std::make_unique<nbmc_mesh>();
  nbmc::RunStats st;
  std::vector<std::uint32_t> kept;  // isolated drop/sphere: the particles kept
  nbmc::run_backend(*ctx, p, m->mesh, st, &kept);
  // The particles on the host, for feature weights and isolated spheres.
  const bool feature = full.smooth_weighting == NBMC_SMOOTH_FEATURE && full.smooth_iterations > 0;
  const bool spheres = full.isolated == NBMC_ISOLATED_SPHERE;
  nbmc::ParticleVector downloaded;
  const double* all_xyz = ctx->particles.data();
  std::size_t all_n = ctx->particles.size() / 3;
  if ((feature || spheres) && ctx->device_particles.count) {
    all_n = ctx->device_particles.count;
    downloaded.resize(3 * all_n);
    nbmc::run_on_kokkos_thread(*ctx, [&] {
      nbmc::download_particles(ctx->device_particles.data.get(), all_n, downloaded.data());
    });
    all_xyz = downloaded.data();
  }
  nbmc::FeatureParticles fp;
  std::vector<double> kept_xyz;
  if (feature) {
    fp.xyz = all_xyz;
    fp.count = all_n;
    if (p.drop_isolated && kept.size() < all_n) {  // only those the surface was made of
      kept_xyz.resize(3 * kept.size());
      for (std::size_t i = 0; i < kept.size(); ++i)
        for (int a = 0; a < 3; ++a) kept_xyz[3 * i + a] = all_xyz[3 * std::size_t(kept[i]) + a];
      fp.xyz = kept_xyz.data();
      fp.count = kept.size();
    }
    fp.radius = p.influence_radius;
    fp.spacing = p.spacing;
  }
  if (spheres && kept.size() < all_n) {
    const float radius = float(is_density_field(p.method) ? 0.5 * p.spacing : p.iso_radius);
    m->spheres.reserve(4 * (all_n - kept.size()));
    std::size_t k = 0;
    for (std::size_t i = 0; i < all_n; ++i) {
      if (k < kept.size() && kept[k] == i) {
        ++k;
        continue;
      }
      for (int a = 0; a < 3; ++a) m->spheres.push_back(float(all_xyz[3 * i + a]));
      m->spheres.push_back(radius);
    }
  }
  // (On the Kokkos thread: its loops run on the threads the pipeline ran on.)
  nbmc::run_on_kokkos_thread(*ctx, [&] {
    ctx->postprocess = nbmc::postprocess_mesh(full, m->mesh, st, ctx->memory, feature ? &fp : nullptr);
  });
  // The post-processing's estimates were counted while each step ran.
  ctx->peak_memory = std::max(ctx->peak_memory, ctx->memory.peak.load());
  // On the final vertices, after the clean-up and smoothing.
  nbmc::interpolate_mesh_attributes(*ctx, p, *m, st);
  ctx->stats = st;
  ctx->has_stats = true;
  *mesh = m.release();
  return NBMC_OK;
  NBMC_CAPI_END
}

void nbmc_stats_init(nbmc_stats* s) {
  if (!s) return;
  std::memset(s, 0, sizeof(*s));
  s->struct_size = sizeof(nbmc_stats);
}

int32_t nbmc_context_stats(const nbmc_context* ctx, nbmc_stats* s) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  auto* c = const_cast<nbmc_context*>(ctx);
  if (!s) return fail(c, NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_stats: stats is NULL");
  // A caller built before the post-processing fields were appended passes
  // the shorter struct; it gets the fields it has.
  if (s->struct_size < offsetof(nbmc_stats, raw_triangle_count))
    return fail(c, NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_stats: fill the struct with nbmc_stats_init()");
  nbmc_stats* const caller = s;
  const std::size_t caller_size = std::min<std::size_t>(s->struct_size, sizeof(nbmc_stats));
  nbmc_stats full;
  s = &full;
  if (!ctx->has_stats)
    return fail(c, NBMC_ERROR_NO_PARTICLES, "nbmc_context_stats: no reconstruction has succeeded on this context yet");
  c->last_error.clear();
  const nbmc::RunStats& st = ctx->stats;
  nbmc_stats_init(s);
  s->particle_count = st.particles;
  s->surface_particle_count = st.surface_particles;
  s->occupied_cell_count = st.occupied_cells;
  s->band_vertex_count = st.band_vertices;
  s->band_block_count = st.band_blocks;
  s->grid_vertex_count = st.grid_vertices;
  s->triangulated_cell_count = st.cells;
  s->vertex_count = st.vertices;
  s->triangle_count = st.triangles;
  for (int a = 0; a < 3; ++a) {
    s->grid_dims[a] = st.dims[a];
    s->grid_origin[a] = st.origin[a];
  }
  s->peak_memory_bytes = ctx->peak_memory;
  s->neighbour_evaluations = st.evaluations;
  for (int i = 0; i < NBMC_STAGE_SLOTS; ++i) s->stage_seconds[i] = st.stage[i];
  s->total_seconds = st.total;
  s->cell_size = st.cell;
  s->raw_triangle_count = ctx->postprocess.raw_triangles;
  s->smoothing_volume_change = ctx->postprocess.volume_change;
  s->dropped_particle_count = st.dropped_particles;
  s->dropped_cluster_count = st.dropped_clusters;
  s->pre_decimation_triangle_count = ctx->postprocess.pre_decimation_triangles;
  s->cleanup_bad_triangles_before = ctx->postprocess.bad_before;
  s->cleanup_bad_triangles_after = ctx->postprocess.bad_after;
  s->cleanup_moves = ctx->postprocess.moves;
  s->cleanup_flips = ctx->postprocess.flips;
  s->cleanup_collapses = ctx->postprocess.collapses;
  s->cleanup_cuts = ctx->postprocess.cuts;
  s->cleanup_removed_component_triangles = ctx->postprocess.removed_component_triangles;
  std::memcpy(caller, &full, caller_size);
  caller->struct_size = uint32_t(caller_size);
  return NBMC_OK;
}

uint64_t nbmc_mesh_vertex_count(const nbmc_mesh* m) { return m ? m->mesh.vertex_count() : 0; }
uint64_t nbmc_mesh_triangle_count(const nbmc_mesh* m) { return m ? m->mesh.triangle_count() : 0; }
const float* nbmc_mesh_positions(const nbmc_mesh* m) {
  if (m && m->mesh.on_device) return m->mesh.d_positions;
  try {
    return m ? m->float_positions() : nullptr;
  } catch (...) {  // out of memory for the rounded copy
    return nullptr;
  }
}
const double* nbmc_mesh_positions_f64(const nbmc_mesh* m) {
  return m && m->mesh.f64 && !m->mesh.positions64.empty() ? m->mesh.positions64.data() : nullptr;
}
const float* nbmc_mesh_normals(const nbmc_mesh* m) {
  if (m && m->mesh.on_device) return m->mesh.d_normals;
  return m && !m->mesh.normals.empty() ? m->mesh.normals.data() : nullptr;
}
const uint32_t* nbmc_mesh_triangles(const nbmc_mesh* m) {
  if (m && m->mesh.on_device) return m->mesh.d_triangles;
  return m && !m->mesh.triangles.empty() ? m->mesh.triangles.data() : nullptr;
}
int32_t nbmc_mesh_memory(const nbmc_mesh* m) { return m && m->mesh.on_device ? NBMC_MEMORY_DEVICE : NBMC_MEMORY_HOST; }
int32_t nbmc_mesh_copy_to_host(const nbmc_mesh* m, float* positions, float* normals, uint32_t* triangles) {
  if (!m) return NBMC_ERROR_INVALID_ARGUMENT;
  try {
    const nbmc::HostMesh& h = m->mesh;
    if (h.on_device) {
      nbmc::download_mesh(h, positions, normals, triangles);
    } else {
      if (positions && h.f64)
        for (std::size_t i = 0; i < h.positions64.size(); ++i) positions[i] = float(h.positions64[i]);
      else if (positions && !h.positions.empty())
        std::memcpy(positions, h.positions.data(), h.positions.size() * sizeof(float));
      if (normals && !h.normals.empty()) std::memcpy(normals, h.normals.data(), h.normals.size() * sizeof(float));
      if (triangles && !h.triangles.empty())
        std::memcpy(triangles, h.triangles.data(), h.triangles.size() * sizeof(uint32_t));
    }
    return NBMC_OK;
  } catch (const Error& e) {
    return e.status;
  } catch (...) {
    return NBMC_ERROR_INTERNAL;
  }
}
void nbmc_mesh_destroy(nbmc_mesh* m) { delete m; }
uint64_t nbmc_mesh_sphere_count(const nbmc_mesh* m) { return m ? m->spheres.size() / 4 : 0; }
const float* nbmc_mesh_spheres(const nbmc_mesh* m) { return m && !m->spheres.empty() ? m->spheres.data() : nullptr; }

int32_t nbmc_kokkos_finalize(void) {
  try {
    return nbmc::runtime_finalize() ? NBMC_OK : NBMC_ERROR_INVALID_ARGUMENT;
  } catch (...) {
    return NBMC_ERROR_INTERNAL;
  }
}

}  // extern "C"

extern "C" {

void nbmc_subdomain_stats_init(nbmc_subdomain_stats* out) {
  if (!out) return;
  std::memset(out, 0, sizeof(*out));
  out->struct_size = sizeof(nbmc_subdomain_stats);
  out->parts[0] = out->parts[1] = out->parts[2] = 1;
}

void nbmc_subdomain_entry_init(nbmc_subdomain_entry* out) {
  if (!out) return;
  std::memset(out, 0, sizeof(*out));
  out->struct_size = sizeof(nbmc_subdomain_entry);
}

int32_t nbmc_context_set_subdomains(nbmc_context* ctx, int32_t nx, int32_t ny, int32_t nz) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  nbmc::SubdomainSetting s;
  if (nx == NBMC_SUBDOMAINS_AUTO) {
    s.automatic = true;
  } else {
    const int32_t n[3] = {nx, ny, nz};
    for (int a = 0; a < 3; ++a)
      if (n[a] < 1 || n[a] > 4096)
        return fail(ctx, NBMC_ERROR_INVALID_ARGUMENT,
                    "nbmc_context_set_subdomains: subdomains per axis must be 1 to 4096 (got " + std::to_string(nx) +
                        " x " + std::to_string(ny) + " x " + std::to_string(nz) + ")");
    if (std::int64_t(nx) * ny * nz > 1000000)
      return fail(ctx, NBMC_ERROR_INVALID_ARGUMENT, "nbmc_context_set_subdomains: more than a million subdomains");
    for (int a = 0; a < 3; ++a) s.parts[a] = n[a];
  }
  ctx->subdomains = s;
  ctx->last_error.clear();
  return NBMC_OK;
}

int32_t nbmc_context_subdomain_stats(const nbmc_context* ctx, nbmc_subdomain_stats* out) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  auto* c = const_cast<nbmc_context*>(ctx);
  if (!out || out->struct_size < sizeof(nbmc_subdomain_stats))
    return fail(c, NBMC_ERROR_INVALID_ARGUMENT,
                "nbmc_context_subdomain_stats: out is NULL or not filled by nbmc_subdomain_stats_init()");
  if (!ctx->has_stats)
    return fail(c, NBMC_ERROR_NO_PARTICLES, "nbmc_context_subdomain_stats: no reconstruction has succeeded yet");
  const nbmc::SubdomainReport& r = ctx->subdomain_report;
  nbmc_subdomain_stats_init(out);
  if (r.used) {
    for (int a = 0; a < 3; ++a) out->parts[a] = r.parts[a];
    out->count = r.count;
  }
  out->automatic = r.automatic ? 1 : 0;
  out->ghost_width = r.ghost_width;
  out->ghost_particles = r.ghost_particles;
  out->reruns = r.reruns;
  out->exchanged_cells = r.exchanged_cells;
  out->shared_vertices = r.shared_vertices;
  out->budget_bytes = r.budget_bytes;
  out->stitch_seconds = r.stitch_seconds;
  c->last_error.clear();
  return NBMC_OK;
}

int32_t nbmc_context_subdomain_entry(const nbmc_context* ctx, uint64_t i, nbmc_subdomain_entry* out) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  auto* c = const_cast<nbmc_context*>(ctx);
  if (!out || out->struct_size < sizeof(nbmc_subdomain_entry))
    return fail(c, NBMC_ERROR_INVALID_ARGUMENT,
                "nbmc_context_subdomain_entry: out is NULL or not filled by nbmc_subdomain_entry_init()");
  if (!ctx->has_stats)
    return fail(c, NBMC_ERROR_NO_PARTICLES, "nbmc_context_subdomain_entry: no reconstruction has succeeded yet");
  const auto& entries = ctx->subdomain_report.entries;
  if (i >= entries.size())
    return fail(c, NBMC_ERROR_INVALID_ARGUMENT,
                "nbmc_context_subdomain_entry: index " + std::to_string(i) + " out of range (" +
                    std::to_string(entries.size()) + " subdomains)");
  const nbmc::SubdomainEntry& e = entries[std::size_t(i)];
  nbmc_subdomain_entry_init(out);
  for (int a = 0; a < 3; ++a) {
    out->coord[a] = e.coord[a];
    out->cell_lo[a] = e.cell_lo[a];
    out->cell_hi[a] = e.cell_hi[a];
  }
  out->particles = e.particles;
  out->ghost_particles = e.ghost_particles;
  out->vertex_count = e.vertices;
  out->triangle_count = e.triangles;
  out->runs = std::uint32_t(e.runs);
  out->rank = e.rank;
  out->seconds = e.seconds;
  c->last_error.clear();
  return NBMC_OK;
}

}  // extern "C"

extern "C" {

int32_t nbmc__context_bind_collective(nbmc_context* ctx, int32_t bound) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  ctx->collective = bound != 0;
  ctx->pending_status = 0;
  ctx->pending_error.clear();
  ctx->last_error.clear();
  return NBMC_OK;
}

int32_t nbmc__context_attach(nbmc_context* ctx, void* data, void (*release)(void*)) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  if (!data) ctx->attached.reset();
  else ctx->attached = std::shared_ptr<void>(data, [release](void* p) {
    if (release) release(p);
  });
  return NBMC_OK;
}

void* nbmc__context_attached(const nbmc_context* ctx) { return ctx ? ctx->attached.get() : nullptr; }

int32_t nbmc__context_fail(nbmc_context* ctx, int32_t status, const char* message) {
  return fail(ctx, status, message ? message : "");
}

int32_t nbmc__reconstruct_collective(nbmc_context* ctx, const nbmc_params* params, const nbmc__collective* c,
                                     int32_t output, int32_t root, nbmc_mesh** mesh) {
  if (mesh) *mesh = nullptr;
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  NBMC_CAPI_BEGIN(ctx)
  // Argument errors that every rank sees alike (the same call on each).
  if (!params || !c || !mesh)
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, "nbmc_mpi_reconstruct: params, mesh or the communicator is NULL");
  if (params->struct_size < offsetof(nbmc_params, cleanup))
    throw Error(NBMC_ERROR_INVALID_ARGUMENT, "nbmc_mpi_reconstruct: fill params with nbmc_params_init()");
  nbmc_params full;
  nbmc_params_init(&full);
  std::memcpy(&full, params, std::min<std::size_t>(params->struct_size, sizeof full));
  full.struct_size = sizeof full;
  check_double_positions(*ctx, full, "nbmc_mpi_reconstruct");
  auto m = std::make_unique<nbmc_mesh>();
  ctx->has_stats = false;
  nbmc::reconstruct_collective(*ctx, full, *c, output, root, *m);
  ctx->has_stats = true;
  *mesh = m.release();
  return NBMC_OK;
  NBMC_CAPI_END
}

const uint64_t* nbmc_mesh_global_vertex_ids(const nbmc_mesh* mesh) {
  if (!mesh || mesh->mesh.global_ids.empty()) return nullptr;
  return mesh->mesh.global_ids.data();
}

uint64_t nbmc_mesh_global_vertex_count(const nbmc_mesh* mesh) {
  return mesh ? mesh->mesh.global_vertex_count : 0;
}

}  // extern "C"
