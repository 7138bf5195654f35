/* SPDX-License-Identifier: MIT */
/*
 * nbmc — narrow-band marching cubes for particle-based fluids.
 *
 * The stable C ABI. Written by hand; see docs/api.md for the long form.
 *
 * Conventions
 *  - Every fallible function returns an int32_t status (NBMC_OK == 0).
 *    Handles come back through out-parameters.
 *  - nbmc_status_string(code) returns a static string; the detailed message of
 *    the last failed call on a context is nbmc_context_last_error(ctx), valid
 *    until the next call on that context.
 *  - Enumerations travel as int32_t; their values are never renumbered.
 *  - Structs passed in start with `uint32_t struct_size`; fill them with the
 *    matching nbmc_*_init() function before changing fields.
 *  - Uploads copy. A mesh owns its memory and outlives its context. Arrays
 *    are host memory unless a function says otherwise (NBMC_MEMORY_DEVICE).
 *    Every *_destroy(NULL) is a no-op.
 *
 * Thread safety
 *  - Different contexts and meshes may be used from different threads at once;
 *    reconstructions on one backend run one after the other (one Kokkos runtime
 *    per process), each giving the same mesh as when run alone.
 *  - One context must not be used by two threads at the same time (no internal
 *    locking); it may move between threads.
 *  - When nbmc initialises Kokkos, it does so on a thread of its own and runs
 *    every reconstruction there (Kokkos 3.4's OpenMP space only accepts work
 *    from the thread that initialised it), unless the first context asks for
 *    NBMC_CONTEXT_KOKKOS_ON_CALLING_THREAD. When the Kokkos runtime belongs to
 *    a thread of the host (it initialised Kokkos, or used that flag), call
 *    nbmc_context_reconstruct from that thread, as Kokkos itself requires.
 *  - Mesh getters are read-only and may be called concurrently on one mesh.
 */
#ifndef NBMC_H
#define NBMC_H

#include <stddef.h>
#include <stdint.h>

#define NBMC_VERSION_MAJOR 0
#define NBMC_VERSION_MINOR 1
#define NBMC_VERSION_PATCH 0
#define NBMC_VERSION (NBMC_VERSION_MAJOR * 10000 + NBMC_VERSION_MINOR * 100 + NBMC_VERSION_PATCH)

#if defined(_WIN32)
#  if defined(NBMC_BUILDING_LIBRARY)
#    define NBMC_API __declspec(dllexport)
#  else
#    define NBMC_API __declspec(dllimport)
#  endif
#elif defined(__GNUC__) || defined(__clang__)
#  define NBMC_API __attribute__((visibility("default")))
#else
#  define NBMC_API
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* ------------------------------------------------------------------ status */
/* Values are fixed forever; new codes are only appended. */
#define NBMC_OK                          0
#define NBMC_ERROR_INVALID_ARGUMENT      1  /* null pointer, bad enum value, bad struct_size */
#define NBMC_ERROR_INVALID_PARTICLES     2  /* a position is NaN, infinite or beyond 1e15 */
#define NBMC_ERROR_NO_PARTICLES          3  /* zero particles, or none uploaded yet */
#define NBMC_ERROR_INVALID_PARAMETER     4  /* spacing <= 0, radius too small, thresholds inverted, ... */
#define NBMC_ERROR_DOMAIN_TOO_LARGE      5  /* grid indices or mesh indices would overflow */
#define NBMC_ERROR_OUT_OF_MEMORY         6  /* host or device allocation failed */
#define NBMC_ERROR_BACKEND_UNAVAILABLE   7  /* requested backend not compiled in or no device */
#define NBMC_ERROR_IO                    8  /* file could not be read or written */
#define NBMC_ERROR_INTERNAL              9  /* a bug: please report with the message */
#define NBMC_ERROR_MEMORY_BUDGET        10  /* estimated need exceeds the context's memory budget */
#define NBMC_ERROR_CANCELLED            11  /* the progress callback asked to stop */
#define NBMC_ERROR_FORMAT               12  /* a file is malformed or of an unsupported kind */

/* --------------------------------------------------------------- constants */
/* Backends (nbmc_context_desc.backend). */
#define NBMC_BACKEND_AUTO    0  /* CUDA when compiled in and a device exists, else OpenMP, else serial */
#define NBMC_BACKEND_SERIAL  1
#define NBMC_BACKEND_OPENMP  2
#define NBMC_BACKEND_CUDA    3

/* Scalar field methods (nbmc_params.method). */
#define NBMC_METHOD_SSP07  0  /* Solenthaler, Schlaefli, Pajarola 2007 (default) */
#define NBMC_METHOD_ZB05   1  /* Zhu & Bridson 2005 */
#define NBMC_METHOD_SPH    2  /* normalised SPH density (cubic spline), splashsurf's level set;
                                 iso level nbmc_params.iso_threshold */
#define NBMC_METHOD_YT10   3  /* Yu & Turk 2010: SPH density with anisotropic kernels (per-particle
                                 weighted PCA, nbmc_params.aniso_*); iso level iso_threshold */

/* Isolated particles (nbmc_params.isolated). */
#define NBMC_ISOLATED_KEEP  0  /* every particle makes surface (default) */
#define NBMC_ISOLATED_DROP  1  /* clusters of fewer than min_cluster particles make none */
#define NBMC_ISOLATED_SPHERE 2 /* as DROP, and their particles are returned as spheres
                                  (nbmc_mesh_sphere_count, nbmc_mesh_spheres) */

/* Smoothing weights (nbmc_params.smooth_weighting). */
#define NBMC_SMOOTH_UNIFORM  0  /* every vertex smoothed alike (default) */
#define NBMC_SMOOTH_FEATURE  1  /* per vertex, by the particles near it: thin features are kept */

/* Field evaluation strategies (nbmc_params.field). */
#define NBMC_FIELD_NARROW_BAND  0  /* gather on band vertices only (the method; default) */
#define NBMC_FIELD_DENSE        1  /* baseline: gather on every vertex of the bounding grid */
#define NBMC_FIELD_SCATTER      2  /* baseline: serial scatter over a dense grid */

/* Context flags (nbmc_context_desc.flags). */
/* When nbmc initialises Kokkos, do it on the calling thread instead of a
 * thread of nbmc's own: the host may then use that Kokkos runtime too, and
 * must call nbmc_context_reconstruct from this thread only. */
#define NBMC_CONTEXT_KOKKOS_ON_CALLING_THREAD 1u

/* Where arrays handed to or returned by nbmc live. */
#define NBMC_MEMORY_HOST    0  /* ordinary host memory (default) */
#define NBMC_MEMORY_DEVICE  1  /* CUDA memory of the context's GPU (CUDA backend only) */

