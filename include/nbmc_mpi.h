/* SPDX-License-Identifier: MIT
 *
 * nbmc over MPI: one frame reconstructed by all ranks of a communicator
 * (docs/scale-out.md). A separate header and library (libnbmc_mpi, over
 * libnbmc): include/nbmc.h and libnbmc stay MPI-free. Link with
 * nbmc::nbmc_mpi (CMake; it brings nbmc::nbmc and MPI::MPI_C).
 *
 * Typical use inside a domain-decomposed solver (every call on every rank):
 *
 *   nbmc_context* ctx;  nbmc_context_create(&desc, &ctx);
 *   nbmc_mpi_context_set_comm(ctx, MPI_COMM_WORLD);   // collective
 *   nbmc_context_set_particles_f64(ctx, my_xyz, my_count, 0);  // 0 is allowed
 *   nbmc_mpi_reconstruct(ctx, &params, NBMC_MPI_PIECES, 0, &mesh);
 *   // mesh: this rank's piece of one watertight mesh, with
 *   // nbmc_mesh_global_vertex_ids(mesh) consistent across the ranks
 *
 * Each particle must be passed by exactly one rank (any decomposition: the
 * ranks' regions may be any shape and may interleave). nbmc picks its own
 * subdomains (nbmc_context_set_subdomains sets their number; by default four
 * per rank, or more with NBMC_SUBDOMAINS_AUTO and a memory budget),
 * moves particles and ghost particles to the ranks that run them, and
 * returns the same mesh as one process would make of all the particles, bit
 * for bit (gathered), or the pieces of it (pieces: before clean-up and
 * smoothing, which need the whole mesh).
 *
 * Errors: a failure on any rank (bad particles passed to the upload, a
 * memory budget, out of memory, a bad parameter) ends nbmc_mpi_reconstruct on
 * every rank with the same status and a message that names the failing rank;
 * no rank is left waiting. A failed communication aborts like MPI itself.
 */
#ifndef NBMC_MPI_H
#define NBMC_MPI_H

#include <mpi.h>

#include "nbmc.h"

#ifdef __cplusplus
extern "C" {
#endif

#define NBMC_MPI_GATHER 0 /* the whole mesh on the root rank; an empty mesh on the others */
#define NBMC_MPI_PIECES 1 /* every rank its piece, with global vertex ids */

/* Binds ctx to a duplicate of comm (collective over comm). From then on the
 * context's reconstructions are collective with nbmc_mpi_reconstruct, and a
 * rank may set zero particles (count 0, xyz NULL). MPI must be initialised.
 * Returns NBMC_OK, NBMC_ERROR_INVALID_ARGUMENT (ctx NULL, MPI not
 * initialised, MPI_COMM_NULL). */
NBMC_API int32_t nbmc_mpi_context_set_comm(nbmc_context* ctx, MPI_Comm comm);
/* The same for a Fortran handle (an mpi_f08 type(MPI_Comm)'s MPI_VAL, or an
 * mpif.h/mpi-module integer): converted with MPI_Comm_f2c. */
NBMC_API int32_t nbmc_mpi_context_set_comm_f(nbmc_context* ctx, int32_t fortran_comm);

/* Collective over the context's communicator: every rank calls it with the
 * same params, output and root. output NBMC_MPI_GATHER: the root gets the
 * frame's mesh in *mesh (post-processed as nbmc_context_reconstruct would),
 * every other rank an empty mesh; NBMC_MPI_PIECES: each rank its piece.
 * nbmc_context_stats() then holds the frame's counts (per-stage times: the
 * slowest rank's), nbmc_context_subdomain_stats/_entry the subdomains (all
 * of them on the root, with the rank that ran each). Statuses as
 * nbmc_context_reconstruct; NBMC_ERROR_INVALID_ARGUMENT if ctx is not bound
 * to a communicator. */
NBMC_API int32_t nbmc_mpi_reconstruct(nbmc_context* ctx, const nbmc_params* params, int32_t output, int32_t root,
                                      nbmc_mesh** mesh);

/* The rank's rank and size in the context's communicator (-1 when unbound). */
NBMC_API int32_t nbmc_mpi_context_rank(const nbmc_context* ctx);
NBMC_API int32_t nbmc_mpi_context_size(const nbmc_context* ctx);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* NBMC_MPI_H */
