// SPDX-License-Identifier: MIT
// The pipeline instantiated for the CUDA execution space, and what only the
// CUDA build has: the device radix sort (CUB, shipped with the CUDA toolkit),
// uploads from device pointers, meshes left in device memory.
#include "../../src/backends.hpp"
#include "attributes.hpp"
#include "pipeline.hpp"
#include "../../src/core/mesh_memory.hpp"
#include "../../src/core/parallel.hpp"

#if defined(KOKKOS_ENABLE_CUDA)
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cuda_runtime.h>
#endif

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <limits>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

namespace nbmc {

#if defined(KOKKOS_ENABLE_CUDA)
namespace {

[[noreturn]] void cuda_fail(cudaError_t e, const std::string& what) {
  cudaGetLastError();  // clear a sticky allocation error
  const int status = e == cudaErrorMemoryAllocation ? 6 /*OUT_OF_MEMORY*/ : 9 /*INTERNAL*/;
  throw Error(status, what + ": " + cudaGetErrorString(e));
}

void cuda_check(cudaError_t e, const std::string& what) {
  if (e != cudaSuccess) cuda_fail(e, what);
}

[[noreturn]] void allocation_failed(cudaError_t e, std::size_t bytes, const std::string& what) {
  cudaGetLastError();
  std::ostringstream s;
  s << "could not allocate " << bytes / 1048576.0 << " MiB of device memory for " << what << " ("
    << cudaGetErrorString(e) << ")";
  throw Error(e == cudaErrorMemoryAllocation ? 6 : 9, s.str());
}

// A device pointer the caller gave us: device or managed memory of the
// current device, or a clear error.
void check_device_pointer(const void* p, const char* fn, const char* what = "xyz",
                          const char* host_hint = "nbmc_context_set_particles_f32/f64") {
  cudaPointerAttributes a;
  const cudaError_t e = cudaPointerGetAttributes(&a, p);
  if (e != cudaSuccess) {
    cudaGetLastError();
    throw Error(1, std::string(fn) + ": " + what + " is not a CUDA pointer (" + cudaGetErrorString(e) + ")");
  }
  if (a.type != cudaMemoryTypeDevice && a.type != cudaMemoryTypeManaged)
    throw Error(1, std::string(fn) + ": " + what + " is host memory; use " + host_hint + " for host arrays");
  int dev = 0;
  cuda_check(cudaGetDevice(&dev), fn);
  if (a.type == cudaMemoryTypeDevice && a.device != dev) {
    std::ostringstream s;
    s << fn << ": " << what << " lives on CUDA device " << a.device << ", the context runs on device " << dev;
    throw Error(1, s.str());
  }
}

// The pinned staging ring of download_segments: allocated on first use and
// kept for the life of the process (pinning costs milliseconds, more than
// one mesh's copy saves). Its lock also serialises downloads of concurrent
// contexts.
constexpr std::size_t kStagingChunk = std::size_t(4) << 20;
constexpr int kStagingSlots = 2;
struct Staging {
  std::mutex m;
  char* buffer = nullptr;  // kStagingSlots * kStagingChunk pinned bytes; null: pinning failed
  cudaEvent_t copied[kStagingSlots] = {};
  bool tried = false;
};
Staging& staging() {
  static Staging* s = new Staging();  // never destroyed (the driver reclaims it at exit)
  return *s;
}

// The device buffers' pool (device_pool_allocate): a pool of nbmc's own, so
// that its release threshold leaves the application's default pool alone.
// It keeps what a frame freed for the frame's later buffers; the end of each
// reconstruction gives the memory back to the driver (trim_device_pool), so
// that nothing stays reserved between calls.
cudaMemPool_t device_pool() {
  static const cudaMemPool_t pool = [] {
    const char* e = std::getenv("NBMC_DEVICE_POOL");
    if (e != nullptr && e[0] == '0' && e[1] == '\0') return cudaMemPool_t(nullptr);
    int dev = 0, supported = 0;
    if (cudaGetDevice(&dev) != cudaSuccess ||
        cudaDeviceGetAttribute(&supported, cudaDevAttrMemoryPoolsSupported, dev) != cudaSuccess || !supported) {
      cudaGetLastError();
      return cudaMemPool_t(nullptr);
    }
    cudaMemPoolProps props = {};
    props.allocType = cudaMemAllocationTypePinned;
    props.handleTypes = cudaMemHandleTypeNone;
    props.location.type = cudaMemLocationTypeDevice;
    props.location.id = dev;
    cudaMemPool_t p = nullptr;
    if (cudaMemPoolCreate(&p, &props) != cudaSuccess) {
      cudaGetLastError();
      return cudaMemPool_t(nullptr);
    }
    std::uint64_t keep = std::numeric_limits<std::uint64_t>::max();  // (until trim_device_pool)
    cudaMemPoolSetAttribute(p, cudaMemPoolAttrReleaseThreshold, &keep);
    cudaGetLastError();
    return p;
  }();
  return pool;
}

void trim_device_pool() {
  const cudaMemPool_t pool = device_pool();
  if (pool == nullptr) return;
  if (cudaStreamSynchronize(Kokkos::Cuda().cuda_stream()) != cudaSuccess || cudaMemPoolTrimTo(pool, 0) != cudaSuccess)
    cudaGetLastError();
}

}  // namespace

namespace Details {

void* device_pool_allocate(std::size_t bytes, const std::string& what, bool zero) {
  const cudaStream_t stream = Kokkos::Cuda().cuda_stream();
  const cudaMemPool_t pool = device_pool();
  void* p = nullptr;
  const cudaError_t e = pool ? cudaMallocFromPoolAsync(&p, bytes, pool, stream) : cudaMalloc(&p, bytes);
  if (e != cudaSuccess) allocation_failed(e, bytes, what);
  if (zero) {
    const cudaError_t z = pool ? cudaMemsetAsync(p, 0, bytes, stream) : cudaMemset(p, 0, bytes);
    if (z != cudaSuccess) {
      device_pool_free(p);
      cuda_fail(z, what);
    }
  }
  return p;
}

void device_pool_free(void* p) noexcept {
  if (p == nullptr) return;
  const cudaError_t e = device_pool() ? cudaFreeAsync(p, Kokkos::Cuda().cuda_stream()) : cudaFree(p);
  if (e != cudaSuccess) cudaGetLastError();
}

// A pageable copy from the device runs at about a sixth of a pinned one
// (40 MB of mesh: 5.5 ms on an H100 machine, with the first touch of the
// fresh host pages) and faults the pages in on the calling thread. Here the
// GPU copies 4 MiB chunks into pinned memory while the host threads move the
// previous chunk on to its destination, faulting its pages in in parallel.
// The host threads are Kokkos' (OpenMP): they have just run the pipeline's
// host steps and spin for a while after each; starting other threads now
// would compete with them for the cores (an H100 machine, the 1.65 M
// frame's mesh at r/2: 6-9 ms on other threads, 2.7-3.2 ms on these;
// bench/RESULTS.md, "Session 24").
namespace {
// The staging ring, made on first use (under st.m); false where pinning or
// its events failed (then plain copies).
bool staging_ready(Staging& st) {
  if (!st.tried) {
    st.tried = true;
    void* p = nullptr;
    if (cudaHostAlloc(&p, kStagingSlots * kStagingChunk, cudaHostAllocDefault) == cudaSuccess) {
      int made = 0;
      while (made < kStagingSlots && cudaEventCreateWithFlags(&st.copied[made], cudaEventDisableTiming) == cudaSuccess)
        ++made;
      if (made == kStagingSlots) {
        st.buffer = static_cast<char*>(p);
      } else {
        while (made > 0) cudaEventDestroy(st.copied[--made]);
        cudaFreeHost(p);
      }
    }
    cudaGetLastError();  // (a failure above leaves plain copies)
  }
  return st.buffer != nullptr;
}

// A host and a device array of `bytes` (a segment), or a piece of one.
struct Chunk {
  char* host;
  char* device;
  std::size_t bytes;
};
// The segments (DownloadSegment or UploadSegment) cut into the ring's chunks
// (kStagingChunk bytes at most). Or, where the ring could not be made, each
// segment copied directly (`kind`) and waited for, and no chunk.
template <class Segment>
std::vector<Chunk> ring_chunks(Staging& st, cudaStream_t stream, const Segment* segments, std::size_t n,
                               cudaMemcpyKind kind, const char* what) {
  auto ptr = [](const void* p) { return const_cast<char*>(static_cast<const char*>(p)); };
  std::vector<Chunk> chunks;
  const bool ring = staging_ready(st);
  for (std::size_t k = 0; k < n; ++k) {
    const Chunk c{ptr(segments[k].host), ptr(segments[k].device), segments[k].bytes};
    if (!ring && c.bytes)
      cuda_check(kind == cudaMemcpyDeviceToHost ? cudaMemcpyAsync(c.host, c.device, c.bytes, kind, stream)
                                                : cudaMemcpyAsync(c.device, c.host, c.bytes, kind, stream),
                 what);
    for (std::size_t at = 0; ring && at < c.bytes; at += kStagingChunk)
      chunks.push_back({c.host + at, c.device + at, std::min(kStagingChunk, c.bytes - at)});
  }
  if (!ring) cuda_check(cudaStreamSynchronize(stream), what);
  return chunks;
}

// On an error, nothing may still be copying through the ring when its lock
// is released.
struct Drain {
  cudaStream_t stream;
  bool done = false;
  ~Drain() {
    if (!done && cudaStreamSynchronize(stream) != cudaSuccess) cudaGetLastError();
  }
};
}  // namespace

void kokkos_host_copy(char* dst, const char* src, std::size_t bytes) {
  using HostExec = Kokkos::DefaultHostExecutionSpace;
  constexpr std::size_t part = std::size_t(256) << 10;
  Kokkos::parallel_for(
      "nbmc::mesh::host_copy", Kokkos::RangePolicy<HostExec>(0, (bytes + part - 1) / part),
      [=](const std::size_t q) { std::memcpy(dst + q * part, src + q * part, std::min(part, bytes - q * part)); });
  HostExec().fence();
}

// A pageable copy from the device runs at about a sixth of a pinned one
// (40 MB of mesh: 5.5 ms on an H100 machine, with the first touch of the
// fresh host pages) and faults the pages in on the calling thread. Here the
// GPU copies 4 MiB chunks into pinned memory while the host threads move the
// previous chunk on to its destination, faulting its pages in in parallel.
// The pipeline's host threads are Kokkos' (OpenMP, kokkos_host_copy): they
// have just run the pipeline's host steps and spin for a while after each;
// starting other threads now would compete with them for the cores (an H100
// machine, the 1.65 M frame's mesh at r/2: 6-9 ms on other threads, 2.7-3.2
// ms on these; bench/RESULTS.md, "Session 24").
//
// A destination that is a page-locked block of the host cache (or becomes
// one now: HostBlockCache::pin_for_device, a block's second use) gets the
// GPU's copy directly, queued before the ring's chunks: a sequence's later
// meshes skip the host threads' copies.
void download_segments(const Kokkos::Cuda& space, const DownloadSegment* segments, std::size_t n, HostCopy copy) {
  const cudaStream_t stream = space.cuda_stream();
  Staging& st = staging();
  std::lock_guard<std::mutex> lock(st.m);
  Drain drain{stream};
  std::vector<DownloadSegment> rest;
  rest.reserve(n);
  std::size_t direct = 0, direct_bytes = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const DownloadSegment& c = segments[k];
    if (c.bytes && HostBlockCache::instance().pin_for_device(c.host, c.bytes, cuda_pin, cuda_unpin)) {
      cuda_check(cudaMemcpyAsync(c.host, c.device, c.bytes, cudaMemcpyDeviceToHost, stream), "mesh download");
      ++direct;
      direct_bytes += c.bytes;
    } else {
      rest.push_back(c);
    }
  }
  const std::vector<Chunk> chunks =
      ring_chunks(st, stream, rest.data(), rest.size(), cudaMemcpyDeviceToHost, "mesh download");
  if (chunks.empty()) {  // (copied directly, or nothing to copy)
    if (direct) cuda_check(cudaStreamSynchronize(stream), "mesh download");
    drain.done = true;
    if (direct && host_trace_on())
      std::fprintf(stderr, "[nbmc trace] download: %zu page-locked destinations (%.1f MiB) copied directly\n", direct,
                   double(direct_bytes) / double(1 << 20));
    return;
  }
  auto issue = [&](std::size_t i) {
    char* slot = st.buffer + (i % kStagingSlots) * kStagingChunk;
    cuda_check(cudaMemcpyAsync(slot, chunks[i].device, chunks[i].bytes, cudaMemcpyDeviceToHost, stream),
               "mesh download");
    cuda_check(cudaEventRecord(st.copied[i % kStagingSlots], stream), "mesh download");
  };
  // NBMC_TRACE=1: how long the host waited for the GPU's copies and how
  // long its own copies took (which side bounds the download).
  using clock = std::chrono::steady_clock;
  const bool timed = host_trace_on();
  double waited = 0, copied = 0;
  for (std::size_t i = 0; i < std::min<std::size_t>(kStagingSlots, chunks.size()); ++i) issue(i);
  for (std::size_t i = 0; i < chunks.size(); ++i) {
    const clock::time_point t0 = timed ? clock::now() : clock::time_point();
    cuda_check(cudaEventSynchronize(st.copied[i % kStagingSlots]), "mesh download");
    const clock::time_point t1 = timed ? clock::now() : clock::time_point();
    copy(chunks[i].host, st.buffer + (i % kStagingSlots) * kStagingChunk, chunks[i].bytes);
    if (timed) {
      waited += std::chrono::duration<double, std::milli>(t1 - t0).count();
      copied += std::chrono::duration<double, std::milli>(clock::now() - t1).count();
    }
    if (i + kStagingSlots < chunks.size()) issue(i + kStagingSlots);
  }
  drain.done = true;
  if (timed)
    std::fprintf(stderr,
                 "[nbmc trace] download: %zu page-locked destinations (%.1f MiB) copied directly, %zu chunks of %zu "
                 "MiB, waited for the GPU %.3f ms, host copies %.3f ms\n",
                 direct, double(direct_bytes) / double(1 << 20), chunks.size(), kStagingChunk >> 20, waited, copied);
}

// The other way: the host threads copy a chunk into a slot of the ring while
// the GPU copies the previous one from the other.
void upload_segments(const Kokkos::Cuda& space, const UploadSegment* segments, std::size_t n, HostCopy copy) {
  const cudaStream_t stream = space.cuda_stream();
  Staging& st = staging();
  std::lock_guard<std::mutex> lock(st.m);
  const std::vector<Chunk> chunks = ring_chunks(st, stream, segments, n, cudaMemcpyHostToDevice, "mesh upload");
  if (chunks.empty()) return;
  Drain drain{stream};
  for (std::size_t i = 0; i < chunks.size(); ++i) {
    const int s = int(i % kStagingSlots);
    char* slot = st.buffer + std::size_t(s) * kStagingChunk;
    if (i >= std::size_t(kStagingSlots)) cuda_check(cudaEventSynchronize(st.copied[s]), "mesh upload");
    copy(slot, chunks[i].host, chunks[i].bytes);
    cuda_check(cudaMemcpyAsync(chunks[i].device, slot, chunks[i].bytes, cudaMemcpyHostToDevice, stream), "mesh upload");
    cuda_check(cudaEventRecord(st.copied[s], stream), "mesh upload");
  }
  cuda_check(cudaStreamSynchronize(stream), "mesh upload");
  drain.done = true;
}

void device_sort_pairs(const Kokkos::Cuda& space, MemoryTracker& tracker, std::uint64_t* keys_in,
                       std::uint64_t* keys_out, std::uint32_t* vals_in, std::uint32_t* vals_out, std::size_t n,
                       int end_bit) {
  if (n > std::size_t(std::numeric_limits<int>::max()))
    throw Error(5, "the device sort handles at most 2^31 - 1 particles");
  const cudaStream_t stream = space.cuda_stream();
  std::size_t temp_bytes = 0;
  cuda_check(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, keys_in, keys_out, vals_in, vals_out, int(n), 0,
                                             end_bit, stream),
             "radix sort (size query)");
  Buffer<unsigned char, Kokkos::CudaSpace> temp(tracker, "neighbourhood::sort_temp", temp_bytes);
  cuda_check(cub::DeviceRadixSort::SortPairs(temp.data(), temp_bytes, keys_in, keys_out, vals_in, vals_out, int(n),
                                             0, end_bit, stream),
             "radix sort");
  space.fence();
}