/* How lengths in nbmc_params are given (nbmc_params.length_unit). */
#define NBMC_UNIT_SPACING   0  /* multiples of the particle spacing r (default) */
#define NBMC_UNIT_ABSOLUTE  1  /* the same units as the particle positions */

/* Pipeline stages, for timings and progress. */
#define NBMC_STAGE_UPLOAD             0  /* validation, bounds, copy to the backend */
#define NBMC_STAGE_NEIGHBOURHOOD      1  /* z-order sort, cell starts */
#define NBMC_STAGE_SURFACE_PARTICLES  2
#define NBMC_STAGE_BAND               3  /* narrow band marking and compaction */
#define NBMC_STAGE_FIELD              4  /* scalar field */
#define NBMC_STAGE_TRIANGULATION      5  /* marching cubes, normals */
#define NBMC_STAGE_OUTPUT             6  /* copy of the mesh to the host */
#define NBMC_STAGE_COUNT              7
#define NBMC_STAGE_SLOTS             16  /* size of the stage arrays in nbmc_stats */

/* ------------------------------------------------------------ opaque types */
typedef struct nbmc_context nbmc_context;
typedef struct nbmc_mesh nbmc_mesh;

/* ----------------------------------------------------------------- version */
/* NBMC_VERSION of the library actually loaded (compare with the header's). */
NBMC_API uint32_t nbmc_version(void);
/* "major.minor.patch" plus the compiled-in backends, static string. */
NBMC_API const char* nbmc_version_string(void);
/* Static English name of a status code ("unknown status" for others). */
NBMC_API const char* nbmc_status_string(int32_t status);
/* Static name of a stage ("upload", "neighbourhood", ...), NULL if out of range. */
NBMC_API const char* nbmc_stage_name(int32_t stage);
/* 1 if the backend is compiled in and usable on this machine, else 0. */
NBMC_API int32_t nbmc_backend_available(int32_t backend);

/* ----------------------------------------------------------------- context */
typedef struct nbmc_context_desc {
  uint32_t struct_size; /* sizeof(nbmc_context_desc) */
  int32_t backend;      /* NBMC_BACKEND_*, default AUTO */
  int32_t num_threads;  /* host threads for OpenMP; 0 = all cores (default); at most 65536,
                           clamped to 4x the cores (at least 16) */
  int32_t device_id;    /* CUDA device, default 0 */
  uint32_t flags;       /* NBMC_CONTEXT_* bits, default 0 */
  uint32_t reserved0;
} nbmc_context_desc;

/* Fills *desc with the defaults. */
NBMC_API void nbmc_context_desc_init(nbmc_context_desc* desc);

/* Creates a context. desc may be NULL for the defaults. Initialises the Kokkos
 * runtime on first use if the host program has not (see
 * nbmc_kokkos_finalize); the context is then independent of all others.
 * On failure *out is set to NULL. */
NBMC_API int32_t nbmc_context_create(const nbmc_context_desc* desc, nbmc_context** out);

/* Destroys a context and its buffers. Meshes it produced stay valid. */
NBMC_API void nbmc_context_destroy(nbmc_context* ctx);

/* Message of the last failed call on ctx ("" after success); valid until the
 * next call on ctx. With ctx == NULL, the message of the last failed
 * nbmc_context_create on this thread. */
NBMC_API const char* nbmc_context_last_error(const nbmc_context* ctx);

/* The backend the context really uses (AUTO resolved). */
NBMC_API int32_t nbmc_context_backend(const nbmc_context* ctx, int32_t* backend);

/* Uploads (copies) count particle positions. Particle i's x, y, z are the
 * three consecutive values at byte offset i * byte_stride from xyz;
 * byte_stride 0 means tightly packed (3 * sizeof value). Works for C arrays of
 * [x,y,z] and for Fortran pos(3, n). Replaces earlier particles and removes
 * all particle attributes (nbmc_context_set_attribute_*). Positions are
 * validated here: NaN, Inf or a magnitude above 1e15 gives
 * NBMC_ERROR_INVALID_PARTICLES (the message names the first bad particle),
 * count 0 gives NBMC_ERROR_NO_PARTICLES; on failure the context keeps no
 * particles. One particle, or many at the same position, is valid input (a
 * sphere of radius iso_radius). Large uploads are validated on several
 * threads (the context's num_threads). On a CUDA context the copy is
 * page-locked for fast transfers to the GPU, and later uploads whose size
 * is within a factor 2 reuse it (the first upload pays for the locking). */
NBMC_API int32_t nbmc_context_set_particles_f32(nbmc_context* ctx, const float* xyz,
                                                uint64_t count, uint64_t byte_stride);
NBMC_API int32_t nbmc_context_set_particles_f64(nbmc_context* ctx, const double* xyz,
                                                uint64_t count, uint64_t byte_stride);

/* The same from CUDA device memory (cudaMalloc'd or managed memory of the
 * context's GPU), for solvers whose particles live on the GPU: the positions
 * are copied and validated on the device, nothing goes through the host.
 * float or double, byte_stride as above but a multiple of the value size
 * (and xyz aligned to it). The context must use NBMC_BACKEND_CUDA; other
 * backends give NBMC_ERROR_BACKEND_UNAVAILABLE. A host pointer, or device
 * memory of another GPU, gives NBMC_ERROR_INVALID_ARGUMENT; bad positions
 * NBMC_ERROR_INVALID_PARTICLES as above. The call returns when the copy is
 * done (the caller may then change its array). The copy is device memory
 * held by the context (24 bytes per particle) until the next upload or
 * nbmc_context_destroy. */
NBMC_API int32_t nbmc_context_set_particles_device_f32(nbmc_context* ctx, const float* xyz,
                                                       uint64_t count, uint64_t byte_stride);
NBMC_API int32_t nbmc_context_set_particles_device_f64(nbmc_context* ctx, const double* xyz,
                                                       uint64_t count, uint64_t byte_stride);

/* Where the meshes of later reconstructions on ctx are put:
 * NBMC_MEMORY_HOST (default) or NBMC_MEMORY_DEVICE, which leaves them in the
 * GPU's memory (for a renderer or a GPU post-process; no copy to the host):
 * CUDA backend only, else NBMC_ERROR_BACKEND_UNAVAILABLE. */
NBMC_API int32_t nbmc_context_set_mesh_memory(nbmc_context* ctx, int32_t memory);

/* Progress and cancellation. The callback is called during
 * nbmc_context_reconstruct, on the thread that runs the reconstruction (see
 * Thread safety; the calling thread waits meanwhile), with the stage
 * (NBMC_STAGE_*) and the fraction of that stage done in [0,1];
 * returning non-zero cancels the reconstruction, which then returns
 * NBMC_ERROR_CANCELLED. fn == NULL removes it. */
