/* SPDX-License-Identifier: MIT
 *
 * Internal: how libnbmc reconstructs one frame over several processes
 * without depending on MPI. libnbmc_mpi (src/mpi/) fills this table of
 * collective operations with MPI calls on the communicator of a context and
 * calls nbmc__reconstruct_collective(); libnbmc itself never sees an MPI
 * type, so include/nbmc.h and the plain library stay MPI-free. Not installed,
 * not part of the stable ABI: both libraries come from the same build.
 *
 * Every operation is collective over all `size` processes, returns 0 on
 * success and non-zero when the communication failed. Buffers handed out in
 * *recv are allocated with malloc() and released by the caller with free().
 */
#ifndef NBMC_COLLECTIVE_H
#define NBMC_COLLECTIVE_H

#include "nbmc.h"

#ifdef __cplusplus
extern "C" {
#endif

#define NBMC__SUM_U64 0
#define NBMC__MAX_U64 1
#define NBMC__MIN_U64 2
#define NBMC__MIN_F64 3
#define NBMC__MAX_F64 4

typedef struct nbmc__collective {
  void* user;
  int32_t rank, size;
  /* send_bytes[r] bytes of `send` (concatenated in rank order) go to rank r;
   * *recv receives what each rank r sent here, recv_bytes[r] bytes each. */
  int32_t (*alltoallv)(void* user, const void* send, const uint64_t* send_bytes, void** recv, uint64_t* recv_bytes);
  /* In-place reduction of n values (uint64_t or double, by op). */
  int32_t (*allreduce)(void* user, void* values, int32_t n, int32_t op);
  /* Every rank's `bytes` bytes to root; on root *recv holds them in rank
   * order, recv_bytes[r] from rank r (recv_bytes has size entries). */
  int32_t (*gatherv)(void* user, const void* send, uint64_t bytes, int32_t root, void** recv, uint64_t* recv_bytes);
  /* root's *bytes bytes at *data to every rank (others get a malloc'd copy). */
  int32_t (*bcast)(void* user, void** data, uint64_t* bytes, int32_t root);
} nbmc__collective;

#define NBMC__OUTPUT_GATHER 0 /* the whole mesh on root, an empty mesh elsewhere */
#define NBMC__OUTPUT_PIECES 1 /* each process its piece, with global vertex ids */

/* Collective over the processes of `c`: each passes the particles it owns
 * (set on ctx as usual; none is allowed once ctx is bound with
 * nbmc__context_bind_collective). */
NBMC_API int32_t nbmc__reconstruct_collective(nbmc_context* ctx, const nbmc_params* params,
                                              const nbmc__collective* c, int32_t output, int32_t root,
                                              nbmc_mesh** mesh);

/* Marks ctx as one of several processes' contexts (bound = 1) or not: a
 * process may then set zero particles, and a failed upload is remembered so
 * that the next collective reconstruction fails on every process. */
NBMC_API int32_t nbmc__context_bind_collective(nbmc_context* ctx, int32_t bound);

/* Attaches data to ctx (replacing and releasing what was attached):
 * release(data) runs when the context is destroyed. */
NBMC_API int32_t nbmc__context_attach(nbmc_context* ctx, void* data, void (*release)(void* data));
NBMC_API void* nbmc__context_attached(const nbmc_context* ctx);

/* Stores a message as the context's last error (for libnbmc_mpi's own
 * failures), returns status. */
NBMC_API int32_t nbmc__context_fail(nbmc_context* ctx, int32_t status, const char* message);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* NBMC_COLLECTIVE_H */
