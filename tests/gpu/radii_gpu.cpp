// SPDX-License-Identifier: MIT
// Per-particle radii on the CUDA backend (run on a GPU machine):
//  - a coarse box and a sphere sampled four times finer, with their radii
//    (and larger twins of some fine particles at their very positions):
//    OpenMP and CUDA give the same mesh bit for bit (SSP07, ZB05, SPH);
//  - radii from device memory (float strided, double packed) equal the same
//    radii from the host, bit for bit; device particles with host radii, and
//    a device mesh, too;
//  - a subdomain split on the GPU gives the GPU's whole-frame mesh;
//  - errors: a host pointer, a misaligned stride, a negative radius on the
//    device.
//   nbmc_cuda_radii
#include "gpu_support.hpp"

#include <cuda_runtime.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

using namespace nbmc_test;
using namespace gpu_test;

namespace {
Mesh run(int32_t backend, const Points& p, const std::vector<double>& radii, const nbmc_params& prm,
         const int split[3] = nullptr) {
  Ctx ctx(backend);
  if (!ctx.c) return {};
  nbmc_context_set_particles_f64(ctx.c, p.data(), p.size() / 3, 0);
  if (nbmc_context_set_radii_f64(ctx.c, radii.data(), radii.size(), 0) != NBMC_OK) {
    check(false, "set_radii: " + ctx.error());
    return {};
  }
  if (split) nbmc_context_set_subdomains(ctx.c, split[0], split[1], split[2]);
  nbmc_mesh* m = nullptr;
  if (nbmc_context_reconstruct(ctx.c, &prm, &m) != NBMC_OK) {
    check(false, "reconstruct: " + ctx.error());
    return {};
  }
  return take_host(m);
}
}  // namespace