typedef int32_t (*nbmc_progress_fn)(void* user, int32_t stage, double fraction);
NBMC_API int32_t nbmc_context_set_progress(nbmc_context* ctx, nbmc_progress_fn fn, void* user);

/* Caps the memory nbmc may allocate for this context's reconstructions, host
 * and device together, in bytes (0 = no cap, the default). Before it
 * allocates, a reconstruction estimates what the frame needs (after sizing the
 * grid, and again after finding the surface particles); over the cap it
 * returns NBMC_ERROR_MEMORY_BUDGET with the estimate in the message, and any
 * single allocation that would pass the cap fails the same way. The context
 * stays usable. The returned mesh is counted while it is being built. The
 * mesh post-processing (clean-up, smoothing, decimation; host memory, after
 * the reconstruction) is counted too: before each step, its estimated peak
 * (an upper bound from the mesh's vertex and triangle counts, docs/api.md)
 * plus the mesh it works on must fit, else the call fails with
 * NBMC_ERROR_MEMORY_BUDGET naming the step (no mesh is returned); while the
 * step runs, that estimate counts towards nbmc_stats.peak_memory_bytes. */
NBMC_API int32_t nbmc_context_set_memory_budget(nbmc_context* ctx, uint64_t bytes);

/* -------------------------------------------------------------- parameters */
typedef struct nbmc_params {
  uint32_t struct_size;     /* sizeof(nbmc_params) */
  int32_t length_unit;      /* NBMC_UNIT_SPACING (default) or NBMC_UNIT_ABSOLUTE */
  double spacing;           /* r: rest distance of the particles, absolute, > 0. Required. */
  double cell_size;         /* marching-cubes cell edge; default 0.5 (r/2) */
  double influence_radius;  /* R, kernel support of the field; default 4 (4r) */
  double band_width;        /* half width of the band box around surface particles; default 2 (2r) */
  double surface_radius;    /* neighbourhood radius of the surface-particle test; default 2 (2r);
                               at most 2 * influence_radius */
  double iso_radius;        /* r-bar of eq. (1) (SSP07) / particle radius (ZB05); default 1 (r) */
  int32_t method;           /* NBMC_METHOD_*, default SSP07 */
  int32_t field;            /* NBMC_FIELD_*, default NARROW_BAND */
  double t_low;             /* SSP07 eigenvalue thresholds; default 0.4 */
  double t_high;            /*                               default 3.5 */
  double color_threshold;   /* |grad colour field| * surface_radius above which a particle is on the
                               surface; default 0.75 */
  int32_t neighbour_threshold; /* fewer neighbours within surface_radius => surface; default 25 */
  int32_t compute_normals;  /* non-zero (default): per-vertex normals from the field gradient */
  int32_t use_bbox;         /* non-zero: only particles within R of [bbox_min, bbox_max] (absolute)
                               are used and the grid covers the box plus a margin of
                               max(band_width, iso_radius + cell_size) + 2 cells; the mesh is
                               not clipped to the box and may reach into that margin
                               (NBMC_METHOD_SPH and NBMC_METHOD_YT10: particles within 2R,
                               margin with R in place of iso_radius) */
  int32_t reserved0;
  double bbox_min[3];
  double bbox_max[3];
  /* Appended with the mesh post-processing (see "Mesh post-processing"
     below): a caller built against a header without them passes the shorter
     struct, and these fields keep their defaults. */
  int32_t cleanup;          /* non-zero (default): remove degenerate and sliver triangles by edge
                               collapses and flips; 0: the raw marching-cubes mesh */
  int32_t smooth_iterations; /* Taubin lambda|mu smoothing steps after the clean-up (then, with
                               cleanup on, the clean-up again, ending with fairing flips of the
                               edges whose other diagonal bends the surface less); default 0 */
  /* Appended with NBMC_METHOD_SPH (older callers: the default). */
  double iso_threshold;     /* NBMC_METHOD_SPH and NBMC_METHOD_YT10: iso level of the normalised
                               density, a fraction of the rest density, 0 < iso_threshold < 1;
                               default 0.6 (splashsurf's --surface-threshold). SPH: the kernel's
                               compact support is influence_radius. Ignored by the other methods. */
  /* Appended with the isolated-particle filter (older callers: the defaults). */
  int32_t isolated;         /* NBMC_ISOLATED_KEEP (default) or NBMC_ISOLATED_DROP: a cluster is a
                               connected component of the particles linked when closer than
                               surface_radius; clusters of fewer than min_cluster particles are
                               left out before the reconstruction (nbmc_stats counts them). Host
                               work, O(particles); not available over MPI */
  int32_t min_cluster;      /* NBMC_ISOLATED_DROP: smallest cluster kept, >= 1; default 10 */
  /* Appended with double-precision positions (older callers: the default). */
  int32_t double_positions; /* non-zero: the mesh keeps its vertex positions in double precision
                               (nbmc_mesh_positions_f64) through the clean-up, smoothing, the
                               subdomain stitch and the MPI gather, and the writers that can
                               (PLY, OBJ, VTK, VTU, VTP, HDF5) store doubles. The field is still
                               float, relative to the grid origin: the gain is for coordinates
                               far from the origin (at 5e6 m a float resolves 0.5 m; a double
                               keeps the field's relative precision there). Host meshes only:
                               with NBMC_MEMORY_DEVICE, NBMC_ERROR_INVALID_PARAMETER.
                               0 (default): float positions, as before */
  /* Appended with decimation and feature-weighted smoothing (older callers:
     the defaults; see "Mesh post-processing" below). */
  double decimate_fraction; /* 0 < f <= 1: after the clean-up and smoothing, quadric-error edge
                               collapses down to f times the triangles (fewer collapses where
                               one would open, fold or break the mesh); 1 (default): off */
  int32_t smooth_weighting; /* NBMC_SMOOTH_UNIFORM (default) or NBMC_SMOOTH_FEATURE: each vertex's
                               smoothing step scaled by a weight in [0, 1] from the particles
                               around it (few, as on a thin sheet, a filament or a droplet:
                               near 0; the bulk: 1). Not available over MPI */
  int32_t reserved1;        /* 0 */
  /* Appended with NBMC_METHOD_YT10 (older callers: the defaults). Yu & Turk's
     anisotropic kernels (docs/methods.md): each particle's neighbours within
     influence_radius R give a weighted covariance, whose principal axes
     stretch that particle's kernel (isotropic support h = R/2). Checked
     whatever the method; used by NBMC_METHOD_YT10 only. */
  double aniso_kr;          /* k_r: largest ratio of a kernel's longest to its shortest axis, >= 1;
                               default 4 (Yu & Turk) */
  double aniso_ks;          /* k_s: scale of the kernel axes, > 0, normalised so that a particle
                               inside a uniform fluid gets the isotropic kernel at k_s = 1 (Yu &
                               Turk's 1400 is in their scene's units; see docs/methods.md);
                               default 1. Axes are clamped to at most 1.5 h */
  double aniso_kn;          /* k_n: kernel scale of a particle with aniso_neighbours or fewer
                               neighbours (a sphere of support k_n h), 0 < k_n <= 1.5; also the
                               smallest longest axis of any kernel; default 0.5 (Yu & Turk) */
  double aniso_lambda;      /* lambda: Laplacian smoothing of the kernel centres towards their
                               neighbours' weighted mean, 0 <= lambda <= 1 (0: none); default 0.3;
                               a centre moves at most 0.2 R */
  int32_t aniso_neighbours; /* N_eps: more neighbours than this within R (the particle itself not
                               counted) give an anisotropic kernel, fewer a sphere; >= 0;
                               default 25 (Yu & Turk) */
  int32_t reserved2;        /* 0 */
  /* Appended with the distance guard (older callers: the default). */
  double max_distance;      /* rho: where no particle lies within rho (a length, like cell_size), the
                               field is raised so that the surface stays within about rho of the
                               particles (bench/RESULTS.md: every vertex within rho + 0.4 r at
                               cell r): bridges between splashes and fillets in concave corners
                               that lie farther out are cut back to balls of radius rho around the
                               particles. With per-particle radii each particle's rho scales with
                               its radius. NBMC_METHOD_SSP07, ZB05 and SPH; ignored by YT10 (its
                               kernels keep its surface close). >= 0; 0 or >= influence_radius:
                               off; default 1.5 (1.5 r) */
} nbmc_params;

