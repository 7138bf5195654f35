// SPDX-License-Identifier: MIT
// nbmc.h as C++17 under -Wall -Wextra -Werror -pedantic -Wconversion, and the
// properties a C++ host relies on: C linkage, standard-layout trivially
// copyable structs, handles usable with std::unique_ptr.
#include "nbmc.h"
#include "nbmc.h"

#include <cstdio>
#include <cstring>
#include <memory>
#include <type_traits>
#include <vector>

static_assert(NBMC_VERSION == NBMC_VERSION_MAJOR * 10000 + NBMC_VERSION_MINOR * 100 + NBMC_VERSION_PATCH);
static_assert(NBMC_STAGE_COUNT <= NBMC_STAGE_SLOTS);
static_assert(std::is_standard_layout_v<nbmc_context_desc> && std::is_trivially_copyable_v<nbmc_context_desc>);
static_assert(std::is_standard_layout_v<nbmc_params> && std::is_trivially_copyable_v<nbmc_params>);
static_assert(std::is_standard_layout_v<nbmc_stats> && std::is_trivially_copyable_v<nbmc_stats>);
static_assert(offsetof(nbmc_context_desc, struct_size) == 0 && offsetof(nbmc_params, struct_size) == 0 &&
              offsetof(nbmc_stats, struct_size) == 0);
static_assert(std::is_same_v<decltype(nbmc_context_desc::struct_size), uint32_t>);
static_assert(std::is_same_v<decltype(&nbmc_context_create), int32_t (*)(const nbmc_context_desc*, nbmc_context**)>);
static_assert(std::is_same_v<decltype(&nbmc_mesh_triangles), const uint32_t* (*)(const nbmc_mesh*)>);
static_assert(std::is_same_v<nbmc_progress_fn, int32_t (*)(void*, int32_t, double)>);
static_assert(std::is_same_v<decltype(&nbmc_context_set_particles_device_f32),
                             int32_t (*)(nbmc_context*, const float*, uint64_t, uint64_t)>);
static_assert(std::is_same_v<decltype(&nbmc_context_set_particles_device_f64),
                             int32_t (*)(nbmc_context*, const double*, uint64_t, uint64_t)>);
static_assert(std::is_same_v<decltype(&nbmc_context_set_mesh_memory), int32_t (*)(nbmc_context*, int32_t)>);
static_assert(std::is_same_v<decltype(&nbmc_mesh_memory), int32_t (*)(const nbmc_mesh*)>);
static_assert(std::is_same_v<decltype(&nbmc_mesh_copy_to_host),
                             int32_t (*)(const nbmc_mesh*, float*, float*, uint32_t*)>);
static_assert(NBMC_MEMORY_HOST == 0 && NBMC_MEMORY_DEVICE == 1);
static_assert(std::is_same_v<decltype(&nbmc_mesh_positions_f64), const double* (*)(const nbmc_mesh*)>);
static_assert(std::is_same_v<decltype(nbmc_params::double_positions), int32_t>);
static_assert(std::is_same_v<decltype(&nbmc_context_set_attribute_f32),
                             int32_t (*)(nbmc_context*, const char*, const float*, uint32_t, uint64_t)>);
static_assert(std::is_same_v<decltype(&nbmc_context_set_attribute_f64),
                             int32_t (*)(nbmc_context*, const char*, const double*, uint32_t, uint64_t)>);
static_assert(std::is_same_v<decltype(&nbmc_context_set_attribute_device_f32),
                             int32_t (*)(nbmc_context*, const char*, const float*, uint32_t, uint64_t)>);
static_assert(std::is_same_v<decltype(&nbmc_context_set_attribute_device_f64),
                             int32_t (*)(nbmc_context*, const char*, const double*, uint32_t, uint64_t)>);
static_assert(std::is_same_v<decltype(&nbmc_mesh_attribute_count), uint32_t (*)(const nbmc_mesh*)>);
static_assert(std::is_same_v<decltype(&nbmc_mesh_attribute_name), const char* (*)(const nbmc_mesh*, uint32_t)>);
static_assert(std::is_same_v<decltype(&nbmc_mesh_attribute), const float* (*)(const nbmc_mesh*, const char*, uint32_t*)>);
static_assert(NBMC_STAGE_ATTRIBUTES == 8 && NBMC_STAGE_ATTRIBUTES < NBMC_STAGE_SLOTS);
static_assert(std::is_same_v<decltype(&nbmc_mesh_sphere_count), uint64_t (*)(const nbmc_mesh*)>);
static_assert(std::is_same_v<decltype(&nbmc_mesh_spheres), const float* (*)(const nbmc_mesh*)>);
static_assert(std::is_same_v<decltype(nbmc_params::decimate_fraction), double>);
static_assert(std::is_same_v<decltype(nbmc_params::smooth_weighting), int32_t>);
static_assert(std::is_same_v<decltype(nbmc_stats::pre_decimation_triangle_count), uint64_t>);
static_assert(std::is_same_v<decltype(nbmc_stats::cleanup_bad_triangles_before), uint64_t> &&
              std::is_same_v<decltype(nbmc_stats::cleanup_removed_component_triangles), uint64_t>);
