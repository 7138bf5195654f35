/* SPDX-License-Identifier: MIT */
/*
 * nbmc.h as C99 under -Wall -Wextra -Werror -pedantic -Wconversion
 * -Wstrict-prototypes (see CMakeLists.txt), and the contract of the ABI that
 * needs no particles: version, names, initialisers, NULL handling and misuse
 * with exact status codes.
 */
#include "nbmc.h"
#include "nbmc.h" /* the include guard works */

#include <math.h>
#include <stdio.h>
#include <string.h>

/* C99 has no static_assert. */
#define NBMC_ABI_STATIC_ASSERT(cond, name) typedef char nbmc_abi_assert_##name[(cond) ? 1 : -1]

NBMC_ABI_STATIC_ASSERT(NBMC_VERSION == NBMC_VERSION_MAJOR * 10000 + NBMC_VERSION_MINOR * 100 + NBMC_VERSION_PATCH,
                       version_formula);
NBMC_ABI_STATIC_ASSERT(NBMC_STAGE_COUNT <= NBMC_STAGE_SLOTS, stage_slots);
NBMC_ABI_STATIC_ASSERT(offsetof(nbmc_context_desc, struct_size) == 0, desc_size_first);
NBMC_ABI_STATIC_ASSERT(offsetof(nbmc_params, struct_size) == 0, params_size_first);
NBMC_ABI_STATIC_ASSERT(offsetof(nbmc_stats, struct_size) == 0, stats_size_first);
/* The NBMC_METHOD_YT10 block starts where the struct before it ended (its
   sizeof, tail padding included): a caller built against that header passes
   struct_size = that sizeof, and none of its bytes reach the new fields. */
NBMC_ABI_STATIC_ASSERT(offsetof(nbmc_params, aniso_kr) ==
                           (offsetof(nbmc_params, reserved1) + 4 + sizeof(double) - 1) / sizeof(double) *
                               sizeof(double),
                       params_yt10_after_old_size);
/* The structs are made of fixed-width members with no hidden padding
 * differences between compilers: sizes are multiples of 8. */
NBMC_ABI_STATIC_ASSERT(sizeof(nbmc_context_desc) % 8 == 0, desc_size);
NBMC_ABI_STATIC_ASSERT(sizeof(nbmc_params) % 8 == 0, params_size);
NBMC_ABI_STATIC_ASSERT(sizeof(nbmc_stats) % 8 == 0, stats_size);
/* The clean-up's counts follow pre_decimation_triangle_count: a caller built
   before them passes struct_size = their offset. */
NBMC_ABI_STATIC_ASSERT(offsetof(nbmc_stats, cleanup_bad_triangles_before) ==
                           offsetof(nbmc_stats, pre_decimation_triangle_count) + 8,
                       stats_cleanup_after_old_size);
NBMC_ABI_STATIC_ASSERT(sizeof(((nbmc_stats*)0)->stage_seconds) == NBMC_STAGE_SLOTS * sizeof(double), stage_array);

static int failures = 0;

#define CHECK(cond)                                                    \
  do {                                                                 \
    if (!(cond)) {                                                     \
      fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond); \
      ++failures;                                                      \
    }                                                                  \
  } while (0)

static int32_t never_called(void* user, int32_t stage, double fraction) {
  (void)user;
  (void)stage;
  (void)fraction;
  return 0;
}

