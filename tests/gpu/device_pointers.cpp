// SPDX-License-Identifier: MIT
// Device pointers through the C API (CUDA backend, run on a GPU machine):
//  - particles uploaded from cudaMalloc'd float (strided) and double arrays
//    give the same mesh as the same values uploaded from the host;
//  - a mesh left in device memory (NBMC_MEMORY_DEVICE) has device pointers,
//    and copied to the host it equals the host mesh bit for bit; it can be
//    written to a file and outlives its context;
//  - errors: a host pointer, a misaligned stride, NaN on the device, the
//    device calls on a CPU backend;
//  - a sequence's meshes downloaded into page-locked blocks equal the first.
//   nbmc_cuda_device_pointers [DATA_DIR]
#include "gpu_support.hpp"

#include <cuda_runtime.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

using namespace nbmc_test;
using namespace gpu_test;

namespace {
bool is_device_pointer(const void* p) {
  cudaPointerAttributes a;
  return p && cudaPointerGetAttributes(&a, p) == cudaSuccess && a.type == cudaMemoryTypeDevice;
}

void run(const char* name, const Points& pts, double spacing, double cell) {
  nbmc_params prm = params(spacing);
  prm.cell_size = cell;
  const std::size_t n = pts.size() / 3;
  // Host reference on the CUDA backend, from floats (what the device upload gets).
  std::vector<float> f(pts.begin(), pts.end());
  Ctx host(NBMC_BACKEND_CUDA);
  nbmc_mesh* ref_mesh = nullptr;
  if (nbmc_context_set_particles_f32(host.c, f.data(), n, 0) != NBMC_OK ||
      nbmc_context_reconstruct(host.c, &prm, &ref_mesh) != NBMC_OK) {
    check(false, std::string(name) + ": host upload on CUDA: " + nbmc_context_last_error(host.c));
    return;
  }
  const Mesh ref = host_copy(ref_mesh);
  nbmc_mesh_destroy(ref_mesh);

  // Device float array with a stride of 5 floats (x, y, z, and two other fields).
  std::vector<float> strided(5 * n, -7.f);
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) strided[5 * i + a] = f[3 * i + a];
  float* d_f = nullptr;
  double* d_d = nullptr;
  cudaMalloc(&d_f, strided.size() * sizeof(float));
  cudaMalloc(&d_d, pts.size() * sizeof(double));
  cudaMemcpy(d_f, strided.data(), strided.size() * sizeof(float), cudaMemcpyHostToDevice);
  std::vector<double> dd(f.begin(), f.end());  // the same values as doubles
  cudaMemcpy(d_d, dd.data(), dd.size() * sizeof(double), cudaMemcpyHostToDevice);

