// SPDX-License-Identifier: MIT
// libnbmc_mpi: include/nbmc_mpi.h over libnbmc. The collective operations
// libnbmc needs (src/collective.h) are written here with MPI on a duplicate
// of the caller's communicator (its errors returned, not fatal, so that a
// failure becomes a status). Large messages go point to point in chunks, so
// no count overflows MPI's int.
#include "nbmc_mpi.h"

#include "../collective.h"

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <new>
#include <vector>

namespace {

constexpr std::uint64_t kChunk = std::uint64_t(1) << 30;  // bytes per message
constexpr int kTagBase = 7100;

struct Bound {
  MPI_Comm comm = MPI_COMM_NULL;
  int rank = 0, size = 1;
};

void release_bound(void* p) {
  Bound* b = static_cast<Bound*>(p);
  int finalized = 0;
  MPI_Finalized(&finalized);
  if (!finalized && b->comm != MPI_COMM_NULL) MPI_Comm_free(&b->comm);
  delete b;
}

int32_t rc(int e) { return e == MPI_SUCCESS ? 0 : (e == 0 ? 1 : e); }

// Sends/receives n bytes in chunks (non-blocking, completed by the caller).
void post_send(MPI_Comm c, const char* p, std::uint64_t n, int dest, int tag, std::vector<MPI_Request>& req) {
  for (std::uint64_t at = 0; at < n; at += kChunk) {
    req.emplace_back();
    MPI_Isend(p + at, int(std::min(kChunk, n - at)), MPI_BYTE, dest, tag, c, &req.back());
  }
}
void post_recv(MPI_Comm c, char* p, std::uint64_t n, int src, int tag, std::vector<MPI_Request>& req) {
  for (std::uint64_t at = 0; at < n; at += kChunk) {
    req.emplace_back();
    MPI_Irecv(p + at, int(std::min(kChunk, n - at)), MPI_BYTE, src, tag, c, &req.back());
  }
}
int wait_all(std::vector<MPI_Request>& req) {
  if (req.empty()) return MPI_SUCCESS;
  return MPI_Waitall(int(req.size()), req.data(), MPI_STATUSES_IGNORE);
}

int32_t alltoallv(void* user, const void* send, const uint64_t* send_bytes, void** recv, uint64_t* recv_bytes) {
  const Bound& b = *static_cast<Bound*>(user);
  // Sizes first.
  int e = MPI_Alltoall(send_bytes, 1, MPI_UINT64_T, recv_bytes, 1, MPI_UINT64_T, b.comm);
  if (e != MPI_SUCCESS) return rc(e);
  std::uint64_t total = 0;
  for (int r = 0; r < b.size; ++r) total += recv_bytes[r];
  char* out = static_cast<char*>(std::malloc(total ? total : 1));
  if (!out) return 1;
  std::vector<MPI_Request> req;
  const char* s = static_cast<const char*>(send);
  std::uint64_t in_at = 0, out_at = 0;
  for (int r = 0; r < b.size; ++r) {
    post_recv(b.comm, out + in_at, recv_bytes[r], r, kTagBase, req);
    in_at += recv_bytes[r];
  }
  for (int r = 0; r < b.size; ++r) {
    post_send(b.comm, s + out_at, send_bytes[r], r, kTagBase, req);
    out_at += send_bytes[r];
  }
  e = wait_all(req);
  if (e != MPI_SUCCESS) {
    std::free(out);
    return rc(e);
  }
  *recv = out;
  return 0;
}

int32_t allreduce(void* user, void* values, int32_t n, int32_t op) {
  const Bound& b = *static_cast<Bound*>(user);
  MPI_Datatype t = op >= NBMC__MIN_F64 ? MPI_DOUBLE : MPI_UINT64_T;
  MPI_Op o = MPI_SUM;
  if (op == NBMC__MAX_U64 || op == NBMC__MAX_F64) o = MPI_MAX;
  if (op == NBMC__MIN_U64 || op == NBMC__MIN_F64) o = MPI_MIN;
  return rc(MPI_Allreduce(MPI_IN_PLACE, values, n, t, o, b.comm));
}

int32_t gatherv(void* user, const void* send, uint64_t bytes, int32_t root, void** recv, uint64_t* recv_bytes) {
  const Bound& b = *static_cast<Bound*>(user);
  int e = MPI_Gather(&bytes, 1, MPI_UINT64_T, recv_bytes, 1, MPI_UINT64_T, root, b.comm);
  if (e != MPI_SUCCESS) return rc(e);
  std::vector<MPI_Request> req;
  if (b.rank == root) {
    std::uint64_t total = 0;
    for (int r = 0; r < b.size; ++r) total += recv_bytes[r];
    char* out = static_cast<char*>(std::malloc(total ? total : 1));
    if (!out) return 1;
    std::uint64_t at = 0;
    for (int r = 0; r < b.size; ++r) {
      if (r == root) std::memcpy(out + at, send, bytes);
      else post_recv(b.comm, out + at, recv_bytes[r], r, kTagBase + 1, req);
      at += recv_bytes[r];
    }
    e = wait_all(req);
    if (e != MPI_SUCCESS) {
      std::free(out);
      return rc(e);
    }
    *recv = out;
    return 0;
  }
  post_send(b.comm, static_cast<const char*>(send), bytes, root, kTagBase + 1, req);
  *recv = nullptr;
  return rc(wait_all(req));
}

int32_t bcast(void* user, void** data, uint64_t* bytes, int32_t root) {
  const Bound& b = *static_cast<Bound*>(user);
  int e = MPI_Bcast(bytes, 1, MPI_UINT64_T, root, b.comm);
  if (e != MPI_SUCCESS) return rc(e);
  char* p = static_cast<char*>(*data);
  if (b.rank != root) {
    p = static_cast<char*>(std::malloc(*bytes ? *bytes : 1));
    if (!p) return 1;
    *data = p;
  }
  for (std::uint64_t at = 0; at < *bytes; at += kChunk) {
    e = MPI_Bcast(p + at, int(std::min(kChunk, *bytes - at)), MPI_BYTE, root, b.comm);
    if (e != MPI_SUCCESS) return rc(e);
  }
  return 0;
}

}  // namespace

