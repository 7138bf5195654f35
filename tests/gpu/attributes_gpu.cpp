// SPDX-License-Identifier: MIT
// Particle attributes on the CUDA backend (run on a GPU machine):
//  - attributes from device memory (float strided, double packed) equal the
//    same values uploaded from the host, bit for bit;
//  - device particles + device attributes + a device mesh give the same mesh
//    and attributes as host particles + host attributes + a host mesh, and
//    the attributes are host memory;
//  - the values are close to the OpenMP backend's (its vertices differ by a
//    few ulps) and each equals the kernel mean at its own vertex;
//  - errors: a host pointer, a misaligned stride, NaN on the device.
//   nbmc_cuda_attributes
#include "gpu_support.hpp"

#include <cuda_runtime.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

using namespace nbmc_test;
using namespace gpu_test;

namespace {
std::vector<float> attr(const nbmc_mesh* m, const char* name) {
  uint32_t c = 0;
  const float* a = nbmc_mesh_attribute(m, name, &c);
  if (!a) return {};
  return std::vector<float>(a, a + nbmc_mesh_vertex_count(m) * c);
}

std::vector<float> positions(const nbmc_mesh* m) {
  std::vector<float> p(3 * nbmc_mesh_vertex_count(m));
  nbmc_mesh_copy_to_host(m, p.data(), nullptr, nullptr);
  return p;
}

bool same(const std::vector<float>& a, const std::vector<float>& b) {
  return !a.empty() && a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

double kernel_mean(const Points& p, const std::vector<double>& v, const float* x, double R) {
  double s = 0, w = 0;
  for (std::size_t j = 0; j < p.size() / 3; ++j) {
    const double d0 = x[0] - p[3 * j], d1 = x[1] - p[3 * j + 1], d2 = x[2] - p[3 * j + 2];
    const double q = (d0 * d0 + d1 * d1 + d2 * d2) / (R * R);
    if (q >= 1) continue;
    const double k = (1 - q) * (1 - q) * (1 - q);
    s += k * v[j];
    w += k;
  }
  return w > 0 ? s / w : std::numeric_limits<double>::quiet_NaN();
}
}  // namespace

int main() {
  if (!nbmc_backend_available(NBMC_BACKEND_CUDA)) {
    std::printf("no CUDA backend/device: skipped\n");
    return 0;
  }
  const Points p = sphere(0.2, 0.1, -0.3, 4, 1);
  const std::size_t n = p.size() / 3;
  std::vector<double> height(n);
  struct Item {
    float pad;
    float vel[3];
  };
  std::vector<Item> items(n);
  std::vector<float> vel(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    height[i] = p[3 * i + 2];
    for (int k = 0; k < 3; ++k) {
      vel[3 * i + k] = float(p[3 * i + k] * (k + 1));
      items[i].vel[k] = vel[3 * i + k];
    }
  }
  const nbmc_params prm = params(1);

  Ctx gpu(NBMC_BACKEND_CUDA);
  check(gpu.c != nullptr, "CUDA context");
  if (!gpu.c) return 1;

  // Host particles, host attributes, host mesh: the reference.
  nbmc_context_set_particles_f64(gpu.c, p.data(), n, 0);
  check(nbmc_context_set_attribute_f64(gpu.c, "height", height.data(), 1, 0) == NBMC_OK, "host f64 attribute");
  check(nbmc_context_set_attribute_f32(gpu.c, "vel", vel.data(), 3, 0) == NBMC_OK, "host f32 attribute");
  nbmc_mesh* ref = nullptr;
  check(nbmc_context_reconstruct(gpu.c, &prm, &ref) == NBMC_OK, std::string("reconstruct: ") + nbmc_context_last_error(gpu.c));
  const std::vector<float> ref_h = attr(ref, "height"), ref_v = attr(ref, "vel"), ref_p = positions(ref);
  check(ref_h.size() == nbmc_mesh_vertex_count(ref) && ref_v.size() == 3 * ref_h.size() && !ref_h.empty(),
        "reference attributes (" + std::to_string(ref_h.size()) + " vertices)");
  double worst = 0;
  for (std::size_t i = 0; i < ref_h.size(); ++i)
    worst = std::fmax(worst, std::fabs(ref_h[i] - kernel_mean(p, height, &ref_p[3 * i], 4)));
  check(worst < 1e-5, "height = kernel mean at each GPU vertex (max diff " + std::to_string(worst) + ")");

  // Device attributes (strided float, packed double) on the host particles.
  Item* d_items = to_device(items);
  double* d_height = to_device(height);
  check(nbmc_context_set_attribute_device_f32(gpu.c, "vel", d_items[0].vel, 3, sizeof(Item)) == NBMC_OK,
        std::string("device f32 strided: ") + nbmc_context_last_error(gpu.c));
  check(nbmc_context_set_attribute_device_f64(gpu.c, "height", d_height, 1, 0) == NBMC_OK,
        std::string("device f64: ") + nbmc_context_last_error(gpu.c));
  nbmc_mesh* m = nullptr;
  nbmc_context_reconstruct(gpu.c, &prm, &m);
  check(same(attr(m, "height"), ref_h) && same(attr(m, "vel"), ref_v), "device attributes == host attributes");
  nbmc_mesh_destroy(m);

  // Device particles, device attributes, device mesh.
  double* d_p = to_device(p);
  check(nbmc_context_set_particles_device_f64(gpu.c, d_p, n, 0) == NBMC_OK, "device particles");
  check(nbmc_context_set_attribute_device_f64(gpu.c, "height", d_height, 1, 0) == NBMC_OK, "device height");
  check(nbmc_context_set_attribute_device_f32(gpu.c, "vel", d_items[0].vel, 3, sizeof(Item)) == NBMC_OK, "device vel");
  nbmc_context_set_mesh_memory(gpu.c, NBMC_MEMORY_DEVICE);
  m = nullptr;
  check(nbmc_context_reconstruct(gpu.c, &prm, &m) == NBMC_OK, std::string("device run: ") + nbmc_context_last_error(gpu.c));
  check(nbmc_mesh_memory(m) == NBMC_MEMORY_DEVICE, "device mesh");
  cudaPointerAttributes pa;
  const float* ha = nbmc_mesh_attribute(m, "height", nullptr);
  check(ha && cudaPointerGetAttributes(&pa, ha) == cudaSuccess && pa.type != cudaMemoryTypeDevice,
        "attributes of a device mesh are host memory");
  check(same(positions(m), ref_p), "device mesh == host mesh");
  check(same(attr(m, "height"), ref_h) && same(attr(m, "vel"), ref_v), "device everything == host everything");
  check(nbmc_mesh_write(m, "attributes_gpu.vtp", nullptr) == NBMC_OK, "device mesh with attributes written");
  std::remove("attributes_gpu.vtp");
  nbmc_mesh_destroy(m);
  nbmc_context_set_mesh_memory(gpu.c, NBMC_MEMORY_HOST);

  // Device particles split into subdomains on the GPU: the same again.
  {
    Ctx split(NBMC_BACKEND_CUDA);
    nbmc_context_set_subdomains(split.c, 2, 2, 1);
    nbmc_context_set_particles_device_f64(split.c, d_p, n, 0);
    nbmc_context_set_attribute_device_f64(split.c, "height", d_height, 1, 0);
    nbmc_mesh* s = nullptr;
    check(nbmc_context_reconstruct(split.c, &prm, &s) == NBMC_OK, "2x2x1 subdomains on the GPU");
    check(same(positions(s), ref_p) && same(attr(s, "height"), ref_h), "subdomains: same mesh and attributes");
    nbmc_mesh_destroy(s);
  }

  // The OpenMP backend: vertices within a few ulps, so values close.
  {
    Ctx cpu(NBMC_BACKEND_OPENMP);
    nbmc_context_set_particles_f64(cpu.c, p.data(), n, 0);
    nbmc_context_set_attribute_f64(cpu.c, "height", height.data(), 1, 0);
    nbmc_mesh* c = nullptr;
    nbmc_context_reconstruct(cpu.c, &prm, &c);
    const std::vector<float> h = attr(c, "height");
    double d = h.size() == ref_h.size() ? 0 : 1e9;
    for (std::size_t i = 0; i < h.size() && i < ref_h.size(); ++i) d = std::fmax(d, std::fabs(h[i] - ref_h[i]));
    check(d < 1e-4, "OpenMP vs CUDA attributes (max diff " + std::to_string(d) + ")");
    nbmc_mesh_destroy(c);
  }

  // Errors.
  nbmc_context_set_particles_f64(gpu.c, p.data(), n, 0);
  int32_t st = nbmc_context_set_attribute_device_f64(gpu.c, "h", height.data(), 1, 0);
  check(st == NBMC_ERROR_INVALID_ARGUMENT, std::string("host pointer refused: ") + nbmc_context_last_error(gpu.c));
  st = nbmc_context_set_attribute_device_f64(gpu.c, "h", d_height, 1, 12);
  check(st == NBMC_ERROR_INVALID_ARGUMENT, std::string("misaligned stride refused: ") + nbmc_context_last_error(gpu.c));
  std::vector<double> bad = height;
  bad[3] = std::nan("");
  double* d_bad = to_device(bad);
  st = nbmc_context_set_attribute_device_f64(gpu.c, "h", d_bad, 1, 0);
  check(st == NBMC_ERROR_INVALID_PARTICLES, std::string("NaN on the device: ") + nbmc_context_last_error(gpu.c));
  cudaFree(d_bad);
  cudaFree(d_p);
  cudaFree(d_height);
  cudaFree(d_items);
  nbmc_mesh_destroy(ref);
  std::printf("%d failure(s)\n", failures);
  return failures ? 1 : 0;
}