  nbmc_mesh* mesh_f = nullptr;
  nbmc_mesh* mesh_d = nullptr;
  nbmc_mesh* mesh_dev = nullptr;
  {
    Ctx dev(NBMC_BACKEND_CUDA);
    int32_t s = nbmc_context_set_particles_device_f32(dev.c, d_f, n, 5 * sizeof(float));
    if (s == NBMC_OK) s = nbmc_context_reconstruct(dev.c, &prm, &mesh_f);
    const std::string err = s ? nbmc_context_last_error(dev.c) : "";
    check(s == NBMC_OK && nbmc_mesh_memory(mesh_f) == NBMC_MEMORY_HOST && same(host_copy(mesh_f), ref),
          std::string(name) + ": device f32 (stride 20 B) upload gives the host-upload mesh (" +
              std::to_string(ref.triangle_count()) + " triangles) " + err);
    s = nbmc_context_set_particles_device_f64(dev.c, d_d, n, 0);
    if (s == NBMC_OK) s = nbmc_context_reconstruct(dev.c, &prm, &mesh_d);
    check(s == NBMC_OK && same(host_copy(mesh_d), ref), std::string(name) + ": device f64 upload, same mesh");
    // The mesh left on the device.
    s = nbmc_context_set_mesh_memory(dev.c, NBMC_MEMORY_DEVICE);
    if (s == NBMC_OK) s = nbmc_context_reconstruct(dev.c, &prm, &mesh_dev);
    check(s == NBMC_OK && nbmc_mesh_memory(mesh_dev) == NBMC_MEMORY_DEVICE &&
              nbmc_mesh_vertex_count(mesh_dev) == ref.vertex_count() &&
              nbmc_mesh_triangle_count(mesh_dev) == ref.triangle_count() &&
              (ref.triangle_count() == 0 ||
               (is_device_pointer(nbmc_mesh_positions(mesh_dev)) && is_device_pointer(nbmc_mesh_triangles(mesh_dev)) &&
                is_device_pointer(nbmc_mesh_normals(mesh_dev)))),
          std::string(name) + ": NBMC_MEMORY_DEVICE mesh: device pointers, same counts");
    nbmc_stats st;
    nbmc_stats_init(&st);
    nbmc_context_stats(dev.c, &st);
    std::printf("     device-resident run: total %.4f s (upload %.4f, neighbourhood %.4f, output %.4f)\n",
                st.total_seconds, st.stage_seconds[NBMC_STAGE_UPLOAD], st.stage_seconds[NBMC_STAGE_NEIGHBOURHOOD],
                st.stage_seconds[NBMC_STAGE_OUTPUT]);
  }  // the context is gone; the device mesh stays valid
  check(same(host_copy(mesh_dev), ref), std::string(name) + ": device mesh copied to the host after its context "
                                                              "is destroyed equals the host mesh");
  const std::string path = std::string("/tmp/nbmc_device_mesh_") + std::to_string(n) + ".ply";
  check(nbmc_mesh_write(mesh_dev, path.c_str(), nullptr) == NBMC_OK && std::ifstream(path).good(),
        std::string(name) + ": a device mesh can be written (" + path + ")");
  std::remove(path.c_str());
  nbmc_mesh_destroy(mesh_f);
  nbmc_mesh_destroy(mesh_d);
  nbmc_mesh_destroy(mesh_dev);
  cudaFree(d_f);
  cudaFree(d_d);
}

