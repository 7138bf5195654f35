/* SPDX-License-Identifier: MIT */
/*
 * The thread-safety contract of nbmc.h: "Different contexts and meshes may be
 * used from different threads at once. One context ... may move between
 * threads." The main thread creates a context (and so initialises Kokkos);
 * then a context created on the main thread is used on a worker thread, and
 * two workers create and use contexts of their own at the same time. Every
 * reconstruction must succeed and give the same mesh.
 */
#include "nbmc.h"

#include <pthread.h>
#include <stdio.h>

#define SIDE 10
#define COUNT (SIDE * SIDE * SIDE)

static float g_xyz[3 * COUNT];

typedef struct job {
  nbmc_context* ctx; /* NULL: create one on the worker */
  int32_t status;
  uint64_t triangles;
  char message[256];
} job;

static void* work(void* arg) {
  job* j = (job*)arg;
  nbmc_context* ctx = j->ctx;
  nbmc_params params;
  nbmc_mesh* mesh = NULL;
  j->status = NBMC_OK;
  if (!ctx) j->status = nbmc_context_create(NULL, &ctx);
  if (j->status == NBMC_OK) j->status = nbmc_context_set_particles_f32(ctx, g_xyz, COUNT, 0);
  if (j->status == NBMC_OK) {
    nbmc_params_init(&params);
    params.spacing = 0.1;
    j->status = nbmc_context_reconstruct(ctx, &params, &mesh);
  }
  snprintf(j->message, sizeof j->message, "%s", nbmc_context_last_error(ctx));
  j->triangles = nbmc_mesh_triangle_count(mesh);
  nbmc_mesh_destroy(mesh);
  nbmc_context_destroy(ctx);
  return NULL;
}

int main(void) {
  job jobs[3] = {{NULL, 0, 0, ""}, {NULL, 0, 0, ""}, {NULL, 0, 0, ""}};
  pthread_t threads[3];
  job local = {NULL, 0, 0, ""};
  int i, failures = 0;
  for (i = 0; i < COUNT; ++i) {
    g_xyz[3 * i] = 0.1f * (float)(i % SIDE);
    g_xyz[3 * i + 1] = 0.1f * (float)((i / SIDE) % SIDE);
    g_xyz[3 * i + 2] = 0.1f * (float)(i / (SIDE * SIDE));
  }
  work(&local); /* the main thread first: initialises Kokkos here */
  if (local.status != NBMC_OK) {
    fprintf(stderr, "main thread: %s: %s\n", nbmc_status_string(local.status), local.message);
    return 1;
  }
  if (nbmc_context_create(NULL, &jobs[0].ctx) != NBMC_OK) return 1; /* moves to a worker */
  for (i = 0; i < 3; ++i) pthread_create(&threads[i], NULL, work, &jobs[i]);
  for (i = 0; i < 3; ++i) pthread_join(threads[i], NULL);
  for (i = 0; i < 3; ++i) {
    if (jobs[i].status != NBMC_OK || jobs[i].triangles != local.triangles) {
      fprintf(stderr, "worker %d: %s (status %d): %s; %llu triangles, main thread %llu\n", i,
              nbmc_status_string(jobs[i].status), (int)jobs[i].status, jobs[i].message,
              (unsigned long long)jobs[i].triangles, (unsigned long long)local.triangles);
      ++failures;
    }
  }
  if (failures) return 1;
  printf("contexts on 3 threads: all reconstructions agree (%llu triangles)\n", (unsigned long long)local.triangles);
  return 0;
}
