// SPDX-License-Identifier: MIT
// What the GPU checks share (tests/gpu, built with the CUDA backend): the
// ok/FAIL lines and their count, a context owner, an upload of a host vector
// to device memory, a mesh copied to the host (from host or device memory)
// and bit-for-bit comparison of two meshes.
#pragma once

#include "nbmc_test.hpp"

#include <cuda_runtime.h>

#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace gpu_test {

// Failed checks so far (main returns non-zero when there are any).
inline int failures = 0;

inline void check(bool ok, const std::string& what) {
  std::printf("%s %s\n", ok ? "ok  " : "FAIL", what.c_str());
  if (!ok) ++failures;
}

// A context on one backend (c is NULL when it could not be created).
struct Ctx {
  nbmc_context* c = nullptr;
  explicit Ctx(int32_t backend) {
    nbmc_context_desc d;
    nbmc_context_desc_init(&d);
    d.backend = backend;
    if (nbmc_context_create(&d, &c) != NBMC_OK) c = nullptr;
  }
  ~Ctx() { nbmc_context_destroy(c); }
  Ctx(const Ctx&) = delete;
  Ctx& operator=(const Ctx&) = delete;
  std::string error() const { return nbmc_context_last_error(c); }
};

// A device copy of v (cudaFree it); NULL when the allocation fails.
template <class T>
T* to_device(const std::vector<T>& v) {
  T* d = nullptr;
  if (cudaMalloc(&d, v.size() * sizeof(T)) != cudaSuccess) return nullptr;
  cudaMemcpy(d, v.data(), v.size() * sizeof(T), cudaMemcpyHostToDevice);
  return d;
}

// The mesh (host or device memory) in host vectors; empty when the copy
// fails. Normals only when the mesh has them.
inline nbmc_test::Mesh host_copy(const nbmc_mesh* m) {
  nbmc_test::Mesh h;
  if (!m) return h;
  h.positions.resize(3 * nbmc_mesh_vertex_count(m));
  h.normals.resize(nbmc_mesh_normals(m) ? h.positions.size() : 0);
  h.triangles.resize(3 * nbmc_mesh_triangle_count(m));
  if (nbmc_mesh_copy_to_host(m, h.positions.data(), h.normals.empty() ? nullptr : h.normals.data(),
                             h.triangles.data()) != NBMC_OK)
    h = nbmc_test::Mesh();
  return h;
}

// host_copy, then destroys the mesh.
inline nbmc_test::Mesh take_host(nbmc_mesh* m) {
  nbmc_test::Mesh h = host_copy(m);
  nbmc_mesh_destroy(m);
  return h;
}

// The same triangles, positions and normals, bit for bit (and not empty: an
// empty mesh is a failed run here).
inline bool same(const nbmc_test::Mesh& a, const nbmc_test::Mesh& b) {
  return !a.triangles.empty() && a.triangles == b.triangles && a.positions.size() == b.positions.size() &&
         std::memcmp(a.positions.data(), b.positions.data(), a.positions.size() * sizeof(float)) == 0 &&
         a.normals.size() == b.normals.size() &&
         std::memcmp(a.normals.data(), b.normals.data(), a.normals.size() * sizeof(float)) == 0;
}

}  // namespace gpu_test