void errors() {
  Ctx dev(NBMC_BACKEND_CUDA);
  auto said = [](const Ctx& c) { return std::string(nbmc_context_last_error(c.c)); };
  std::vector<float> host(30, 0.f);
  int32_t s = nbmc_context_set_particles_device_f32(dev.c, host.data(), 10, 0);
  check(s == NBMC_ERROR_INVALID_ARGUMENT, "host pointer to the device upload: " + said(dev));
  float* d = nullptr;
  cudaMalloc(&d, 64 * sizeof(float));
  std::vector<float> v(64, 0.5f);
  v[3 * 7 + 1] = std::nanf("");
  cudaMemcpy(d, v.data(), v.size() * sizeof(float), cudaMemcpyHostToDevice);
  s = nbmc_context_set_particles_device_f32(dev.c, d, 20, 0);
  check(s == NBMC_ERROR_INVALID_PARTICLES && said(dev).find("particle 7") != std::string::npos,
        "NaN on the device: " + said(dev));
  nbmc_params prm = params(0.1);
  nbmc_mesh* m = nullptr;
  s = nbmc_context_reconstruct(dev.c, &prm, &m);
  check(s == NBMC_ERROR_NO_PARTICLES && !m, "after a failed device upload the context holds no particles: " + said(dev));
  s = nbmc_context_set_particles_device_f32(dev.c, d, 10, 13);
  check(s == NBMC_ERROR_INVALID_ARGUMENT, "a stride that is not a multiple of 4: " + said(dev));
  Ctx cpu(NBMC_BACKEND_OPENMP);
  s = nbmc_context_set_particles_device_f32(cpu.c, d, 10, 0);
  check(s == NBMC_ERROR_BACKEND_UNAVAILABLE, "device upload on OpenMP: " + said(cpu));
  s = nbmc_context_set_mesh_memory(cpu.c, NBMC_MEMORY_DEVICE);
  check(s == NBMC_ERROR_BACKEND_UNAVAILABLE, "device mesh on OpenMP: " + said(cpu));
  cudaFree(d);
}
// nbmc_params.double_positions on CUDA: marching cubes writes doubles on the
// device (copied to a host mesh); far from the origin (1e7) the CUDA mesh
// is OpenMP's bit for bit (doubles, normals, triangles: as float meshes,
// cuda_equivalence.cpp), and so from device particles and subdomains;
// a device mesh with double positions is refused (float arrays only).
struct F64Mesh {
  std::vector<double> positions;
  std::vector<float> normals;
  std::vector<std::uint32_t> triangles;
  bool operator==(const F64Mesh& o) const {
    return positions.size() == o.positions.size() &&
           std::memcmp(positions.data(), o.positions.data(), positions.size() * sizeof(double)) == 0 &&
           normals == o.normals && triangles == o.triangles;
  }
};
void double_positions() {
  Points pts = sphere(0, 0, 0, 0.1, 0.01);
  for (double& x : pts) x += 1e7;
  const std::size_t n = pts.size() / 3;
  nbmc_params prm = params(0.01);
  prm.double_positions = 1;
  auto take = [](nbmc_mesh* m) {
    F64Mesh h;
    const std::size_t nv = nbmc_mesh_vertex_count(m), nt = nbmc_mesh_triangle_count(m);
    if (const double* p = nbmc_mesh_positions_f64(m)) h.positions.assign(p, p + 3 * nv);
    if (const float* q = nbmc_mesh_normals(m)) h.normals.assign(q, q + 3 * nv);
    if (const std::uint32_t* t = nbmc_mesh_triangles(m)) h.triangles.assign(t, t + 3 * nt);
    nbmc_mesh_destroy(m);
    return h;
  };
  Ctx cpu(NBMC_BACKEND_OPENMP), gpu(NBMC_BACKEND_CUDA);
  nbmc_mesh* a = nullptr;
  nbmc_mesh* b = nullptr;
  int32_t s = nbmc_context_set_particles_f64(cpu.c, pts.data(), n, 0);
  if (s == NBMC_OK) s = nbmc_context_reconstruct(cpu.c, &prm, &a);
  int32_t t = nbmc_context_set_particles_f64(gpu.c, pts.data(), n, 0);
  if (t == NBMC_OK) t = nbmc_context_reconstruct(gpu.c, &prm, &b);
  check(s == NBMC_OK && t == NBMC_OK, std::string("double_positions on OpenMP and CUDA: ") +
                                          nbmc_context_last_error(cpu.c) + nbmc_context_last_error(gpu.c));
  if (s != NBMC_OK || t != NBMC_OK) return;
  const F64Mesh ref = take(a), cuda = take(b);
  // The same field sums in the same order with the same IEEE operations on
  // both backends, and pass C's doubles from the same float t: bit for bit.
  double worst = ref.positions.size() == cuda.positions.size() ? 0 : 1e300;
  for (std::size_t i = 0; i < ref.positions.size() && i < cuda.positions.size(); ++i)
    worst = std::fmax(worst, std::fabs(ref.positions[i] - cuda.positions[i]));
  check(!ref.positions.empty() && cuda == ref,
        "double_positions at 1e7: the CUDA mesh equals OpenMP's bit for bit (" +
            std::to_string(ref.positions.size() / 3) + " vertices, triangles " +
            (cuda.triangles == ref.triangles ? "equal" : "differ") + ", normals " +
            (cuda.normals == ref.normals ? "equal" : "differ") + ", max position diff " +
            std::to_string(worst / 0.01) + " cell)");
  double* d = nullptr;
  cudaMalloc(&d, pts.size() * sizeof(double));
  cudaMemcpy(d, pts.data(), pts.size() * sizeof(double), cudaMemcpyHostToDevice);
  nbmc_mesh* c = nullptr;
  t = nbmc_context_set_particles_device_f64(gpu.c, d, n, 0);
  if (t == NBMC_OK) t = nbmc_context_reconstruct(gpu.c, &prm, &c);
  check(t == NBMC_OK && take(c) == cuda, "double_positions from device particles: the host particles' doubles");
  // Subdomains on CUDA stitch the doubles too.
  nbmc_context_set_subdomains(gpu.c, 2, 1, 1);
  nbmc_mesh* e = nullptr;
  t = nbmc_context_reconstruct(gpu.c, &prm, &e);
  check(t == NBMC_OK && take(e) == cuda, "double_positions with 2x1x1 subdomains on CUDA: the whole frame's doubles");
  nbmc_context_set_subdomains(gpu.c, 1, 1, 1);
  nbmc_mesh* f = nullptr;
  t = nbmc_context_set_mesh_memory(gpu.c, NBMC_MEMORY_DEVICE);
  if (t == NBMC_OK) t = nbmc_context_reconstruct(gpu.c, &prm, &f);
  check(t == NBMC_ERROR_INVALID_PARAMETER && !f,
        std::string("double_positions with NBMC_MEMORY_DEVICE is refused: ") + nbmc_context_last_error(gpu.c));
  cudaFree(d);
}