namespace {
template <class T>
void exclusive_sum_in_place(const Kokkos::Cuda& space, MemoryTracker& tracker, T* data, std::size_t n) {
  if (n == 0) return;
  const cudaStream_t stream = space.cuda_stream();
  std::size_t temp_bytes = 0;
  cuda_check(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, data, n, stream), "prefix sum (size query)");
  Buffer<unsigned char, Kokkos::CudaSpace> temp(tracker, "scan_temp", temp_bytes);
  cuda_check(cub::DeviceScan::ExclusiveSum(temp.data(), temp_bytes, data, n, stream), "prefix sum");
}
}  // namespace

void device_exclusive_sum(const Kokkos::Cuda& space, MemoryTracker& tracker, std::uint32_t* data, std::size_t n) {
  exclusive_sum_in_place(space, tracker, data, n);
}

void device_exclusive_sum(const Kokkos::Cuda& space, MemoryTracker& tracker, std::uint64_t* data, std::size_t n) {
  exclusive_sum_in_place(space, tracker, data, n);
}

}  // namespace Details

std::shared_ptr<void> cuda_allocate(std::size_t bytes, const char* what) {
  if (bytes == 0) return std::shared_ptr<void>();
  void* p = nullptr;
  const cudaError_t e = cudaMalloc(&p, bytes);
  if (e != cudaSuccess) allocation_failed(e, bytes, what);
  return std::shared_ptr<void>(p, [](void* q) { cudaFree(q); });
}

