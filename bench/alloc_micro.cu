// SPDX-License-Identifier: MIT
// Micro-benchmark: what the pipeline's device buffers cost to allocate and
// free (Kokkos 3.4's CudaSpace calls cudaMalloc and cudaFree; cudaFree also
// waits for the device), against the stream-ordered pool (cudaMallocAsync /
// cudaFreeAsync with a release threshold). A frame of the 1.65 M frame at
// r/2 makes a few dozen buffers of 1-60 MB. Not built by CMake:
//   nvcc -O2 bench/alloc_micro.cu -o alloc_micro && ./alloc_micro
#include <cuda_runtime.h>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <vector>
static double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }
__global__ void touch(char* p, size_t n) {
  for (size_t i = blockIdx.x * size_t(blockDim.x) + threadIdx.x; i < n; i += size_t(gridDim.x) * blockDim.x) p[i] = 1;
}
int main() {
  cudaFree(0);
  const size_t sizes[] = {size_t(64) << 10, size_t(1) << 20, size_t(8) << 20, size_t(32) << 20, size_t(64) << 20};
  cudaStream_t s;
  cudaStreamCreate(&s);
  cudaMemPool_t pool;
  cudaDeviceGetDefaultMemPool(&pool, 0);
  uint64_t threshold = UINT64_MAX;
  cudaMemPoolSetAttribute(pool, cudaMemPoolAttrReleaseThreshold, &threshold);
  for (size_t bytes : sizes) {
    const int k = 40;
    // cudaMalloc + a kernel + cudaFree, k times (as a buffer's life in a stage)
    double t0 = now();
    for (int i = 0; i < k; ++i) {
      char* p;
      cudaMalloc(&p, bytes);
      touch<<<256, 256, 0, s>>>(p, bytes);
      cudaFree(p);
    }
    cudaDeviceSynchronize();
    double t1 = now();
    for (int i = 0; i < k; ++i) {
      char* p;
      cudaMallocAsync(&p, bytes, s);
      touch<<<256, 256, 0, s>>>(p, bytes);
      cudaFreeAsync(p, s);
    }
    cudaStreamSynchronize(s);
    double t2 = now();
    // the kernels alone
    char* q;
    cudaMalloc(&q, bytes);
    double t3 = now();
    for (int i = 0; i < k; ++i) touch<<<256, 256, 0, s>>>(q, bytes);
    cudaStreamSynchronize(s);
    double t4 = now();
    cudaFree(q);
    printf("%8zu KiB: cudaMalloc+kernel+cudaFree %.1f us, async pool %.1f us, kernel alone %.1f us (per buffer)\n",
           bytes >> 10, 1e6 * (t1 - t0) / k, 1e6 * (t2 - t1) / k, 1e6 * (t4 - t3) / k);
  }
  printf("%s\n", cudaGetErrorString(cudaGetLastError()));
}