// Decimation, feature-weighted smoothing and isolated spheres (issue #11) on
// CUDA: the post-processing runs on the host, so a mesh left in device memory
// (copied to the host for it and back) and one from device particles equal
// the CUDA host mesh bit for bit, with the same spheres; against OpenMP (whose
// SSP07 field may differ from CUDA's by ulps, see cuda_equivalence.cpp) the
// mesh is closed, manifold and oriented with about the same triangle count.
void mesh_ops() {
  Points pts = sphere(0, 0, 0, 1.0, 0.1);
  pts.insert(pts.end(), {2.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 2.06, 0.0});  // 2 splashes, 3 particles
  for (int i = 11; i <= 18; ++i) pts.insert(pts.end(), {0.0, 0.0, 0.1 * i});  // a filament
  const std::size_t n = pts.size() / 3;
  nbmc_params prm = params(0.1);
  prm.smooth_iterations = 5;
  prm.smooth_weighting = NBMC_SMOOTH_FEATURE;
  prm.decimate_fraction = 0.25;
  prm.isolated = NBMC_ISOLATED_SPHERE;
  prm.min_cluster = 5;
  auto spheres = [](const nbmc_mesh* m) {
    const float* s = nbmc_mesh_spheres(m);
    return s ? std::vector<float>(s, s + 4 * nbmc_mesh_sphere_count(m)) : std::vector<float>();
  };
  Ctx cpu(NBMC_BACKEND_OPENMP), gpu(NBMC_BACKEND_CUDA);
  nbmc_mesh *a = nullptr, *b = nullptr, *c = nullptr, *d = nullptr;
  int32_t s = nbmc_context_set_particles_f64(cpu.c, pts.data(), n, 0);
  if (s == NBMC_OK) s = nbmc_context_reconstruct(cpu.c, &prm, &a);
  int32_t t = nbmc_context_set_particles_f64(gpu.c, pts.data(), n, 0);
  if (t == NBMC_OK) t = nbmc_context_reconstruct(gpu.c, &prm, &b);
  check(s == NBMC_OK && t == NBMC_OK, std::string("mesh ops on OpenMP and CUDA: ") + nbmc_context_last_error(cpu.c) +
                                          nbmc_context_last_error(gpu.c));
  if (s != NBMC_OK || t != NBMC_OK) return;
  nbmc_stats st;
  nbmc_stats_init(&st);
  nbmc_context_stats(gpu.c, &st);
  const Mesh ref = host_copy(b);
  nbmc_mesh_check_result r;
  nbmc_mesh_check_result_init(&r);
  check(nbmc_mesh_check(b, &r) == NBMC_OK && r.closed && r.manifold && r.oriented &&
            st.triangle_count * 4 <= st.pre_decimation_triangle_count + 3 && st.triangle_count > 0,
        "mesh ops on CUDA: closed, manifold, oriented, decimated to a quarter (" +
            std::to_string(st.pre_decimation_triangle_count) + " -> " + std::to_string(st.triangle_count) + ")");
  check(spheres(b) == spheres(a) && spheres(b).size() == 12, "mesh ops: CUDA's spheres are OpenMP's (3 particles)");
  const double ta = double(nbmc_mesh_triangle_count(a)), tb = double(nbmc_mesh_triangle_count(b));
  check(std::fabs(ta - tb) <= 0.01 * ta + 2, "mesh ops: OpenMP and CUDA triangle counts within 1% (" +
                                                 std::to_string(ta) + ", " + std::to_string(tb) + ")");
  double* dd = nullptr;
  cudaMalloc(&dd, pts.size() * sizeof(double));
  cudaMemcpy(dd, pts.data(), pts.size() * sizeof(double), cudaMemcpyHostToDevice);
  t = nbmc_context_set_particles_device_f64(gpu.c, dd, n, 0);
  if (t == NBMC_OK) t = nbmc_context_reconstruct(gpu.c, &prm, &c);
  check(t == NBMC_OK && same(host_copy(c), ref) && spheres(c) == spheres(b),
        std::string("mesh ops from device particles: the same mesh and spheres ") + nbmc_context_last_error(gpu.c));
  t = nbmc_context_set_mesh_memory(gpu.c, NBMC_MEMORY_DEVICE);
  if (t == NBMC_OK) t = nbmc_context_reconstruct(gpu.c, &prm, &d);
  check(t == NBMC_OK && nbmc_mesh_memory(d) == NBMC_MEMORY_DEVICE && same(host_copy(d), ref) &&
            spheres(d) == spheres(b),
        std::string("mesh ops with NBMC_MEMORY_DEVICE: the same mesh (decimated on the host, copied back) and "
                    "spheres in host memory ") + nbmc_context_last_error(gpu.c));
  nbmc_context_set_mesh_memory(gpu.c, NBMC_MEMORY_HOST);
  for (nbmc_mesh* m : {a, b, c, d}) nbmc_mesh_destroy(m);
  cudaFree(dd);
}