int main() {
  if (!nbmc_backend_available(NBMC_BACKEND_CUDA)) {
    std::printf("no CUDA backend/device: skipped\n");
    return 0;
  }
  // The frame of tests/test_radii.cpp: spacing 0.1 box, spacing 0.025 sphere.
  const double rc = 0.1, rf = 0.025;
  const double lo[3] = {-1.2, -0.4, -0.4}, hi[3] = {-0.6, 0.4, 0.4};
  Points p = box(lo, hi, rc);
  const std::size_t coarse = p.size() / 3;
  p = concat(p, sphere(0.6, 0, 0, 0.4, rf));
  // Larger twins of every 7th fine particle: coincident particles of
  // different radii, which both backends order by radius (the device by a
  // radix pass, the host by order_by_radius).
  const std::size_t singles = p.size() / 3;
  for (std::size_t i = coarse; i < singles; i += 7) p.insert(p.end(), {p[3 * i], p[3 * i + 1], p[3 * i + 2]});
  const std::size_t n = p.size() / 3;
  std::vector<double> radii(n, rf);
  std::fill(radii.begin(), radii.begin() + std::ptrdiff_t(coarse), rc);
  std::fill(radii.begin() + std::ptrdiff_t(singles), radii.end(), 1.5 * rf);
  nbmc_params prm = params(rc);
  prm.cell_size = rf / rc;

  // OpenMP against CUDA, per method.
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05, NBMC_METHOD_SPH}) {
    nbmc_params q = prm;
    q.method = method;
    const Mesh cpu = run(NBMC_BACKEND_OPENMP, p, radii, q), gpu = run(NBMC_BACKEND_CUDA, p, radii, q);
    const std::string name = method == NBMC_METHOD_SSP07 ? "ssp07" : method == NBMC_METHOD_ZB05 ? "zb05" : "sph";
    Mesh gm;
    gm.positions = gpu.positions;
    gm.triangles = gpu.triangles;
    const MeshReport rep = check_mesh(gm);
    check(rep.closed && rep.oriented && rep.vertex_manifold && rep.components == 2,
          name + ": GPU mesh closed, two components (" + rep.summary() + ")");
    check(same(cpu, gpu), name + ": OpenMP and CUDA meshes bit for bit");
  }

  Ctx gpu(NBMC_BACKEND_CUDA);
  check(gpu.c != nullptr, "CUDA context");
  if (!gpu.c) return 1;
  auto reconstruct = [&]() {
    nbmc_mesh* m = nullptr;
    const int32_t st = nbmc_context_reconstruct(gpu.c, &prm, &m);
    if (st != NBMC_OK) check(false, "reconstruct: " + gpu.error());
    return take_host(m);
  };
  // Mesh particles, host radii: the reference.
  nbmc_context_set_particles_f64(gpu.c, p.data(), n, 0);
  check(nbmc_context_set_radii_f64(gpu.c, radii.data(), n, 0) == NBMC_OK, "host radii: " + gpu.error());
  const Mesh ref = reconstruct();
  check(!ref.triangles.empty(), "reference mesh (" + std::to_string(ref.triangles.size() / 3) + " triangles)");

  // Device radii: float, every other float (byte_stride 8); double, packed.
  std::vector<float> strided(2 * n, -1.f);
  for (std::size_t i = 0; i < n; ++i) strided[2 * i] = float(radii[i]);
  float* d_strided = to_device(strided);
  double* d_radii = to_device(radii);
  check(nbmc_context_set_radii_device_f64(gpu.c, d_radii, n, 0) == NBMC_OK, "device f64 radii: " + gpu.error());
  check(same(reconstruct(), ref), "device f64 radii == host radii");
  check(nbmc_context_set_radii_device_f32(gpu.c, d_strided, n, 2 * sizeof(float)) == NBMC_OK,
        "device f32 strided radii: " + gpu.error());
  {
    // The float radii from the host give the same mesh.
    std::vector<float> rf32(n);
    for (std::size_t i = 0; i < n; ++i) rf32[i] = float(radii[i]);
    const Mesh dev = reconstruct();
    check(nbmc_context_set_radii_f32(gpu.c, rf32.data(), n, 0) == NBMC_OK, "host f32 radii");
    check(same(dev, reconstruct()), "device f32 strided radii == host f32 radii");
  }

  // Device particles, host radii, a device mesh.
  double* d_p = to_device(p);
  check(nbmc_context_set_particles_device_f64(gpu.c, d_p, n, 0) == NBMC_OK, "device particles: " + gpu.error());
  check(nbmc_context_set_radii_f64(gpu.c, radii.data(), n, 0) == NBMC_OK, "radii after device particles");
  check(nbmc_context_set_mesh_memory(gpu.c, NBMC_MEMORY_DEVICE) == NBMC_OK, "device meshes");
  check(same(reconstruct(), ref), "device particles + host radii + device mesh == host run");
  nbmc_context_set_mesh_memory(gpu.c, NBMC_MEMORY_HOST);

  // A split on the GPU.
  {
    const int split[3] = {3, 2, 1};
    check(same(run(NBMC_BACKEND_CUDA, p, radii, prm, split), ref), "3x2x1 subdomains on the GPU == whole frame");
  }

  // Errors.
  nbmc_context_set_particles_f64(gpu.c, p.data(), n, 0);
  int32_t st = nbmc_context_set_radii_device_f64(gpu.c, radii.data(), n, 0);
  check(st == NBMC_ERROR_INVALID_ARGUMENT, "host pointer refused: " + gpu.error());
  st = nbmc_context_set_radii_device_f64(gpu.c, d_radii, n, 12);
  check(st == NBMC_ERROR_INVALID_ARGUMENT, "misaligned stride refused: " + gpu.error());
  std::vector<double> bad = radii;
  bad[3] = -1;
  double* d_bad = to_device(bad);
  st = nbmc_context_set_radii_device_f64(gpu.c, d_bad, n, 0);
  check(st == NBMC_ERROR_INVALID_PARAMETER && gpu.error().find("particle 3") != std::string::npos,
        "negative radius on the device: " + gpu.error());
  cudaFree(d_bad);
  cudaFree(d_p);
  cudaFree(d_radii);
  cudaFree(d_strided);
  std::printf("%s (%d failed)\n", failures ? "FAILED" : "PASSED", failures);
  return failures ? 1 : 0;
}
