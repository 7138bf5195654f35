// SPDX-License-Identifier: MIT
// Backend selection, the Kokkos runtime's lifetime, and dispatch of a
// reconstruction to the execution space of a context.
#pragma once

#include "collective.h"
#include "context.hpp"

#include <functional>

struct nbmc_mesh;

namespace nbmc {

const char* version_string();
const char* backend_name(int32_t backend);
bool backend_available(int32_t backend);
int32_t auto_backend();

// Kokkos is initialised by the first context unless the host did it; nbmc
// finalises only what it initialised.
void runtime_acquire(nbmc_context& ctx);
void runtime_release(nbmc_context& ctx);
bool runtime_finalize();
// Upper bound of the OpenMP threads a context gets (4x the cores, at least 16).
int max_threads();

// Validates the user's parameters and converts them to absolute units.
Params resolve_params(const nbmc_params& in);
// Rejects parameter/particle combinations whose grid could not be indexed.
void check_domain(const Params& p);

// kept_out (may be null): with p.drop_isolated, the indices of the particles
// the isolated-particle filter kept (ascending); else left empty.
void run_backend(nbmc_context& ctx, const Params& p, HostMesh& mesh, RunStats& st,
                 std::vector<std::uint32_t>* kept_out = nullptr);
// One subdomain (in.region) or frame on the context's backend, from any thread.
void run_region(nbmc_context& ctx, const ParticleInput& in, const Params& p, const Progress& progress, HostMesh& mesh,
                RunStats& st);
// The frame over the processes of a collective (src/distributed.cpp): the
// reconstruction, the root's clean-up and smoothing (gather output), and the
// particle attributes onto the final vertices.
void reconstruct_collective(nbmc_context& ctx, const nbmc_params& params, const nbmc__collective& hooks,
                            int32_t output, int32_t root, nbmc_mesh& mesh);
// The most host threads a context's host steps may use (core/parallel.hpp's
// limit): 1 for the serial backend, the context's thread count, 0 = all.
std::size_t host_threads_of(const nbmc_context& ctx);
// Runs fn where the context's backend runs its work (nbmc's Kokkos thread,
// serialised with the reconstructions of that backend), with the context's
// host thread limit.
void run_on_kokkos_thread(nbmc_context& ctx, const std::function<void()>& fn);

// Explicit instantiations, one file per backend (pipeline_*.cpp).
void reconstruct_serial(const ParticleInput& in, const Params& p, MemoryTracker& t, const Progress& pr, HostMesh& m,
                        RunStats& st);
void reconstruct_openmp(const ParticleInput& in, const Params& p, MemoryTracker& t, const Progress& pr, HostMesh& m,
                        RunStats& st);
void reconstruct_cuda(const ParticleInput& in, const Params& p, MemoryTracker& t, const Progress& pr,
                      bool mesh_on_device, HostMesh& m, RunStats& st, int device);

// Particle attributes interpolated onto mesh vertices on a backend
// (backends/kokkos/attributes.hpp). Host arrays except xyz with on_device.
struct AttributeJob {
  const double* xyz = nullptr;      // 3 per particle, absolute
  bool on_device = false;           // xyz in CUDA memory
  std::size_t count = 0;
  const double* values = nullptr;   // count * width, particle-major
  std::size_t width = 0;            // components of all attributes together
  const float* vertices = nullptr;  // 3 per vertex (or vertices64)
  const double* vertices64 = nullptr;
  std::size_t vertex_count = 0;
  double radius = 0;
  const double* scale = nullptr;    // host, count: per-particle support radius * scale[j] (NULL: radius)
  bool use_bounds = false;          // bounds (lo[3], hi[3]) fix the cell grid in place of the particles' own
  double bounds[6] = {0, 0, 0, 0, 0, 0};
  double* out = nullptr;            // vertex_count * width
  std::uint8_t* empty = nullptr;    // vertex_count: 1 where no particle is closer than radius
};
// Runs job on the context's backend (from any thread); false if the
// particles' box is too large for its cell grid (use the host path then).
bool interpolate_attributes_on_backend(nbmc_context& ctx, const AttributeJob& job);
bool interpolate_attributes_serial(const AttributeJob& job, MemoryTracker& t);
bool interpolate_attributes_openmp(const AttributeJob& job, MemoryTracker& t);
bool interpolate_attributes_cuda(const AttributeJob& job, MemoryTracker& t);

// CUDA helpers (pipeline_cuda.cpp; without CUDA they throw
// NBMC_ERROR_BACKEND_UNAVAILABLE). Copies count positions of type float
// (f32) or double from device memory at xyz (byte_stride apart, 0 = packed)
// into a new packed double array on the device, validating them there.
DeviceParticles upload_device_particles(const void* xyz, bool f32, std::uint64_t count, std::uint64_t byte_stride,
                                        const char* fn);
// Page-locks host memory for fast copies to the GPU (cudaHostRegister);
// false where that is not possible (no CUDA, or the driver refused).
bool cuda_pin(void* p, std::size_t bytes);
void cuda_unpin(void* p);
// Frees the context's host particle buffer (unpinning it first).
void release_host_particles(nbmc_context& ctx);
// Makes ctx.particles hold n uninitialised doubles; the buffer is reused
// while the size stays within a factor 2 (no page faults for a sequence's
// next frame).
double* prepare_host_particles(nbmc_context& ctx, std::size_t n);
// CUDA contexts: page-locks the buffer once it is filled (then reused
// pinned); a no-op elsewhere or when it is pinned already.
void pin_host_particles(nbmc_context& ctx);
// Copies the arrays of a device mesh into host buffers (any may be NULL).
void download_mesh(const HostMesh& m, float* positions, float* normals, std::uint32_t* triangles);
// A device mesh (NBMC_MEMORY_DEVICE) for its post-processing on the host:
// copied into h's vectors (sized here) through the pinned staging ring, with,
// when `incidence`, the clean-up's incidence built on the GPU into
// h.incidence (left out where the memory budget would not hold it); and the
// post-processed h copied back into m's device arrays (the counts only
// shrink). On the host threads of core/parallel.hpp (any calling thread).
// The download leaves the memory of its device buffers in nbmc's device pool
// for the upload's: release_device_pool() after the upload (and on every
// way out) gives it back to the driver (a no-op without CUDA).
void download_mesh_for_postprocess(const HostMesh& m, HostMesh& h, bool incidence, MemoryTracker& tracker);
void upload_mesh_after_postprocess(HostMesh& m, const HostMesh& h);
// The same after a clean-up that listed where its result differs from the
// mesh m's arrays still hold (cleanup_mesh's `changed`, valid): only those
// places are copied, and m's counts shrink to h's. False (m untouched)
// where the GPU or the memory budget has no room for the few buffers; the
// caller then copies the whole mesh back.
bool upload_changed_entries(HostMesh& m, const HostMesh& h, const mesh::ChangedEntries& changed,
                            MemoryTracker& tracker);
void release_device_pool();
// Copies count particles (3 doubles each) from the CUDA device to the host.
void download_particles(const void* device_xyz, std::size_t count, double* host);
// Replaces a host mesh by a copy in one device allocation (NBMC_MEMORY_DEVICE).
void move_mesh_to_device(HostMesh& m);
// Copies count items of item_bytes, byte_stride apart in CUDA memory (checked
// to be device memory of the current GPU, aligned to value_bytes), packed
// into host. Throws Error(NBMC_ERROR_INVALID_ARGUMENT) for a host or
// misaligned pointer, (NBMC_ERROR_BACKEND_UNAVAILABLE) without CUDA.
// host_hint names the setter for host arrays (in the message for a host pointer).
void download_device_items(const void* src, std::uint64_t count, std::uint64_t byte_stride, std::size_t item_bytes,
                           std::size_t value_bytes, void* host, const char* fn,
                           const char* host_hint = "nbmc_context_set_attribute_f32/f64");
// Free memory of the current CUDA device (0 without CUDA).
std::uint64_t cuda_free_memory();

}  // namespace nbmc