void allocate_device_mesh(HostMesh& mesh, std::uint64_t vertices, std::uint64_t triangles, bool normals) {
  const std::size_t np = 3 * std::size_t(vertices), nn = normals ? np : 0, nt = 3 * std::size_t(triangles);
  const std::size_t bytes = (np + nn) * sizeof(float) + nt * sizeof(std::uint32_t);
  mesh.device = cuda_allocate(bytes, "the mesh");
  mesh.on_device = true;
  float* base = static_cast<float*>(mesh.device.get());
  mesh.d_positions = np ? base : nullptr;
  mesh.d_normals = nn ? base + np : nullptr;
  mesh.d_triangles = nt ? reinterpret_cast<std::uint32_t*>(base + np + nn) : nullptr;
  mesh.d_vertices = vertices;
  mesh.d_triangles_count = triangles;
}

#endif  // KOKKOS_ENABLE_CUDA

void reconstruct_cuda(const ParticleInput& in, const Params& p, MemoryTracker& t, const Progress& pr,
                      bool mesh_on_device, HostMesh& m, RunStats& st, int device) {
#if defined(KOKKOS_ENABLE_CUDA)
  (void)device;  // Kokkos 3.4 binds one device at initialisation
  struct Trim {
    ~Trim() { trim_device_pool(); }
  } trim;  // (after the pipeline's buffers are freed, on every exit)
  Details::reconstruct(Kokkos::Cuda(), in, p, t, pr, mesh_on_device, m, st);
#else
  (void)in; (void)p; (void)t; (void)pr; (void)mesh_on_device; (void)m; (void)st; (void)device;
  throw Error(7, "the CUDA backend is not compiled in");
#endif
}