/* Fills *params with the defaults (spacing is 0 and must be set). */
NBMC_API void nbmc_params_init(nbmc_params* params);

/* ------------------------------------------------------------ reconstruct */
/* Reconstructs the surface of the uploaded particles. On success *mesh is a
 * new mesh the caller owns (free with nbmc_mesh_destroy); on failure it is set
 * to NULL and the context stays usable. Blocking. */
NBMC_API int32_t nbmc_context_reconstruct(nbmc_context* ctx, const nbmc_params* params,
                                          nbmc_mesh** mesh);

/* Figures of the last successful reconstruction on ctx. */
typedef struct nbmc_stats {
  uint32_t struct_size;        /* sizeof(nbmc_stats) */
  uint32_t reserved0;
  uint64_t particle_count;
  uint64_t surface_particle_count;
  uint64_t occupied_cell_count;    /* non-empty neighbour-grid cells */
  uint64_t band_vertex_count;      /* grid vertices where the field was evaluated */
  uint64_t band_block_count;       /* allocated 8x8x8 band blocks (dense: 0) */
  uint64_t grid_vertex_count;      /* vertices of the whole bounding grid (not allocated) */
  uint64_t triangulated_cell_count;
  uint64_t vertex_count;
  uint64_t triangle_count;
  uint64_t grid_dims[3];           /* vertices per axis of the bounding grid */
  uint64_t peak_memory_bytes;      /* peak of nbmc's own allocations during the call */
  uint64_t neighbour_evaluations;  /* particle-vertex pairs inside the influence radius */
  double stage_seconds[NBMC_STAGE_SLOTS]; /* indexed by NBMC_STAGE_* */
  double total_seconds;
  double grid_origin[3];
  double cell_size;                /* absolute */
  /* Appended with the mesh post-processing (NBMC_STAGE_POSTPROCESS): a caller
     built against a header without them passes the shorter struct and gets
     the fields it has. */
  uint64_t raw_triangle_count;     /* triangles of the marching-cubes mesh, before the clean-up */
  double smoothing_volume_change;  /* enclosed volume after smoothing / before - 1; 0 without */
  /* Appended with the isolated-particle filter (nbmc_params.isolated). */
  uint64_t dropped_particle_count; /* particles left out as isolated (0 with NBMC_ISOLATED_KEEP) */
  uint64_t dropped_cluster_count;  /* the clusters they formed */
  /* Appended with decimation (nbmc_params.decimate_fraction). */
  uint64_t pre_decimation_triangle_count; /* triangles before the decimation (after the clean-up
                                             and smoothing); triangle_count without decimation */
  /* Appended with the clean-up's counts (nbmc_params.cleanup; all 0 with the
     clean-up off). The clean-up runs on the marching-cubes mesh and, with
     smoothing on, once more after it: the counts of repairs are summed over
     both runs. Bad triangles: degenerate + sliver, as nbmc_mesh_check
     counts them. raw_triangle_count - pre_decimation_triangle_count =
     2 cleanup_collapses + 6 cleanup_cuts + cleanup_removed_component_triangles. */
  uint64_t cleanup_bad_triangles_before; /* bad triangles of the marching-cubes mesh */
  uint64_t cleanup_bad_triangles_after;  /* left after the last clean-up (none could repair them) */
  uint64_t cleanup_moves;                /* repairs that moved vertices (one within its tangent
                                            plane, or a needle's cluster widened) */
  uint64_t cleanup_flips;                /* edges flipped */
  uint64_t cleanup_collapses;            /* edges collapsed (each removes a vertex and two
                                            triangles) */
  uint64_t cleanup_cuts;                 /* pinched tubes cut (the last resort; each removes six
                                            triangles) */
  uint64_t cleanup_removed_component_triangles; /* triangles removed with whole bad components:
                                            droplets smaller than a cell and specks of
                                            degenerate triangles */
} nbmc_stats;

NBMC_API void nbmc_stats_init(nbmc_stats* stats);
NBMC_API int32_t nbmc_context_stats(const nbmc_context* ctx, nbmc_stats* stats);

/* -------------------------------------------------------------------- mesh */
/* Counts; 0 for NULL. */
NBMC_API uint64_t nbmc_mesh_vertex_count(const nbmc_mesh* mesh);
NBMC_API uint64_t nbmc_mesh_triangle_count(const nbmc_mesh* mesh);
/* Pointers into the mesh (valid until nbmc_mesh_destroy): positions and normals
 * are 3 * vertex_count floats (x,y,z per vertex), triangles 3 * triangle_count
 * vertex indices, counter-clockwise seen from outside the fluid. Normals point
 * out of the fluid and are NULL when compute_normals was 0. Empty mesh: NULL.
 * A mesh made with nbmc_params.double_positions: positions are its doubles
 * rounded to float (see nbmc_mesh_positions_f64). */
