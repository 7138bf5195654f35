// Times the CUDA runtime's first steps in a fresh process.
#include <cuda_runtime.h>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>
static double ms(std::chrono::steady_clock::time_point& t) {
  auto n = std::chrono::steady_clock::now();
  double r = std::chrono::duration<double, std::milli>(n - t).count();
  t = n;
  return r;
}
__global__ void k1(float* p, int n) { int i = blockIdx.x * blockDim.x + threadIdx.x; if (i < n) p[i] += 1; }
#include <cstring>
#include <unistd.h>
int main(int argc, char** argv) {
  const char* mode = argc > 1 ? argv[1] : "normal";
  auto t = std::chrono::steady_clock::now();
  int n = 0; cudaGetDeviceCount(&n); printf("cudaGetDeviceCount %.1f ms\n", ms(t));
  cudaSetDevice(0); printf("cudaSetDevice %.1f ms\n", ms(t));
  cudaFree(0); printf("cudaFree(0) (context) %.1f ms\n", ms(t));
  cudaDeviceProp pr; cudaGetDeviceProperties(&pr, 0); printf("props %.1f ms\n", ms(t));
  float* d = nullptr; size_t N = 10 << 20; cudaMalloc(&d, N * 4); printf("cudaMalloc 40MB %.1f ms\n", ms(t));
  float* d2 = nullptr; cudaMalloc(&d2, N * 4); printf("cudaMalloc 40MB again %.1f ms\n", ms(t));
  std::vector<float> h(N, 1.f); ms(t);
  cudaMemcpy(d, h.data(), N * 4, cudaMemcpyHostToDevice); printf("memcpy 40MB pageable %.1f ms\n", ms(t));
  cudaMemcpy(d, h.data(), N * 4, cudaMemcpyHostToDevice); printf("memcpy 40MB pageable again %.1f ms\n", ms(t));
  k1<<<(N + 255) / 256, 256>>>(d, int(N)); cudaDeviceSynchronize(); printf("first kernel %.1f ms\n", ms(t));
  k1<<<(N + 255) / 256, 256>>>(d, int(N)); cudaDeviceSynchronize(); printf("second kernel %.1f ms\n", ms(t));
  cudaFree(d); cudaFree(d2); printf("free %.1f ms\n", ms(t));
  if (!strcmp(mode, "reset")) { cudaDeviceReset(); printf("reset %.1f ms\n", ms(t)); }
  fflush(stdout);
  if (!strcmp(mode, "quick")) _exit(0);
  return 0;
}