// Host uploads on a CUDA context reuse one page-locked buffer while the size
// stays within a factor 2: a sequence of uploads on one context gives the
// meshes fresh contexts give.
void reuse() {
  const nbmc_params prm = params(0.1);
  const Points sets[] = {sphere(0, 0, 0, 1.0, 0.1), sphere(0.05, 0, 0, 1.0, 0.1), sphere(0, 0, 0, 0.5, 0.1),
                         sphere(0, 0.1, 0, 1.0, 0.1)};
  Ctx seq(NBMC_BACKEND_CUDA);
  int k = 0;
  for (const Points& pts : sets) {
    nbmc_mesh* a = nullptr;
    int32_t s = nbmc_context_set_particles_f64(seq.c, pts.data(), pts.size() / 3, 0);
    if (s == NBMC_OK) s = nbmc_context_reconstruct(seq.c, &prm, &a);
    Ctx fresh(NBMC_BACKEND_CUDA);
    nbmc_mesh* b = nullptr;
    int32_t t = nbmc_context_set_particles_f64(fresh.c, pts.data(), pts.size() / 3, 0);
    if (t == NBMC_OK) t = nbmc_context_reconstruct(fresh.c, &prm, &b);
    check(s == NBMC_OK && t == NBMC_OK && same(host_copy(a), host_copy(b)),
          "upload " + std::to_string(++k) + " of a sequence on one CUDA context (" + std::to_string(pts.size() / 3) +
              " particles) gives the fresh context's mesh");
    nbmc_mesh_destroy(a);
    nbmc_mesh_destroy(b);
  }
}