int main(void) {
  int32_t s;
  nbmc_context_desc desc;
  nbmc_params params;
  nbmc_stats stats;
  nbmc_context* ctx = NULL;
  nbmc_mesh* mesh = (nbmc_mesh*)&desc; /* must be overwritten with NULL */
  int32_t backend = -1;
  const float one[3] = {0.0f, 0.0f, 0.0f};

  /* Version: the loaded library is the one this header belongs to. */
  CHECK(nbmc_version() == NBMC_VERSION);
  CHECK(nbmc_version_string() != NULL && nbmc_version_string()[0] != '\0');

  /* Names are static and total. */
  for (s = NBMC_OK; s <= NBMC_ERROR_FORMAT; ++s) CHECK(strcmp(nbmc_status_string(s), "unknown status") != 0);
  CHECK(strcmp(nbmc_status_string(NBMC_OK), "ok") == 0);
  CHECK(strcmp(nbmc_status_string(-1), "unknown status") == 0);
  CHECK(strcmp(nbmc_status_string(100000), "unknown status") == 0);
  for (s = 0; s < NBMC_STAGE_COUNT; ++s) CHECK(nbmc_stage_name(s) != NULL);
  CHECK(nbmc_stage_name(-1) == NULL);
  /* The post-processing stage (host) comes after the pipeline's stages. */
  CHECK(strcmp(nbmc_stage_name(NBMC_STAGE_POSTPROCESS), "postprocess") == 0);
  CHECK(strcmp(nbmc_stage_name(NBMC_STAGE_ATTRIBUTES), "attributes") == 0);
  CHECK(nbmc_stage_name(NBMC_STAGE_ATTRIBUTES + 1) == NULL);
  CHECK(nbmc_backend_available(NBMC_BACKEND_SERIAL) == 1);
  CHECK(nbmc_backend_available(NBMC_BACKEND_AUTO) == 1);
  CHECK(nbmc_backend_available(-1) == 0);
  CHECK(nbmc_backend_available(1000) == 0);

  /* Initialisers fill struct_size and the documented defaults. */
  memset(&desc, 0xff, sizeof desc);
  nbmc_context_desc_init(&desc);
  CHECK(desc.struct_size == sizeof(nbmc_context_desc));
  CHECK(desc.backend == NBMC_BACKEND_AUTO && desc.num_threads == 0 && desc.flags == 0);
  memset(&params, 0xff, sizeof params);
  nbmc_params_init(&params);
  CHECK(params.struct_size == sizeof(nbmc_params));
  CHECK(params.spacing == 0.0 && params.length_unit == NBMC_UNIT_SPACING);
  CHECK(params.cell_size == 0.5 && params.influence_radius == 4.0 && params.band_width == 2.0);
  CHECK(params.surface_radius == 2.0 && params.iso_radius == 1.0);
  CHECK(params.method == NBMC_METHOD_SSP07 && params.field == NBMC_FIELD_NARROW_BAND);
  CHECK(params.t_low == 0.4 && params.t_high == 3.5 && params.color_threshold == 0.75);
  CHECK(params.neighbour_threshold == 25 && params.compute_normals != 0 && params.use_bbox == 0);
  CHECK(params.cleanup == 1 && params.smooth_iterations == 0 && params.iso_threshold == 0.6);
  CHECK(NBMC_METHOD_SPH == 2);
  CHECK(params.isolated == NBMC_ISOLATED_KEEP && params.min_cluster == 10 && NBMC_ISOLATED_DROP == 1);
  CHECK(params.decimate_fraction == 1.0 && params.smooth_weighting == NBMC_SMOOTH_UNIFORM && params.reserved1 == 0);
  CHECK(NBMC_ISOLATED_SPHERE == 2 && NBMC_SMOOTH_FEATURE == 1);
  CHECK(NBMC_METHOD_YT10 == 3 && params.aniso_kr == 4.0 && params.aniso_ks == 1.0 && params.aniso_kn == 0.5);
  CHECK(params.aniso_lambda == 0.3 && params.aniso_neighbours == 25 && params.reserved2 == 0);
  CHECK(params.max_distance == 1.5);
  memset(&stats, 0xff, sizeof stats);
  nbmc_stats_init(&stats);
  CHECK(stats.struct_size == sizeof(nbmc_stats) && stats.triangle_count == 0);
  nbmc_context_desc_init(NULL); /* no-ops */
  nbmc_params_init(NULL);
  nbmc_stats_init(NULL);

  /* NULL handles. */
  nbmc_context_destroy(NULL);
  nbmc_mesh_destroy(NULL);
  CHECK(nbmc_mesh_vertex_count(NULL) == 0 && nbmc_mesh_triangle_count(NULL) == 0);
  CHECK(nbmc_mesh_positions(NULL) == NULL && nbmc_mesh_normals(NULL) == NULL && nbmc_mesh_triangles(NULL) == NULL);
  CHECK(nbmc_mesh_positions_f64(NULL) == NULL);
  CHECK(nbmc_mesh_sphere_count(NULL) == 0 && nbmc_mesh_spheres(NULL) == NULL);
  CHECK(nbmc_context_backend(NULL, &backend) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_particles_f32(NULL, one, 1, 0) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_particles_f64(NULL, NULL, 1, 0) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_progress(NULL, never_called, NULL) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_reconstruct(NULL, &params, &mesh) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(mesh == NULL); /* set to NULL on failure */
  CHECK(nbmc_context_stats(NULL, &stats) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_create(NULL, NULL) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_particles_device_f32(NULL, one, 1, 0) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_particles_device_f64(NULL, NULL, 1, 0) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_mesh_memory(NULL, NBMC_MEMORY_HOST) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_mesh_memory(NULL) == NBMC_MEMORY_HOST);
  CHECK(nbmc_mesh_copy_to_host(NULL, NULL, NULL, NULL) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_attribute_f32(NULL, "a", one, 1, 0) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_attribute_f64(NULL, "a", NULL, 1, 0) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_attribute_device_f32(NULL, "a", one, 1, 0) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_context_set_attribute_device_f64(NULL, "a", NULL, 1, 0) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(nbmc_mesh_attribute_count(NULL) == 0 && nbmc_mesh_attribute_name(NULL, 0) == NULL);
  {
    uint32_t components = 9;
    CHECK(nbmc_mesh_attribute(NULL, "a", &components) == NULL && components == 0);
    CHECK(nbmc_last_error()[0] != '\0');
  }
  CHECK(strcmp(nbmc_stage_name(NBMC_STAGE_ATTRIBUTES), "attributes") == 0);

  /* Misuse of create: exact codes, a message, *out set to NULL. */
  ctx = (nbmc_context*)&desc;
  nbmc_context_desc_init(&desc);
  desc.struct_size = 4;
  CHECK(nbmc_context_create(&desc, &ctx) == NBMC_ERROR_INVALID_ARGUMENT);
  CHECK(ctx == NULL);
  CHECK(nbmc_context_last_error(NULL)[0] != '\0');
  nbmc_context_desc_init(&desc);
  desc.backend = 42;
  CHECK(nbmc_context_create(&desc, &ctx) == NBMC_ERROR_INVALID_ARGUMENT && ctx == NULL);
  nbmc_context_desc_init(&desc);
  desc.flags = 0x80000000u; /* unknown flag bit */
  CHECK(nbmc_context_create(&desc, &ctx) == NBMC_ERROR_INVALID_ARGUMENT && ctx == NULL);
  nbmc_context_desc_init(&desc);
  desc.num_threads = -1;
  CHECK(nbmc_context_create(&desc, &ctx) == NBMC_ERROR_INVALID_ARGUMENT && ctx == NULL);

  /* A real context: misuse gives exact codes and leaves it usable. */
  s = nbmc_context_create(NULL, &ctx);
  CHECK(s == NBMC_OK && ctx != NULL);
  CHECK(nbmc_context_last_error(NULL)[0] == '\0'); /* cleared by the successful create */
  if (ctx) {
    const float bad[6] = {0.0f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f};
    float nan_xyz[3];
    nan_xyz[0] = 0.0f;
    nan_xyz[1] = NAN;
    nan_xyz[2] = 0.0f;
    CHECK(nbmc_context_backend(ctx, &backend) == NBMC_OK && backend != NBMC_BACKEND_AUTO);
    CHECK(nbmc_context_stats(ctx, &stats) == NBMC_ERROR_NO_PARTICLES);
    nbmc_params_init(&params);
    params.spacing = 0.1;
    CHECK(nbmc_context_reconstruct(ctx, &params, &mesh) == NBMC_ERROR_NO_PARTICLES && mesh == NULL);
    CHECK(nbmc_context_last_error(ctx)[0] != '\0');
    CHECK(nbmc_context_set_particles_f32(ctx, bad, 0, 0) == NBMC_ERROR_NO_PARTICLES);
    CHECK(nbmc_context_set_particles_f32(ctx, NULL, 2, 0) == NBMC_ERROR_INVALID_ARGUMENT);
    CHECK(nbmc_context_set_particles_f32(ctx, bad, 2, 8) == NBMC_ERROR_INVALID_ARGUMENT);
    CHECK(nbmc_context_set_particles_f32(ctx, nan_xyz, 1, 0) == NBMC_ERROR_INVALID_PARTICLES);
    CHECK(nbmc_context_set_particles_f32(ctx, bad, 2, 0) == NBMC_OK);
    CHECK(nbmc_context_last_error(ctx)[0] == '\0'); /* "" after success */
    CHECK(nbmc_context_reconstruct(ctx, NULL, &mesh) == NBMC_ERROR_INVALID_ARGUMENT);
    CHECK(nbmc_context_reconstruct(ctx, &params, NULL) == NBMC_ERROR_INVALID_ARGUMENT);
    params.struct_size = 8;
    CHECK(nbmc_context_reconstruct(ctx, &params, &mesh) == NBMC_ERROR_INVALID_ARGUMENT);
    nbmc_params_init(&params);
    CHECK(nbmc_context_reconstruct(ctx, &params, &mesh) == NBMC_ERROR_INVALID_PARAMETER); /* spacing 0 */
    params.spacing = 0.1;
    params.method = 7;
    CHECK(nbmc_context_reconstruct(ctx, &params, &mesh) == NBMC_ERROR_INVALID_PARAMETER);
    params.method = NBMC_METHOD_SSP07;
    params.t_low = 4.0;
    CHECK(nbmc_context_reconstruct(ctx, &params, &mesh) == NBMC_ERROR_INVALID_PARAMETER);
    params.t_low = 0.4;
    CHECK(nbmc_context_set_progress(ctx, never_called, NULL) == NBMC_OK);
    CHECK(nbmc_context_set_progress(ctx, NULL, NULL) == NBMC_OK);
    /* Device memory: NBMC_MEMORY_* only, and only the CUDA backend takes device pointers. */
    CHECK(nbmc_context_set_mesh_memory(ctx, 7) == NBMC_ERROR_INVALID_ARGUMENT);
    CHECK(nbmc_context_set_mesh_memory(ctx, NBMC_MEMORY_HOST) == NBMC_OK);
    if (backend != NBMC_BACKEND_CUDA) {
      CHECK(nbmc_context_set_mesh_memory(ctx, NBMC_MEMORY_DEVICE) == NBMC_ERROR_BACKEND_UNAVAILABLE);
      CHECK(nbmc_context_set_particles_device_f32(ctx, bad, 2, 0) == NBMC_ERROR_BACKEND_UNAVAILABLE);
      CHECK(nbmc_context_last_error(ctx)[0] != '\0');
    }
    CHECK(nbmc_kokkos_finalize() == NBMC_ERROR_INVALID_ARGUMENT); /* a context is alive */
    nbmc_context_destroy(ctx);
  }
  CHECK(nbmc_kokkos_finalize() == NBMC_OK);

  if (failures) {
    fprintf(stderr, "%d check(s) failed\n", failures);
    return 1;
  }
  printf("nbmc.h as C99: all checks passed (%s)\n", nbmc_version_string());
  return 0;
}