bool interpolate_attributes_cuda(const AttributeJob& job, MemoryTracker& t) {
#if defined(KOKKOS_ENABLE_CUDA)
  struct Trim {
    ~Trim() { trim_device_pool(); }
  } trim;
  return Details::interpolate_attributes(Kokkos::Cuda(), t, job);
#else
  (void)job; (void)t;
  throw Error(7, "the CUDA backend is not compiled in");
#endif
}

DeviceParticles upload_device_particles(const void* xyz, bool f32, std::uint64_t count, std::uint64_t byte_stride,
                                        const char* fn) {
#if defined(KOKKOS_ENABLE_CUDA)
  const std::uint64_t size = f32 ? sizeof(float) : sizeof(double);
  if (byte_stride == 0) byte_stride = 3 * size;
  if (byte_stride % size != 0 || reinterpret_cast<std::uintptr_t>(xyz) % size != 0) {
    std::ostringstream s;
    s << fn << ": on the device, xyz and byte_stride (" << byte_stride << ") must be multiples of " << size
      << " bytes (aligned values)";
    throw Error(1, s.str());
  }
  check_device_pointer(xyz, fn);
  DeviceParticles out;
  out.data = cuda_allocate(std::size_t(count) * 3 * sizeof(double), "the particles");
  out.count = std::size_t(count);
  double* dst = static_cast<double*>(out.data.get());
  const unsigned char* src = static_cast<const unsigned char*>(xyz);
  const std::uint64_t stride = byte_stride;
  const Kokkos::Cuda space;
  using Range = Kokkos::RangePolicy<Kokkos::Cuda>;
  std::uint64_t bad = 0;
  Kokkos::parallel_reduce(
      "nbmc::upload::device_particles", Range(space, 0, count),
      KOKKOS_LAMBDA(const std::size_t i, std::uint64_t& nbad) {
        const unsigned char* q = src + i * stride;
        for (int a = 0; a < 3; ++a) {
          const double v = f32 ? double(reinterpret_cast<const float*>(q)[a]) : reinterpret_cast<const double*>(q)[a];
          // NaN fails both comparisons; Inf is beyond 1e15
          if (!(v >= -1e15 && v <= 1e15)) ++nbad;
          dst[3 * i + a] = v;
        }
      },
      bad);
  {
    const cudaError_t e = cudaGetLastError();
    if (e != cudaSuccess) cuda_fail(e, std::string(fn) + ": reading the device positions");
  }
  if (bad) {
    std::uint64_t first = 0;
    Kokkos::parallel_reduce(
        "nbmc::upload::first_bad_particle", Range(space, 0, count),
        KOKKOS_LAMBDA(const std::size_t i, std::uint64_t& f) {
          bool ok = true;
          for (int a = 0; a < 3; ++a) {
            const double v = dst[3 * i + a];
            ok = ok && v >= -1e15 && v <= 1e15;
          }
          if (!ok && i < f) f = i;
        },
        Kokkos::Min<std::uint64_t>(first));
    std::ostringstream s;
    s << fn << ": " << bad << " coordinate(s) are NaN, infinite or beyond 1e15 in magnitude (first at particle "
      << first << ")";
    throw Error(2, s.str());
  }
  return out;
#else
  (void)xyz; (void)f32; (void)count; (void)byte_stride;
  throw Error(7, std::string(fn) + ": the CUDA backend is not compiled in");
#endif
}