NBMC_API const float* nbmc_mesh_positions(const nbmc_mesh* mesh);
NBMC_API const float* nbmc_mesh_normals(const nbmc_mesh* mesh);
NBMC_API const uint32_t* nbmc_mesh_triangles(const nbmc_mesh* mesh);
NBMC_API void nbmc_mesh_destroy(nbmc_mesh* mesh);
/* Double-precision positions (3 * vertex_count doubles, x,y,z per vertex) of
 * a mesh reconstructed with nbmc_params.double_positions, owned by the mesh
 * and valid until nbmc_mesh_destroy; NULL for NULL, an empty mesh, or a mesh
 * made without double_positions (its float positions are all it has: a
 * widened copy would only pretend to the precision). On such a mesh,
 * nbmc_mesh_positions returns the positions rounded to float (computed on the
 * first call, once, and kept by the mesh; safe to call concurrently). */
NBMC_API const double* nbmc_mesh_positions_f64(const nbmc_mesh* mesh);
/* Where the mesh's arrays live: NBMC_MEMORY_HOST, or NBMC_MEMORY_DEVICE (see
 * nbmc_context_set_mesh_memory), in which case nbmc_mesh_positions, _normals
 * and _triangles return CUDA device pointers (same layout), valid until
 * nbmc_mesh_destroy, which frees them (also after nbmc_kokkos_finalize).
 * NBMC_MEMORY_HOST for NULL. */
NBMC_API int32_t nbmc_mesh_memory(const nbmc_mesh* mesh);
/* Copies the mesh's arrays, wherever they live, into host buffers of
 * 3 * vertex_count floats (positions, normals) and 3 * triangle_count
 * uint32_t (triangles); any pointer may be NULL to skip that array. normals
 * is left untouched when the mesh has none. NBMC_ERROR_INVALID_ARGUMENT for
 * a NULL mesh. */
NBMC_API int32_t nbmc_mesh_copy_to_host(const nbmc_mesh* mesh, float* positions, float* normals,
                                        uint32_t* triangles);

/* ---- File I/O ---- */
/* Particle files and mesh files through nbmc's own readers and writers
 * (docs/formats.md). Formats are named in lower case; NULL or "" means "from
 * the file name's extension".
 *   particles: "xyz", "ply", "vtk", "vtu", "vtp", "bgeo", "h5part", "pysph",
 *              "gadget" (also "swift"), "hdf5"; an HDF5 object is named after
 *              the file: "run.h5:/PartType1" or "data.h5:/group/positions".
 *   meshes:    "ply", "obj", "vtk", "vtu", "glb".
 * Errors: NBMC_ERROR_IO when a file cannot be opened, read or written,
 * NBMC_ERROR_FORMAT when it is malformed or of an unsupported kind,
 * NBMC_ERROR_INVALID_ARGUMENT for NULL pointers or an unknown format name.
 * Messages name the file. */

/* Reads the particle positions of the file at path and uploads them to ctx
 * as nbmc_context_set_particles_f64 does (same validation: NaN/Inf gives
 * NBMC_ERROR_INVALID_PARTICLES, an empty file NBMC_ERROR_NO_PARTICLES).
 * Multi-step files (H5Part) give their first step. On success *count_out
 * (may be NULL) is the number of particles; on failure it is 0 and the
 * context keeps no particles. The file is only read during the call.
 * Same threading rules as every call on ctx; reading HDF5 files is
 * serialised inside nbmc. */
NBMC_API int32_t nbmc_context_load_particles(nbmc_context* ctx, const char* path, const char* format,
                                             uint64_t* count_out);

/* Writes mesh to path in format (NULL: by the extension); a device mesh is
 * copied to the host first. The file is written
 * under a temporary name in the same folder and renamed into place, so a
 * failed call leaves no partial file and an existing file is replaced only
 * on success. mesh is only read; several threads may write the same mesh at
 * once. On failure the message is nbmc_last_error(). An empty mesh gives an
 * empty but valid file. */
NBMC_API int32_t nbmc_mesh_write(const nbmc_mesh* mesh, const char* path, const char* format);

/* Message of the last failed call on this thread that has no context to keep
 * it (nbmc_mesh_write, and nbmc_context_load_particles with ctx == NULL);
 * "" after such a call succeeds. Thread-local; valid until the next such call
 * on the same thread. Calls on a context keep theirs in
 * nbmc_context_last_error(ctx). */
NBMC_API const char* nbmc_last_error(void);

/* ------------------------------------------------------------------ Kokkos */
/* nbmc initialises Kokkos on the first nbmc_context_create unless the host
 * program already did. nbmc never finalises a Kokkos runtime it did not
 * initialise. A host that lets nbmc initialise Kokkos may call this after
 * destroying all contexts (and before exit) to finalise it; otherwise it is
 * finalised at process exit. Returns NBMC_OK, or NBMC_ERROR_INVALID_ARGUMENT
 * while contexts are alive. */
NBMC_API int32_t nbmc_kokkos_finalize(void);

/* ------------------------------------------------------ mesh post-processing */
/* nbmc_context_reconstruct post-processes the mesh on the host, for every
 * backend, after the pipeline (a mesh left in GPU memory with
 * NBMC_MEMORY_DEVICE is copied to the host for it and back into its device
 * arrays), serially, so the result depends only on the raw mesh (same on
 * every backend and thread count):
 *  - clean-up (nbmc_params.cleanup, default on): every degenerate or sliver
 *    triangle (as defined for nbmc_mesh_check) is repaired by collapsing one of
 *    its edges or flipping its longest edge, keeping the mesh closed, manifold
 *    and oriented (link condition checked before each collapse; no triangle
 *    turns by 60 degrees or more; good triangles stay good). Those that no
 *    repair can fix without folding the surface stay. After smoothing,
 *    the clean-up runs again and then flips edges where the quad's other
 *    diagonal bends the surface less (the fairing flips: no vertex moves,
 *    no triangle gets an angle below 5 degrees or its pair's smallest,
 *    docs/api.md).
 *  - smoothing (nbmc_params.smooth_iterations, default 0): Taubin's lambda|mu
 *    filter (lambda = 0.5, mu = -0.53, uniform weights), each iteration one
 *    lambda and one mu step; a component whose volume changed by more than
 *    1% (a droplet of a few vertices, which the filter shrinks) is scaled
 *    back to its volume about its centroid; normals are then recomputed from
 *    the faces, and with the clean-up on, it runs once more.
 *    With nbmc_params.smooth_weighting = NBMC_SMOOTH_FEATURE, each vertex's
 *    steps are scaled by w = s(clamp((n / n_bulk - 0.15) / 0.2, 0, 1)),
 *    s(x) = 3x^2 - 2x^3, with n = sum over the particles j within the
 *    influence radius R of (1 - |x - x_j|^2 / R^2) at the vertex x before
 *    smoothing, and n_bulk = (8/15) pi (R / spacing)^3 the same sum inside a
 *    lattice of the spacing (Loeschner et al. 2023): a flat surface gets 1,
 *    thin sheets, filaments and droplets, with few particles near, barely
 *    move. The particles are those the surface was made of (host work).
 *  - decimation (nbmc_params.decimate_fraction < 1): Garland and Heckbert's
 *    quadric-error edge collapses, cheapest first (ties by vertex index),
 *    until the mesh has at most that fraction of its triangles; each collapse
 *    checked as in the clean-up (link condition, each vertex keeps three
 *    neighbours, no triangle turns by 60 degrees or more, none becomes
 *    degenerate, no good triangle becomes a sliver), so the mesh stays
 *    closed, manifold and oriented and its genus is kept; where every
 *    remaining collapse is refused, it stops above the target. Normals are
 *    recomputed from the faces (area-weighted).
 * The time goes to stage NBMC_STAGE_POSTPROCESS of nbmc_stats, and the vertex
 * and triangle counts there are those of the returned mesh. Particle
 * attributes are interpolated afterwards, onto the final vertices. */
