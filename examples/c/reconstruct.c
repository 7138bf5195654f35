/* SPDX-License-Identifier: MIT */
/*
 * reconstruct: the smallest complete use of the nbmc C ABI.
 *
 *   reconstruct PARTICLES.xyz SPACING OUT.ply [THREADS]
 *
 * Reads a raw particle file (little-endian float32 x, y, z triples, no header),
 * reconstructs the fluid surface with particle spacing SPACING and writes the
 * mesh as a binary little-endian PLY (positions, normals, triangles).
 *
 * Every nbmc call is checked: on failure the program prints the status name
 * and nbmc_context_last_error() and exits with status 1. Copy freely.
 */
#include <nbmc.h>

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------ file helpers */

/* Reads little-endian float32 triples; returns a malloc'ed array of 3 * *count
 * floats, or NULL with a message printed. */
static float* read_xyz(const char* path, uint64_t* count) {
  FILE* f = fopen(path, "rb");
  unsigned char* bytes = NULL;
  float* xyz = NULL;
  long size;
  size_t n, i;
  if (!f) {
    fprintf(stderr, "error: cannot open %s: %s\n", path, strerror(errno));
    return NULL;
  }
  if (fseek(f, 0, SEEK_END) != 0 || (size = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) {
    fprintf(stderr, "error: cannot determine the size of %s\n", path);
    fclose(f);
    return NULL;
  }
  if (size == 0 || size % 12 != 0) {
    fprintf(stderr, "error: %s has %ld bytes, not a positive multiple of 12 (float32 x, y, z)\n", path, size);
    fclose(f);
    return NULL;
  }
  n = (size_t)size / 4; /* number of floats */
  bytes = (unsigned char*)malloc((size_t)size);
  xyz = (float*)malloc(n * sizeof(float));
  if (!bytes || !xyz || fread(bytes, 1, (size_t)size, f) != (size_t)size) {
    fprintf(stderr, "error: cannot read %s\n", path);
    free(bytes);
    free(xyz);
    fclose(f);
    return NULL;
  }
  fclose(f);
  /* Decode explicitly so the program also works on big-endian hosts. */
  for (i = 0; i < n; ++i) {
    const unsigned char* b = bytes + 4 * i;
    uint32_t u = (uint32_t)b[0] | ((uint32_t)b[1] << 8) | ((uint32_t)b[2] << 16) | ((uint32_t)b[3] << 24);
    memcpy(&xyz[i], &u, sizeof u);
  }
  free(bytes);
  *count = (uint64_t)(n / 3);
  return xyz;
}

static int put_u32(FILE* f, uint32_t u) {
  unsigned char b[4];
  b[0] = (unsigned char)(u & 0xffu);
  b[1] = (unsigned char)((u >> 8) & 0xffu);
  b[2] = (unsigned char)((u >> 16) & 0xffu);
  b[3] = (unsigned char)((u >> 24) & 0xffu);
  return fwrite(b, 1, 4, f) == 4;
}

static int put_f32(FILE* f, float v) {
  uint32_t u;
  memcpy(&u, &v, sizeof u);
  return put_u32(f, u);
}

/* Writes a binary little-endian PLY; normals may be NULL. Returns 1 on success. */
static int write_ply(const char* path, uint64_t nv, const float* pos, const float* nrm, uint64_t nt,
                     const uint32_t* tri) {
  FILE* f = fopen(path, "wb");
  uint64_t i;
  int k, ok = 1;
  if (!f) {
    fprintf(stderr, "error: cannot create %s: %s\n", path, strerror(errno));
    return 0;
  }
  fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment written by the nbmc C example\n");
  fprintf(f, "element vertex %llu\nproperty float x\nproperty float y\nproperty float z\n", (unsigned long long)nv);
  if (nrm) fprintf(f, "property float nx\nproperty float ny\nproperty float nz\n");
  fprintf(f, "element face %llu\nproperty list uchar uint vertex_indices\nend_header\n", (unsigned long long)nt);
  for (i = 0; i < nv && ok; ++i) {
    for (k = 0; k < 3; ++k) ok = ok && put_f32(f, pos[3 * i + k]);
    if (nrm)
      for (k = 0; k < 3; ++k) ok = ok && put_f32(f, nrm[3 * i + k]);
  }
  for (i = 0; i < nt && ok; ++i) {
    ok = fputc(3, f) != EOF;
    for (k = 0; k < 3; ++k) ok = ok && put_u32(f, tri[3 * i + k]);
  }
  if (fclose(f) != 0) ok = 0;
  if (!ok) fprintf(stderr, "error: writing %s failed\n", path);
  return ok;
}

/* ------------------------------------------------------------------- main */

/* Prints the failed call, the status name and the context's message. */
static int report(const char* call, int32_t status, const nbmc_context* ctx) {
  fprintf(stderr, "error: %s failed: %s (status %d): %s\n", call, nbmc_status_string(status), (int)status,
          nbmc_context_last_error(ctx));
  return 1;
}

int main(int argc, char** argv) {
  nbmc_context_desc desc;
  nbmc_context* ctx = NULL;
  nbmc_params params;
  nbmc_stats stats;
  nbmc_mesh* mesh = NULL;
  float* xyz = NULL;
  uint64_t count = 0, nv, nt;
  int32_t status, backend = -1;
  double spacing;
  char* end = NULL;
  int rc = 1;

  if (argc < 4 || argc > 5) {
    fprintf(stderr, "usage: %s PARTICLES.xyz SPACING OUT.ply [THREADS]\n", argv[0]);
    return 2;
  }
  spacing = strtod(argv[2], &end);
  if (end == argv[2] || *end != '\0' || !(spacing > 0)) {
    fprintf(stderr, "error: SPACING must be a positive number, got '%s'\n", argv[2]);
    return 2;
  }

  /* The header this program was compiled with must match the loaded library's
   * major version (same SOVERSION); a newer minor is fine. */
  if (nbmc_version() / 10000 != NBMC_VERSION_MAJOR || nbmc_version() < NBMC_VERSION) {
    fprintf(stderr, "error: compiled against nbmc %d.%d.%d but loaded %s\n", NBMC_VERSION_MAJOR,
            NBMC_VERSION_MINOR, NBMC_VERSION_PATCH, nbmc_version_string());
    return 1;
  }
  printf("nbmc %s\n", nbmc_version_string());

  xyz = read_xyz(argv[1], &count);
  if (!xyz) return 1;
  printf("read %llu particles from %s\n", (unsigned long long)count, argv[1]);

  nbmc_context_desc_init(&desc); /* always start from the defaults */
  if (argc == 5) desc.num_threads = atoi(argv[4]);
  status = nbmc_context_create(&desc, &ctx);
  if (status != NBMC_OK) {
    report("nbmc_context_create", status, NULL); /* NULL: this thread's create error */
    goto done;
  }
  status = nbmc_context_backend(ctx, &backend);
  if (status != NBMC_OK) {
    report("nbmc_context_backend", status, ctx);
    goto done;
  }

  /* Tightly packed [x, y, z] floats: byte_stride 0. The data are copied. */
  status = nbmc_context_set_particles_f32(ctx, xyz, count, 0);
  free(xyz);
  xyz = NULL;
  if (status != NBMC_OK) {
    report("nbmc_context_set_particles_f32", status, ctx);
    goto done;
  }

  nbmc_params_init(&params); /* lengths default to multiples of the spacing */
  params.spacing = spacing;
  status = nbmc_context_reconstruct(ctx, &params, &mesh);
  if (status != NBMC_OK) {
    report("nbmc_context_reconstruct", status, ctx);
    goto done;
  }

  nbmc_stats_init(&stats);
  status = nbmc_context_stats(ctx, &stats);
  if (status != NBMC_OK) {
    report("nbmc_context_stats", status, ctx);
    goto done;
  }

  /* The mesh owns its memory and outlives the context: release the context first. */
  nbmc_context_destroy(ctx);
  ctx = NULL;

  nv = nbmc_mesh_vertex_count(mesh);
  nt = nbmc_mesh_triangle_count(mesh);
  printf("backend %d: %llu surface particles, %llu vertices, %llu triangles in %.3f s\n", (int)backend,
         (unsigned long long)stats.surface_particle_count, (unsigned long long)nv, (unsigned long long)nt,
         stats.total_seconds);
  if (nt == 0) {
    fprintf(stderr, "error: the mesh is empty (is SPACING right for these particles?)\n");
    goto done;
  }
  if (!write_ply(argv[3], nv, nbmc_mesh_positions(mesh), nbmc_mesh_normals(mesh), nt, nbmc_mesh_triangles(mesh)))
    goto done;
  printf("wrote %s\n", argv[3]);
  rc = 0;

done:
  free(xyz);
  nbmc_mesh_destroy(mesh);   /* NULL is fine */
  nbmc_context_destroy(ctx); /* NULL is fine */
  return rc;
}