bool cuda_pin(void* p, std::size_t bytes) {
#if defined(KOKKOS_ENABLE_CUDA)
  if (!p || !bytes) return false;
  if (cudaHostRegister(p, bytes, cudaHostRegisterDefault) == cudaSuccess) return true;
  cudaGetLastError();
  return false;
#else
  (void)p; (void)bytes;
  return false;
#endif
}

void cuda_unpin(void* p) {
#if defined(KOKKOS_ENABLE_CUDA)
  if (p && cudaHostUnregister(p) != cudaSuccess) cudaGetLastError();
#else
  (void)p;
#endif
}

void download_mesh(const HostMesh& m, float* positions, float* normals, std::uint32_t* triangles) {
#if defined(KOKKOS_ENABLE_CUDA)
  const std::size_t nv = std::size_t(m.d_vertices) * 3, nt = std::size_t(m.d_triangles_count) * 3;
  if (positions && m.d_positions)
    cuda_check(cudaMemcpy(positions, m.d_positions, nv * sizeof(float), cudaMemcpyDeviceToHost), "mesh positions");
  if (normals && m.d_normals)
    cuda_check(cudaMemcpy(normals, m.d_normals, nv * sizeof(float), cudaMemcpyDeviceToHost), "mesh normals");
  if (triangles && m.d_triangles)
    cuda_check(cudaMemcpy(triangles, m.d_triangles, nt * sizeof(std::uint32_t), cudaMemcpyDeviceToHost),
               "mesh triangles");
#else
  (void)m; (void)positions; (void)normals; (void)triangles;
  throw Error(7, "the CUDA backend is not compiled in");
#endif
}

