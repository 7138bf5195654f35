// SPDX-License-Identifier: MIT
// Micro-benchmark behind the upload's order (pin after the copy; see
// bench/RESULTS.md "Upload"): host-to-device copies of 1.65 M particles as
// doubles (39.7 MB) from pageable and pinned memory, and what pinning costs
// for pages already touched and for fresh ones. Not built by CMake:
//   nvcc -O2 bench/h2d_micro.cu -o h2d_micro && ./h2d_micro
#include <cuda_runtime.h>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>
static double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }
int main() {
  const size_t n = 3 * 1654104, bytes = n * sizeof(double);
  void* d; cudaMalloc(&d, bytes); cudaFree(0);
  for (int rep = 0; rep < 3; ++rep) {
    double* h = (double*)malloc(bytes);
    double t0 = now(); for (size_t i = 0; i < n; ++i) h[i] = double(i); double t1 = now();
    cudaMemcpy(d, h, bytes, cudaMemcpyHostToDevice); cudaDeviceSynchronize(); double t2 = now();
    cudaMemcpy(d, h, bytes, cudaMemcpyHostToDevice); cudaDeviceSynchronize(); double t3 = now();
    cudaHostRegister(h, bytes, cudaHostRegisterDefault); double t4 = now();
    cudaMemcpy(d, h, bytes, cudaMemcpyHostToDevice); cudaDeviceSynchronize(); double t5 = now();
    cudaHostUnregister(h); double t6 = now();
    double* g = (double*)malloc(bytes);
    double t7 = now(); cudaHostRegister(g, bytes, cudaHostRegisterDefault); double t8 = now();
    for (size_t i = 0; i < n; ++i) g[i] = double(i); double t9 = now();
    cudaMemcpy(d, g, bytes, cudaMemcpyHostToDevice); cudaDeviceSynchronize(); double t10 = now();
    cudaHostUnregister(g); free(g); free(h);
    printf("rep %d: first touch %.2f ms, pageable H2D %.2f then %.2f ms, register touched %.2f ms, pinned H2D %.2f ms, unregister %.2f ms | register untouched %.2f ms, fill pinned %.2f ms, pinned H2D %.2f ms\n",
           rep, 1e3*(t1-t0), 1e3*(t2-t1), 1e3*(t3-t2), 1e3*(t4-t3), 1e3*(t5-t4), 1e3*(t6-t5), 1e3*(t8-t7), 1e3*(t9-t8), 1e3*(t10-t9));
  }
}