#define NBMC_STAGE_POSTPROCESS 7  /* mesh clean-up and smoothing (host) */

/* Topology and quality of a mesh (nbmc_mesh_check). Definitions:
 *  - an edge is a pair of vertices joined by at least one triangle; boundary:
 *    one triangle; non-manifold: three or more; misoriented: two triangles
 *    that run along it in the same direction;
 *  - a non-manifold vertex has triangles that form more than one fan around
 *    it (two surfaces touching at a point);
 *  - degenerate: area below 1e-12 times the square of the largest side of the
 *    mesh's bounding box, or a vertex repeated; sliver: not degenerate, with
 *    an angle below 1 degree;
 *  - components: sets of triangles connected through shared edges. */
typedef struct nbmc_mesh_check_result {
  uint32_t struct_size;               /* sizeof(nbmc_mesh_check_result) */
  int32_t closed;                     /* 1: every edge has exactly two triangles */
  int32_t manifold;                   /* 1: no non-manifold edge or vertex */
  int32_t oriented;                   /* 1: no misoriented edge */
  uint64_t vertex_count;
  uint64_t triangle_count;
  uint64_t edge_count;
  uint64_t boundary_edge_count;
  uint64_t nonmanifold_edge_count;
  uint64_t misoriented_edge_count;
  uint64_t nonmanifold_vertex_count;
  uint64_t unreferenced_vertex_count; /* vertices no triangle uses */
  uint64_t degenerate_triangle_count;
  uint64_t sliver_triangle_count;
  uint64_t component_count;
  int64_t euler_characteristic;       /* V - E + F, V counting the vertices triangles use
                                         (2 per closed sphere-like component) */
  double volume;                      /* enclosed volume (divergence theorem): positive when the
                                         triangles are counter-clockwise seen from outside; taken
                                         about the bounding box centre (matters if not closed) */
  double area;                        /* total triangle area */
  double min_angle_degrees;           /* smallest angle of a non-degenerate triangle (0 if none) */
} nbmc_mesh_check_result;

/* Fills *result with zeros and struct_size. */
NBMC_API void nbmc_mesh_check_result_init(nbmc_mesh_check_result* result);

/* Checks mesh (a device mesh is copied to the host first) and fills *result
 * (initialise it with nbmc_mesh_check_result_init). Serial, on the host, a
 * few hundred milliseconds per million triangles; the mesh is only read, so
 * several threads may check one mesh at once. Returns NBMC_OK, or
 * NBMC_ERROR_INVALID_ARGUMENT for a NULL pointer or a struct_size below
 * sizeof(nbmc_mesh_check_result), NBMC_ERROR_OUT_OF_MEMORY. */
NBMC_API int32_t nbmc_mesh_check(const nbmc_mesh* mesh, nbmc_mesh_check_result* result);

/* ------------------------------------------------------------------------
 * Subdomains: one frame reconstructed in pieces (docs/scale-out.md).
 *
 * The frame's cells are split into nx * ny * nz boxes; each is reconstructed
 * with its particles and a ghost layer wide enough that every vertex it
 * computes sees what it would see in the whole frame, one box after another
 * on the context's backend (so at most one box's working memory is held on
 * the GPU), and the pieces are stitched. The mesh is the same as without
 * subdomains, bit for bit (positions, normals, triangle order). Particles in
 * device memory are copied to the host first; a device mesh
 * (NBMC_MEMORY_DEVICE) is copied back to the device after stitching. Only
 * the narrow-band field can be split (NBMC_FIELD_DENSE/SCATTER give
 * NBMC_ERROR_INVALID_PARAMETER).
 * ---------------------------------------------------------------------- */
#define NBMC_SUBDOMAINS_AUTO (-1)

/* nx, ny, nz >= 1 (1, 1, 1: no split, the default), or nx ==
 * NBMC_SUBDOMAINS_AUTO (ny, nz ignored): split only when the estimated memory
 * of the frame exceeds 80% of the memory budget (nbmc_context_set_memory_budget;
 * on a CUDA context without one, 80% of the GPU's free memory), into as many
 * subdomains as the estimate asks, and further if one still exceeds the
 * budget; also when a run fails with OUT_OF_MEMORY, MEMORY_BUDGET or, for a
 * GPU band over its size limit, DOMAIN_TOO_LARGE (then into 2, 4, ...
 * subdomains, with or without a budget). Applies to the following
 * reconstructions. Returns NBMC_OK or
 * NBMC_ERROR_INVALID_ARGUMENT. */
NBMC_API int32_t nbmc_context_set_subdomains(nbmc_context* ctx, int32_t nx, int32_t ny, int32_t nz);

typedef struct nbmc_subdomain_stats {
  uint32_t struct_size;      /* sizeof(nbmc_subdomain_stats) */
  int32_t parts[3];          /* subdomains per axis; 1, 1, 1 when the frame was not split */
  uint64_t count;            /* parts[0] * parts[1] * parts[2]; 0 when not split */
  uint32_t automatic;        /* 1 if NBMC_SUBDOMAINS_AUTO chose the split */
  uint32_t reserved;
  double ghost_width;        /* ghost layer beyond a subdomain's cells (absolute, largest axis) */
  uint64_t ghost_particles;  /* particles read as ghosts, summed over the subdomains */
  uint64_t reruns;           /* subdomain runs repeated because a neighbour's band grew into them */
  uint64_t exchanged_cells;  /* band cells passed between subdomains */
  uint64_t shared_vertices;  /* vertices on shared faces, merged by the stitching */
  uint64_t budget_bytes;     /* the budget NBMC_SUBDOMAINS_AUTO sized for (0: explicit split) */
  double stitch_seconds;
} nbmc_subdomain_stats;