#if defined(KOKKOS_ENABLE_CUDA)
namespace {
// Copies bytes from src to dst on the host threads (core/parallel.hpp: the
// context's OpenMP threads on nbmc's Kokkos thread, else nbmc's pool), in
// parts of 256 KiB: a fresh destination's pages are faulted in in parallel.
void copy_on_host_threads(char* dst, const char* src, std::size_t bytes) {
  constexpr std::size_t part = std::size_t(256) << 10;
  const std::size_t parts = (bytes + part - 1) / part;
  for_chunks(parts, chunk_count(parts, 1), [&](std::size_t, std::size_t b, std::size_t e) {
    for (std::size_t q = b; q < e; ++q) std::memcpy(dst + q * part, src + q * part, std::min(part, bytes - q * part));
  });
}
}  // namespace
#endif

void release_device_pool() {
#if defined(KOKKOS_ENABLE_CUDA)
  trim_device_pool();
#endif
}

void download_mesh_for_postprocess(const HostMesh& m, HostMesh& h, bool incidence, MemoryTracker& tracker) {
#if defined(KOKKOS_ENABLE_CUDA)
  // (The incidence's buffers go back to nbmc's device pool, which keeps them
  // for the changed entries' after the host's clean-up: the caller releases
  // it, release_device_pool.)
  const std::size_t nv = m.d_vertices, nt = m.d_triangles_count;
  h.positions.resize(3 * nv);
  h.normals.resize(m.d_normals ? 3 * nv : 0);
  h.triangles.resize(3 * nt);
  mesh::PrebuiltIncidence& inc = h.incidence;
  inc.clear();
  const Kokkos::Cuda space;
  using Incidence = Details::DeviceIncidence<Kokkos::Cuda>;
  Incidence di;
  if (incidence &&
      Incidence::wanted(tracker, mesh::mesh_bytes(nv, nt, false, m.d_normals != nullptr), nv, nt) &&
      di.build<float>(space, tracker, Kokkos::View<const float*, Kokkos::CudaSpace>(m.d_positions, 3 * nv),
                      Kokkos::View<const std::uint32_t*, Kokkos::CudaSpace>(m.d_triangles, 3 * nt), nv, nt, inc)) {
    host_trace("post-processing: incidence on the device", nt);
    // (The device mesh itself moves: the host's clean-up goes on from it,
    // and gives back only what it changes after.)
    if (di.move_rounds<float>(space, tracker, Kokkos::View<float*, Kokkos::CudaSpace>(m.d_positions, 3 * nv),
                              Kokkos::View<const std::uint32_t*, Kokkos::CudaSpace>(m.d_triangles, 3 * nt), nv, nt,
                              inc))
      host_trace("post-processing: moves on the device", inc.moves);
  }
  const Details::DownloadSegment segments[] = {
      {h.positions.data(), m.d_positions, h.positions.size() * sizeof(float)},
      {h.normals.data(), m.d_normals, h.normals.size() * sizeof(float)},
      {h.triangles.data(), m.d_triangles, h.triangles.size() * sizeof(std::uint32_t)},
      {inc.start.data(), di.start.data(), inc.start.size() * sizeof(std::uint32_t)},
      {inc.incident.data(), di.incident.data(), inc.incident.size() * sizeof(std::uint32_t)},
      {inc.maybe_bad.data(), di.bits.data(), inc.maybe_bad.size() * sizeof(std::uint32_t)}};
  Details::download_segments(space, segments, sizeof(segments) / sizeof(segments[0]), copy_on_host_threads);
#else
  (void)m; (void)h; (void)incidence; (void)tracker;
  throw Error(7, "the CUDA backend is not compiled in");
#endif
}

