/* SPDX-License-Identifier: MIT */
/* Cost of the attribute interpolation (NBMC_STAGE_ATTRIBUTES) on a raw
 * float32 xyz frame: one reconstruction without, one with a vector and a
 * scalar attribute, on the OpenMP backend (or the one named by BACKEND:
 * serial, openmp, cuda).
 *   cc -O2 bench/attributes_cost.c -Ibuild/install/include -Lbuild/install/lib -lnbmc \
 *      -Wl,-rpath,$PWD/build/install/lib -o attributes_cost
 *   ./attributes_cost FRAME.xyz SPACING THREADS [BACKEND] */
#include <nbmc.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
int main(int argc, char** argv) {
  if (argc != 4 && argc != 5) {
    fprintf(stderr, "usage: attributes_cost FRAME.xyz SPACING THREADS [serial|openmp|cuda]\n");
    return 2;
  }
  FILE* f = fopen(argv[1], "rb"); fseek(f, 0, SEEK_END); long sz = ftell(f); fseek(f, 0, SEEK_SET);
  size_t n = sz / 12; float* p = malloc(sz); fread(p, 1, sz, f); fclose(f);
  nbmc_context_desc d; nbmc_context_desc_init(&d); d.backend = NBMC_BACKEND_OPENMP;
  if (argc == 5) d.backend = !strcmp(argv[4], "cuda") ? NBMC_BACKEND_CUDA : !strcmp(argv[4], "serial") ? NBMC_BACKEND_SERIAL : NBMC_BACKEND_OPENMP; d.num_threads = atoi(argv[3]);
  nbmc_context* ctx;
  if (nbmc_context_create(&d, &ctx) != NBMC_OK) { fprintf(stderr, "no context for that backend\n"); return 1; }
  nbmc_params prm; nbmc_params_init(&prm); prm.spacing = atof(argv[2]);
  for (int with = 0; with < 2; ++with) {
    nbmc_context_set_particles_f32(ctx, p, n, 0);
    if (with) { nbmc_context_set_attribute_f32(ctx, "vel", p, 3, 0); nbmc_context_set_attribute_f32(ctx, "x", p, 1, 12); }
    nbmc_mesh* m; int s = nbmc_context_reconstruct(ctx, &prm, &m);
    nbmc_stats st; nbmc_stats_init(&st); nbmc_context_stats(ctx, &st);
    printf("%s attrs=%d: %zu particles, %llu vertices, total %.3f s, attributes stage %.3f s (status %d)\n", argv[1], with, n,
           (unsigned long long)st.vertex_count, st.total_seconds, st.stage_seconds[NBMC_STAGE_ATTRIBUTES], s);
    nbmc_mesh_destroy(m);
  }
  nbmc_context_destroy(ctx);
  return 0;
}