// Appended after the last field of the struct before them, in this order.
static_assert(offsetof(nbmc_stats, cleanup_bad_triangles_before) ==
                  offsetof(nbmc_stats, pre_decimation_triangle_count) + 8 &&
              offsetof(nbmc_stats, cleanup_removed_component_triangles) ==
                  offsetof(nbmc_stats, cleanup_bad_triangles_before) + 6 * 8);
static_assert(NBMC_ISOLATED_SPHERE == 2 && NBMC_SMOOTH_UNIFORM == 0 && NBMC_SMOOTH_FEATURE == 1);

namespace {
struct ContextDeleter {
  void operator()(nbmc_context* c) const noexcept { nbmc_context_destroy(c); }
};
struct MeshDeleter {
  void operator()(nbmc_mesh* m) const noexcept { nbmc_mesh_destroy(m); }
};
using ContextPtr = std::unique_ptr<nbmc_context, ContextDeleter>;
using MeshPtr = std::unique_ptr<nbmc_mesh, MeshDeleter>;

int failures = 0;
void check(bool ok, const char* what, int line) {
  if (!ok) {
    std::fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, line, what);
    ++failures;
  }
}
#define CHECK(cond) check((cond), #cond, __LINE__)
}  // namespace

int main() {
  CHECK(nbmc_version() == NBMC_VERSION);
  nbmc_context_desc desc{};
  nbmc_context_desc_init(&desc);
  desc.backend = NBMC_BACKEND_SERIAL;
  nbmc_context* raw = nullptr;
  CHECK(nbmc_context_create(&desc, &raw) == NBMC_OK);
  ContextPtr ctx(raw);

  // A 4x4x4 block of particles: a closed surface comes out.
  float xyz[64][3];
  for (int i = 0; i < 64; ++i) {
    xyz[i][0] = 0.1f * float(i % 4);
    xyz[i][1] = 0.1f * float((i / 4) % 4);
    xyz[i][2] = 0.1f * float(i / 16);
  }
  CHECK(nbmc_context_set_particles_f32(ctx.get(), &xyz[0][0], 64, 0) == NBMC_OK);

  int calls = 0;
  // A captureless lambda converts to the callback type.
  nbmc_progress_fn fn = [](void* user, int32_t stage, double fraction) -> int32_t {
    ++*static_cast<int*>(user);
    return stage >= 0 && stage < NBMC_STAGE_COUNT && fraction >= 0.0 && fraction <= 1.0 ? 0 : 1;
  };
  CHECK(nbmc_context_set_progress(ctx.get(), fn, &calls) == NBMC_OK);

  nbmc_params params;
  nbmc_params_init(&params);
  params.spacing = 0.1;
  nbmc_mesh* m = nullptr;
  CHECK(nbmc_context_reconstruct(ctx.get(), &params, &m) == NBMC_OK);
  MeshPtr mesh(m);
  CHECK(calls > 0);
  CHECK(nbmc_mesh_triangle_count(mesh.get()) > 0);
  nbmc_stats stats;
  nbmc_stats_init(&stats);
  CHECK(nbmc_context_stats(ctx.get(), &stats) == NBMC_OK);
  CHECK(stats.particle_count == 64 && stats.triangle_count == nbmc_mesh_triangle_count(mesh.get()));

  ctx.reset();  // the mesh outlives its context
  const uint64_t nt = nbmc_mesh_triangle_count(mesh.get());
  const uint64_t nv = nbmc_mesh_vertex_count(mesh.get());
  const uint32_t* tri = nbmc_mesh_triangles(mesh.get());
  bool in_range = tri != nullptr;
  for (uint64_t i = 0; in_range && i < 3 * nt; ++i) in_range = tri[i] < nv;
  CHECK(in_range);
  // A host mesh copies out exactly what the getters show.
  CHECK(nbmc_mesh_memory(mesh.get()) == NBMC_MEMORY_HOST);
  std::vector<uint32_t> tri_copy(3 * nt);
  CHECK(nbmc_mesh_copy_to_host(mesh.get(), nullptr, nullptr, tri_copy.data()) == NBMC_OK);
  CHECK(tri != nullptr && std::memcmp(tri_copy.data(), tri, tri_copy.size() * sizeof(uint32_t)) == 0);
  mesh.reset();

  if (failures) {
    std::fprintf(stderr, "%d check(s) failed\n", failures);
    return 1;
  }
  std::printf("nbmc.h as C++17: all checks passed (%llu triangles)\n", static_cast<unsigned long long>(nt));
  return 0;
}