// A sequence's meshes: from the second reconstruction on, the host cache's
// blocks that the mesh download writes are page-locked and the GPU copies
// straight into them (core/host_cache.hpp, pin_for_device). Every mesh of
// the sequence equals the first (copied through the staging ring) bit for
// bit, host and device meshes, with and without the clean-up; a later raw
// mesh's triangles lie in page-locked memory (the direct copies ran).
void pinned_downloads(const Points& pts, double spacing) {
  const std::size_t n = pts.size() / 3;
  for (int cleanup = 0; cleanup <= 1; ++cleanup) {
    nbmc_params prm = params(spacing);
    prm.cell_size = 0.5;
    prm.cleanup = cleanup;
    Ctx seq(NBMC_BACKEND_CUDA);
    if (nbmc_context_set_particles_f64(seq.c, pts.data(), n, 0) != NBMC_OK) {
      check(false, std::string("pinned downloads: upload: ") + nbmc_context_last_error(seq.c));
      return;
    }
    Mesh first;
    bool locked = false;
    for (int k = 0; k < 6; ++k) {
      const bool on_device = k >= 4;
      if (nbmc_context_set_mesh_memory(seq.c, on_device ? NBMC_MEMORY_DEVICE : NBMC_MEMORY_HOST) != NBMC_OK) break;
      nbmc_mesh* m = nullptr;
      const int32_t s = nbmc_context_reconstruct(seq.c, &prm, &m);
      if (s != NBMC_OK) {
        check(false, std::string("pinned downloads: reconstruction: ") + nbmc_context_last_error(seq.c));
        nbmc_mesh_destroy(m);
        return;
      }
      const Mesh h = host_copy(m);
      if (k == 0) {
        first = h;
      } else {
        check(same(h, first), "pinned downloads (clean-up " + std::to_string(cleanup) + "): mesh " +
                                  std::to_string(k + 1) + (on_device ? " (device)" : " (host)") +
                                  " equals the first bit for bit (" + std::to_string(first.triangle_count()) +
                                  " triangles)");
      }
      cudaPointerAttributes a;
      if (!on_device && k >= 2 && nbmc_mesh_triangles(m) &&
          cudaPointerGetAttributes(&a, nbmc_mesh_triangles(m)) == cudaSuccess && a.type == cudaMemoryTypeHost)
        locked = true;
      cudaGetLastError();
      nbmc_mesh_destroy(m);
    }
    if (cleanup == 0)
      check(locked, "pinned downloads: a later raw mesh's triangles were copied into page-locked memory");
  }
}
}  // namespace

int main(int argc, char** argv) {
  if (!nbmc_backend_available(NBMC_BACKEND_CUDA)) {
    std::printf("FAIL: the CUDA backend is not available\n");
    return 2;
  }
  errors();
  reuse();
  double_positions();
  mesh_ops();
  run("sphere", sphere(0, 0, 0, 1.0, 0.1), 0.1, 0.5);
  const double lo[3] = {-0.8, -0.5, -0.4}, hi[3] = {0.8, 0.5, 0.4};
  run("box", box(lo, hi, 0.1), 0.1, 1.0);
  const std::string dir = argc > 1 ? argv[1] : "../shared/data";
  const std::string big = dir + "/xyz/cbd1654k_t040_1654104.xyz";
  if (std::ifstream(big).good()) {
    const Points frame = read_xyz(big);
    run("cbd1654k, cell r", frame, 0.00484, 1.0);
    pinned_downloads(frame, 0.00484);
  } else {
    std::printf("skip %s (not found)\n", big.c_str());
  }
  std::printf("%s: %d failure(s)\n", failures ? "FAILED" : "PASSED", failures);
  return failures ? 1 : 0;
}