void upload_mesh_after_postprocess(HostMesh& m, const HostMesh& h) {
#if defined(KOKKOS_ENABLE_CUDA)
  const Details::UploadSegment segments[] = {
      {m.d_positions, h.positions.data(), h.positions.size() * sizeof(float)},
      {m.d_normals, h.normals.data(), m.d_normals ? h.normals.size() * sizeof(float) : 0},
      {m.d_triangles, h.triangles.data(), h.triangles.size() * sizeof(std::uint32_t)}};
  Details::upload_segments(Kokkos::Cuda(), segments, sizeof(segments) / sizeof(segments[0]), copy_on_host_threads);
  m.d_vertices = h.positions.size() / 3;
  m.d_triangles_count = h.triangles.size() / 3;
#else
  (void)m; (void)h;
  throw Error(7, "the CUDA backend is not compiled in");
#endif
}

bool upload_changed_entries(HostMesh& m, const HostMesh& h, const mesh::ChangedEntries& changed,
                            MemoryTracker& tracker) {
#if defined(KOKKOS_ENABLE_CUDA)
  const std::size_t nv = h.positions.size() / 3, nt = h.triangles.size() / 3;
  const bool normals = m.d_normals != nullptr;
  if (!changed.valid || h.f64 || nv > m.d_vertices || nt > m.d_triangles_count || h.normals.size() != (normals ? 3 * nv : 0))
    return false;
  const std::size_t ncv = changed.vertices.size(), nct = changed.triangles.size();
  for (std::uint32_t v : changed.vertices)
    if (v >= nv) return false;
  for (std::uint32_t t : changed.triangles)
    if (t >= nt) return false;
  const std::size_t width = normals ? 6 : 3;  // (floats per changed vertex)
  const Kokkos::Cuda space;
  using Range = Kokkos::RangePolicy<Kokkos::Cuda>;
  using Details::Buffer;
  // The listed places of h (the compacted result) packed, uploaded and
  // scattered into m's arrays, which hold the mesh h was downloaded from:
  // every other place below h's counts is the same there.
  Buffer<float, Kokkos::CudaSpace> vval;
  Buffer<std::uint32_t, Kokkos::CudaSpace> vidx, tidx, tval;
  try {
    vidx = Buffer<std::uint32_t, Kokkos::CudaSpace>(tracker, "changed::vertices", ncv);
    vval = Buffer<float, Kokkos::CudaSpace>(tracker, "changed::vertex_values", width * ncv);
    tidx = Buffer<std::uint32_t, Kokkos::CudaSpace>(tracker, "changed::triangles", nct);
    tval = Buffer<std::uint32_t, Kokkos::CudaSpace>(tracker, "changed::triangle_values", 3 * nct);
  } catch (const Error& e) {
    if (e.status != 6 /*NBMC_ERROR_OUT_OF_MEMORY*/ && e.status != 10 /*NBMC_ERROR_MEMORY_BUDGET*/) throw;
    return false;
  } catch (const std::bad_alloc&) {
    return false;
  }
  std::vector<float> vpack(width * ncv);
  std::vector<std::uint32_t> tpack(3 * nct);
  for (std::size_t i = 0; i < ncv; ++i) {
    const std::size_t v = changed.vertices[i];
    for (int a = 0; a < 3; ++a) vpack[width * i + a] = h.positions[3 * v + a];
    if (normals)
      for (int a = 0; a < 3; ++a) vpack[width * i + 3 + a] = h.normals[3 * v + a];
  }
  for (std::size_t i = 0; i < nct; ++i)
    for (int c = 0; c < 3; ++c) tpack[3 * i + c] = h.triangles[3 * std::size_t(changed.triangles[i]) + c];
  const Details::UploadSegment segments[] = {
      {vidx.data(), changed.vertices.data(), ncv * sizeof(std::uint32_t)},
      {vval.data(), vpack.data(), vpack.size() * sizeof(float)},
      {tidx.data(), changed.triangles.data(), nct * sizeof(std::uint32_t)},
      {tval.data(), tpack.data(), tpack.size() * sizeof(std::uint32_t)}};
  Details::upload_segments(space, segments, sizeof(segments) / sizeof(segments[0]), copy_on_host_threads);
  host_trace("post-processing: upload (changed entries)", ncv + nct);
  const std::uint32_t* vi = vidx.data();
  const float* vv = vval.data();
  const std::uint32_t* ti = tidx.data();
  const std::uint32_t* tv = tval.data();
  float* p = m.d_positions;
  float* n = m.d_normals;
  std::uint32_t* t = m.d_triangles;
  Kokkos::parallel_for(
      "nbmc::changed::vertices", Range(space, 0, ncv), KOKKOS_LAMBDA(const std::size_t i) {
        const std::size_t v = vi[i];
        for (int a = 0; a < 3; ++a) p[3 * v + a] = vv[width * i + a];
        if (n)
          for (int a = 0; a < 3; ++a) n[3 * v + a] = vv[width * i + 3 + a];
      });
  Kokkos::parallel_for(
      "nbmc::changed::triangles", Range(space, 0, nct), KOKKOS_LAMBDA(const std::size_t i) {
        const std::size_t x = ti[i];
        for (int c = 0; c < 3; ++c) t[3 * x + c] = tv[3 * i + c];
      });
  {
    const cudaError_t e = cudaGetLastError();
    if (e != cudaSuccess) cuda_fail(e, "mesh upload");
  }
  space.fence();
  host_trace("post-processing: changed entries on the device", ncv + nct);
  m.d_vertices = nv;
  m.d_triangles_count = nt;
  return true;
#else
  (void)m; (void)h; (void)changed; (void)tracker;
  throw Error(7, "the CUDA backend is not compiled in");
#endif
}