extern "C" {

int32_t nbmc_mpi_context_set_comm(nbmc_context* ctx, MPI_Comm comm) {
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  int init = 0, finalized = 0;
  MPI_Initialized(&init);
  MPI_Finalized(&finalized);
  if (!init || finalized)
    return nbmc__context_fail(ctx, NBMC_ERROR_INVALID_ARGUMENT,
                              "nbmc_mpi_context_set_comm: MPI is not initialised (or already finalised)");
  if (comm == MPI_COMM_NULL)
    return nbmc__context_fail(ctx, NBMC_ERROR_INVALID_ARGUMENT, "nbmc_mpi_context_set_comm: comm is MPI_COMM_NULL");
  Bound* b = new (std::nothrow) Bound();
  if (!b) return nbmc__context_fail(ctx, NBMC_ERROR_OUT_OF_MEMORY, "nbmc_mpi_context_set_comm: out of memory");
  if (MPI_Comm_dup(comm, &b->comm) != MPI_SUCCESS) {
    delete b;
    return nbmc__context_fail(ctx, NBMC_ERROR_INTERNAL, "nbmc_mpi_context_set_comm: MPI_Comm_dup failed");
  }
  MPI_Comm_set_errhandler(b->comm, MPI_ERRORS_RETURN);
  MPI_Comm_rank(b->comm, &b->rank);
  MPI_Comm_size(b->comm, &b->size);
  nbmc__context_attach(ctx, b, &release_bound);
  return nbmc__context_bind_collective(ctx, 1);
}

int32_t nbmc_mpi_context_set_comm_f(nbmc_context* ctx, int32_t fortran_comm) {
  return nbmc_mpi_context_set_comm(ctx, MPI_Comm_f2c(MPI_Fint(fortran_comm)));
}

int32_t nbmc_mpi_context_rank(const nbmc_context* ctx) {
  const Bound* b = static_cast<const Bound*>(nbmc__context_attached(ctx));
  return b ? b->rank : -1;
}

int32_t nbmc_mpi_context_size(const nbmc_context* ctx) {
  const Bound* b = static_cast<const Bound*>(nbmc__context_attached(ctx));
  return b ? b->size : -1;
}

int32_t nbmc_mpi_reconstruct(nbmc_context* ctx, const nbmc_params* params, int32_t output, int32_t root,
                             nbmc_mesh** mesh) {
  if (mesh) *mesh = nullptr;
  if (!ctx) return NBMC_ERROR_INVALID_ARGUMENT;
  Bound* b = static_cast<Bound*>(nbmc__context_attached(ctx));
  if (!b)
    return nbmc__context_fail(ctx, NBMC_ERROR_INVALID_ARGUMENT,
                              "nbmc_mpi_reconstruct: the context has no communicator (nbmc_mpi_context_set_comm)");
  nbmc__collective c;
  c.user = b;
  c.rank = b->rank;
  c.size = b->size;
  c.alltoallv = &alltoallv;
  c.allreduce = &allreduce;
  c.gatherv = &gatherv;
  c.bcast = &bcast;
  return nbmc__reconstruct_collective(ctx, params, &c, output, root, mesh);
}

}  // extern "C"
