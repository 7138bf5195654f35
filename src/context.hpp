// SPDX-License-Identifier: MIT
// Internal definitions of the opaque C handles.
#pragma once

#include "nbmc.h"

#include "../backends/kokkos/common.hpp"
#include "../backends/kokkos/pipeline.hpp"
#include "core/decomposition.hpp"
#include "core/mesh_postprocess.hpp"
#include "io/attributes.hpp"

#include <cstdint>
#include <memory>
#include <mutex>
#include <new>
#include <utility>
#include <string>
#include <vector>

namespace nbmc {
using ParticleVector = std::vector<double, NoInitAllocator<double>>;

// Particles uploaded from device memory: packed doubles on the CUDA device.
struct DeviceParticles {
  std::shared_ptr<void> data;
  std::size_t count = 0;
};
}  // namespace nbmc

struct nbmc_context {
  nbmc_context() = default;
  nbmc_context(const nbmc_context&) = delete;
  nbmc_context& operator=(const nbmc_context&) = delete;
  ~nbmc_context();  // capi.cpp: unpins the particle buffer
  int32_t backend = NBMC_BACKEND_SERIAL;
  int32_t num_threads = 0;
  int32_t device_id = 0;
  uint32_t flags = 0;
  std::string last_error;
  nbmc::ParticleVector particles;  // validated, 3 per particle
  void* pinned = nullptr;          // particles.data() while page-locked for the GPU (CUDA contexts)
  nbmc::DeviceParticles device_particles;  // or these, on the CUDA device
  int32_t mesh_memory = NBMC_MEMORY_HOST;
  nbmc_progress_fn progress_fn = nullptr;
  void* progress_user = nullptr;
  nbmc::MemoryTracker memory;
  std::uint64_t peak_memory = 0;
  nbmc::RunStats stats;
  nbmc::SubdomainSetting subdomains;       // nbmc_context_set_subdomains
  bool collective = false;                 // one of several processes' contexts (libnbmc_mpi)
  int32_t pending_status = 0;              // collective: the last upload's failure, for every rank to see
  std::string pending_error;
  std::shared_ptr<void> attached;          // libnbmc_mpi's communicator (nbmc__context_attach)
  nbmc::SubdomainReport subdomain_report;  // of the last reconstruction
  nbmc::mesh::PostprocessStats postprocess;  // of the last reconstruction (capi_mesh.cpp)
  bool has_stats = false;
  // nbmc_context_set_attribute*: per-particle values (doubles) for the
  // particles uploaded last; every particle upload clears them.
  std::vector<nbmc::io::Attribute> attributes;
  // nbmc_context_set_radii*: one radius per particle uploaded last (absolute,
  // validated, their smallest and largest), or empty; every particle upload
  // clears them.
  std::vector<double> radii;
  double radius_min = 0, radius_max = 0;
  // Particles uploaded last (on the host or the device).
  std::uint64_t particle_count() const {
    return device_particles.count ? device_particles.count : particles.size() / 3;
  }
  // What belongs to the particles uploaded last (attributes, radii): every
  // particle upload removes it.
  void clear_particle_values() {
    attributes.clear();
    std::vector<double>().swap(radii);
    radius_min = radius_max = 0;
  }
};

namespace nbmc {
// An attribute interpolated onto a mesh's vertices (host memory).
struct MeshAttribute {
  std::string name;
  std::uint32_t components = 1;
  std::vector<float> values;  // components per vertex
};
}  // namespace nbmc

struct nbmc_mesh {
  nbmc::HostMesh mesh;
  std::vector<nbmc::MeshAttribute> attributes;
  // NBMC_ISOLATED_SPHERE: x, y, z, radius per dropped particle (host memory).
  std::vector<float> spheres;
  // A mesh with double positions (mesh.f64): its float positions, rounded
  // once on first request (nbmc_mesh_positions may be called concurrently).
  mutable std::once_flag rounded;
  // The float positions of a host mesh (rounded from the doubles of an f64
  // mesh); null when it has none. Throws std::bad_alloc.
  const float* float_positions() const;
};