typedef struct nbmc_subdomain_entry {
  uint32_t struct_size;      /* sizeof(nbmc_subdomain_entry) */
  int32_t coord[3];          /* position in the subdomain grid */
  int64_t cell_lo[3];        /* owned marching-cubes cells [cell_lo, cell_hi) */
  int64_t cell_hi[3];
  uint64_t particles;        /* particles in its cells */
  uint64_t ghost_particles;  /* particles it read from around its cells */
  uint64_t vertex_count;     /* of its piece (shared vertices counted in each piece) */
  uint64_t triangle_count;
  uint32_t runs;             /* 1, or more when it ran again */
  int32_t rank;              /* the MPI rank that ran it (0 without MPI) */
  double seconds;
} nbmc_subdomain_entry;

/* Fill *out with zeros and struct_size. */
NBMC_API void nbmc_subdomain_stats_init(nbmc_subdomain_stats* out);
NBMC_API void nbmc_subdomain_entry_init(nbmc_subdomain_entry* out);

/* How the last successful reconstruction was split. NBMC_ERROR_NO_PARTICLES
 * before any succeeded. */
NBMC_API int32_t nbmc_context_subdomain_stats(const nbmc_context* ctx, nbmc_subdomain_stats* out);
/* Subdomain i (0 <= i < count) of the last successful reconstruction;
 * NBMC_ERROR_INVALID_ARGUMENT when i is out of range. */
NBMC_API int32_t nbmc_context_subdomain_entry(const nbmc_context* ctx, uint64_t i, nbmc_subdomain_entry* out);

/* ------------------------------------------------------------------------
 * Pieces of a frame reconstructed over MPI ranks (include/nbmc_mpi.h,
 * NBMC_MPI_PIECES). Plain accessors: no MPI type is involved.
 * ---------------------------------------------------------------------- */
/* Per vertex of a piece: its id in the whole frame's mesh, the same on every
 * rank whose piece has the vertex (ids run from 0 to
 * nbmc_mesh_global_vertex_count() - 1). NULL for any other mesh. */
NBMC_API const uint64_t* nbmc_mesh_global_vertex_ids(const nbmc_mesh* mesh);
/* Vertices of the whole frame's mesh that the pieces make up; 0 for a mesh
 * that is not a piece. */
NBMC_API uint64_t nbmc_mesh_global_vertex_count(const nbmc_mesh* mesh);

/* ------------------------------------------------------------------------
 * Particle attributes: per-particle values (velocity, density, temperature,
 * foam, ...) interpolated onto the vertices of the mesh.
 *
 * An attribute belongs to the particles uploaded last: set the particles
 * first, then the attributes (one item per particle, the particles' count).
 * Every particle upload (nbmc_context_set_particles*, _load_particles),
 * successful or not, removes all attributes, so a solver sets them again
 * each frame and a stale array is never used. nbmc_context_reconstruct then
 * gives each vertex of the returned mesh, at its final position (after the
 * clean-up and smoothing), the kernel-weighted mean of the attribute over the
 * particles within the influence radius R,
 *   a(x) = sum_j k_j a_j / sum_j k_j,  k_j = max(0, (1 - |x - x_j|^2/R^2)^3),
 * the weights of the scalar field; a vertex with no particle closer than R
 * takes the value of its nearest particle (lowest index on ties). The sums
 * run in double precision in a fixed order on the context's backend (the GPU
 * for a CUDA context): the values are the same for any thread count,
 * subdomain split and MPI rank count, and on every backend for the same
 * vertices (a split frame is interpolated on the stitched mesh from all
 * particles). On contexts bound to several processes (nbmc_mpi) each rank
 * sets the attributes of its own particles; every rank with particles must
 * set the same names and components (else nbmc_mpi_reconstruct fails with
 * NBMC_ERROR_INVALID_ARGUMENT on every rank), and the values come on the
 * root's gathered mesh or on each rank's piece.
 * ---------------------------------------------------------------------- */

/* Sets (copies) the attribute called name: components (1, a scalar, or 3, a
 * vector) values per particle, particle i's at byte offset i * byte_stride
 * from data (byte_stride 0: tightly packed, components * sizeof value), for
 * the count of particles uploaded last. name: 1 to 255 bytes without
 * control characters, matched exactly (writers replace what a format cannot
 * hold, e.g. spaces, by '_'); setting a name again replaces that attribute
 * (in its place in the order). data == NULL removes
 * the attribute called name (NBMC_OK also when there is none).
 * Errors: NBMC_ERROR_NO_PARTICLES before any particles are uploaded;
 * NBMC_ERROR_INVALID_ARGUMENT for a NULL ctx or name, a bad name, components
 * other than 1 or 3, a byte_stride smaller than one item, an MPI-bound
 * context; NBMC_ERROR_INVALID_PARTICLES when a value is NaN, infinite or
 * beyond 1e38 in magnitude (the message names the first such particle).
 * On failure the context keeps no attribute of that name. Same threading
 * rules as every call on ctx. */
NBMC_API int32_t nbmc_context_set_attribute_f32(nbmc_context* ctx, const char* name, const float* data,
                                                uint32_t components, uint64_t byte_stride);
NBMC_API int32_t nbmc_context_set_attribute_f64(nbmc_context* ctx, const char* name, const double* data,
                                                uint32_t components, uint64_t byte_stride);
/* The same from CUDA device memory of the context's GPU (CUDA backend only,
 * else NBMC_ERROR_BACKEND_UNAVAILABLE); data and byte_stride must be aligned
 * to the value size. The values are copied to the host (the interpolation
 * runs there) before the call returns. */
NBMC_API int32_t nbmc_context_set_attribute_device_f32(nbmc_context* ctx, const char* name, const float* data,
                                                       uint32_t components, uint64_t byte_stride);
NBMC_API int32_t nbmc_context_set_attribute_device_f64(nbmc_context* ctx, const char* name, const double* data,
                                                       uint32_t components, uint64_t byte_stride);

/* Stage of nbmc_stats.stage_seconds: the interpolation of the attributes. */
#define NBMC_STAGE_ATTRIBUTES 8

/* Attributes of a mesh, in the order they were first set on the context; 0
 * for NULL or a mesh reconstructed without attributes. */
NBMC_API uint32_t nbmc_mesh_attribute_count(const nbmc_mesh* mesh);
/* Name of attribute i (0 <= i < count), valid until nbmc_mesh_destroy; NULL
 * when i is out of range. */