void download_particles(const void* device_xyz, std::size_t count, double* host) {
#if defined(KOKKOS_ENABLE_CUDA)
  if (count)
    cuda_check(cudaMemcpy(host, device_xyz, 3 * count * sizeof(double), cudaMemcpyDeviceToHost),
               "copying the particles to the host");
#else
  (void)device_xyz; (void)count; (void)host;
  throw Error(7, "the CUDA backend is not compiled in");
#endif
}

void download_device_items(const void* src, std::uint64_t count, std::uint64_t byte_stride, std::size_t item_bytes,
                           std::size_t value_bytes, void* host, const char* fn, const char* host_hint) {
#if defined(KOKKOS_ENABLE_CUDA)
  if (byte_stride % value_bytes != 0 || reinterpret_cast<std::uintptr_t>(src) % value_bytes != 0) {
    std::ostringstream s;
    s << fn << ": on the device, data and byte_stride (" << byte_stride << ") must be multiples of " << value_bytes
      << " bytes (aligned values)";
    throw Error(1, s.str());
  }
  check_device_pointer(src, fn, "data", host_hint);
  if (count)
    cuda_check(cudaMemcpy2D(host, item_bytes, src, std::size_t(byte_stride), item_bytes, std::size_t(count),
                            cudaMemcpyDeviceToHost),
               "copying the attribute to the host");
#else
  (void)src; (void)count; (void)byte_stride; (void)item_bytes; (void)value_bytes; (void)host; (void)host_hint;
  throw Error(7, std::string(fn) + ": the CUDA backend is not compiled in");
#endif
}

void move_mesh_to_device(HostMesh& m) {
  if (m.f64) throw Error(4, "double_positions: the mesh must be in host memory (not NBMC_MEMORY_DEVICE)");
#if defined(KOKKOS_ENABLE_CUDA)
  const std::size_t np = m.positions.size(), nn = m.normals.size(), nt = m.triangles.size();
  HostMesh d;
  allocate_device_mesh(d, np / 3, nt / 3, nn > 0);
  // Through the pinned staging ring, as the post-processing's upload (the
  // three pageable copies of a stitched 1.65 M-frame mesh took about 6 ms).
  const Details::UploadSegment segments[] = {{d.d_positions, m.positions.data(), np * sizeof(float)},
                                             {d.d_normals, m.normals.data(), nn * sizeof(float)},
                                             {d.d_triangles, m.triangles.data(), nt * sizeof(std::uint32_t)}};
  Details::upload_segments(Kokkos::Cuda(), segments, sizeof(segments) / sizeof(segments[0]), copy_on_host_threads);
  m = std::move(d);
#else
  (void)m;
  throw Error(7, "the CUDA backend is not compiled in");
#endif
}

std::uint64_t cuda_free_memory() {
#if defined(KOKKOS_ENABLE_CUDA)
  std::size_t free_b = 0, total_b = 0;
  if (cudaMemGetInfo(&free_b, &total_b) != cudaSuccess) {
    cudaGetLastError();
    return 0;
  }
  return free_b;
#else
  return 0;
#endif
}

}  // namespace nbmc