NBMC_API const char* nbmc_mesh_attribute_name(const nbmc_mesh* mesh, uint32_t i);
/* The values of the attribute called name (exact match): components (1 or
 * 3, stored in *components when it is not NULL) floats per vertex, vertex
 * after vertex, in HOST memory for every mesh (also one whose positions are
 * on the device), valid until nbmc_mesh_destroy. NULL when the mesh has no
 * such attribute (or mesh/name is NULL): *components is then 0 and
 * nbmc_last_error() says why; NULL also for a mesh without vertices, with
 * *components set and nbmc_last_error() empty. nbmc_mesh_write writes the
 * attributes into the formats that carry them (PLY, VTK, VTU, VTP, glTF,
 * HDF5; OBJ drops them). Read-only: may be called concurrently on one mesh
 * (the message is thread-local). */
NBMC_API const float* nbmc_mesh_attribute(const nbmc_mesh* mesh, const char* name, uint32_t* components);

/* ------------------------------------------------------------------------
 * Isolated particles as spheres (nbmc_params.isolated = NBMC_ISOLATED_SPHERE):
 * the particles of the clusters of fewer than min_cluster particles make no
 * surface, and the mesh returns them as spheres, for renderers that draw
 * spheres (splashes, spray): one per particle, in the particles' order, of
 * radius iso_radius (absolute; NBMC_METHOD_SPH and NBMC_METHOD_YT10: half
 * the spacing), the size of the surface one particle alone makes.
 * nbmc_stats counts them
 * (dropped_particle_count, dropped_cluster_count).
 * ---------------------------------------------------------------------- */
/* Spheres of the mesh; 0 for NULL or a mesh made without NBMC_ISOLATED_SPHERE. */
NBMC_API uint64_t nbmc_mesh_sphere_count(const nbmc_mesh* mesh);
/* 4 * sphere_count floats, x, y, z, radius per sphere, in HOST memory for
 * every mesh, valid until nbmc_mesh_destroy; NULL when there are none.
 * Read-only: may be called concurrently on one mesh. */
NBMC_API const float* nbmc_mesh_spheres(const nbmc_mesh* mesh);

/* ------------------------------------------------------------------------
 * Per-particle radii: frames whose particles have different sizes
 * (variable-resolution SPH: SWIFT/GADGET SmoothingLengths, SPH-EXA h,
 * adaptive SPlisHSPlasH).
 *
 * A particle's radius is its r: the length nbmc_params.spacing gives a
 * uniform frame (the rest distance, the r of eq. (1) of the paper; twice the
 * "particle radius" of SPlisHSPlasH and splashsurf). The parameters then
 * describe a particle of radius nbmc_params.spacing, and particle i of radius
 * r_i takes influence_radius, band_width, surface_radius and iso_radius times
 * r_i / spacing (in NBMC_UNIT_SPACING: multiples of its own radius):
 *  - the field: particle i's kernel support is its own R_i; rbar of eq. (1)
 *    is the kernel-weighted mean of the contributing particles' iso radii
 *    (SSP07; ZB05 likewise); the SPH density uses R_i as particle i's
 *    smoothing length (with particle volumes ~ r_i^3);
 *  - the surface-particle test: within particle i's own surface radius, with
 *    each neighbour's own volume r_j^3 in the colour field;
 *  - the narrow band: particle i's box is its own band_width wide;
 *  - attribute interpolation: particle j's kernel has support R_j.
 * The cell size stays the frame's: one grid (a cell of at most half the
 * smallest radius resolves the finest particles). What is global takes the
 * largest particle's lengths (r_max = the largest radius): the neighbour
 * search and its cells, the bounding-box margin, the ghost layers of
 * subdomains and MPI ranks, and the isolated-particle filter's linking
 * distance. A frame whose radii span a wide range therefore searches its
 * small particles with the large ones' radius (more particles per search);
 * at most a factor 1e6 between the smallest and the largest radius.
 * Radii that are all equal (to r) make a uniform frame of spacing r: with
 * r == nbmc_params.spacing, the mesh is the one without radii, bit for bit.
 * Subdomain splits and MPI ranks give the same mesh as the whole frame.
 * ---------------------------------------------------------------------- */

/* Sets (copies) the radii of the particles uploaded last: count values, which
 * must be the particle count, particle i's at byte offset i * byte_stride from
 * radii (byte_stride 0: tightly packed). Absolute lengths, in the unit of the
 * positions. The radii apply to every following reconstruction on ctx until
 * they are removed: radii == NULL removes them (count and byte_stride are
 * then ignored; NBMC_OK also when there are none), and so does every
 * particle upload (nbmc_context_set_particles*, _load_particles), successful
 * or not, as for attributes: a solver sets them again with each frame.
 * Errors (the context then keeps no radii): NBMC_ERROR_NO_PARTICLES before
 * any particles are uploaded; NBMC_ERROR_INVALID_ARGUMENT for a NULL ctx, a
 * count other than the particle count, a byte_stride smaller than one value;
 * NBMC_ERROR_INVALID_PARAMETER for a radius that is NaN, infinite, zero,
 * negative or above 1e15 (the message names the first such particle and its
 * value), or radii spanning more than a factor 1e6. Values are checked on the
 * context's threads, like positions.
 * Contexts bound to several processes (nbmc_mpi): every rank sets the radii of
 * its own particles (a rank without particles passes count 0, or nothing);
 * nbmc_mpi_reconstruct fails with NBMC_ERROR_INVALID_ARGUMENT on every rank
 * when some ranks with particles have radii and others have none, and with
 * NBMC_ERROR_INVALID_PARAMETER when the ranks' radii together span more than
 * a factor 1e6. Same threading rules as every call on ctx. */
NBMC_API int32_t nbmc_context_set_radii_f32(nbmc_context* ctx, const float* radii, uint64_t count,
                                            uint64_t byte_stride);
NBMC_API int32_t nbmc_context_set_radii_f64(nbmc_context* ctx, const double* radii, uint64_t count,
                                            uint64_t byte_stride);
/* The same from CUDA device memory of the context's GPU (CUDA backend only,
 * else NBMC_ERROR_BACKEND_UNAVAILABLE); radii and byte_stride must be aligned
 * to the value size (else NBMC_ERROR_INVALID_ARGUMENT, as for a host
 * pointer). The values are copied to the host and validated there before the
 * call returns. */
NBMC_API int32_t nbmc_context_set_radii_device_f32(nbmc_context* ctx, const float* radii, uint64_t count,
                                                   uint64_t byte_stride);
NBMC_API int32_t nbmc_context_set_radii_device_f64(nbmc_context* ctx, const double* radii, uint64_t count,
                                                   uint64_t byte_stride);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* NBMC_H */
