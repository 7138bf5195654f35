// SPDX-License-Identifier: MIT
// How fast one core computes when T cores compute at once: T threads each
// run the same register-only work (8 independent chains of fused
// multiply-adds on 16-float vectors, no memory traffic), and each reports
// its rate. On a CPU whose clock drops when more cores are busy (turbo
// limits) the rate per thread falls with T, and so does the best parallel
// efficiency any program can show against its one-thread time.
//
//   cc -O2 -march=native -pthread bench/clock_probe.c -o clock_probe
//   ./clock_probe [SECONDS_PER_RUN=2 [T ...]]   prints T, Gflop/s per thread (min, mean), ratio to the
//                                              first T (default T: 1 2 4 8 12 16 1)
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

typedef float v16 __attribute__((vector_size(64)));
enum { kMaxThreads = 256 };

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static double seconds = 2.0;
static volatile int go = 0;

static void* work(void* out) {
  v16 a[8], m, b;
  for (int i = 0; i < 8; ++i)
    for (int l = 0; l < 16; ++l) a[i][l] = 1.0f + 0.001f * (float)(i + l);
  for (int l = 0; l < 16; ++l) {
    m[l] = 0.999999f;
    b[l] = 1e-7f;
  }
  while (!go) {
  }
  const double t0 = now();
  long iters = 0;
  double t = t0;
  while (t - t0 < seconds) {
    for (int k = 0; k < 100000; ++k)
      for (int i = 0; i < 8; ++i) a[i] = a[i] * m + b;  // contracted to one FMA per vector with -march=native
    iters += 100000;
    t = now();
  }
  float sink = 0;
  for (int i = 0; i < 8; ++i) sink += a[i][0];
  *(double*)out = (double)iters * 8 * 16 * 2 / (t - t0) * 1e-9 + (sink == 12345.f ? 1e-30 : 0);
  return NULL;
}

static double run(int T, double* lo) {
  pthread_t th[kMaxThreads];
  double r[kMaxThreads];
  go = 0;
  for (int i = 0; i < T; ++i) pthread_create(&th[i], NULL, work, &r[i]);
  go = 1;
  double sum = 0, mn = 1e300;
  for (int i = 0; i < T; ++i) {
    pthread_join(th[i], NULL);
    sum += r[i];
    mn = r[i] < mn ? r[i] : mn;
  }
  *lo = mn;
  return sum / T;
}

int main(int argc, char** argv) {
  if (argc > 1) seconds = atof(argv[1]);
  int counts[64] = {1, 2, 4, 8, 12, 16, 1};
  int n = 7;
  if (argc > 2) {  // the thread counts to run, in order
    n = 0;
    for (int a = 2; a < argc && n < 64; ++a) {
      const int t = atoi(argv[a]);
      if (t >= 1 && t <= kMaxThreads) counts[n++] = t;
    }
  }
  double base = 0;
  printf("threads  Gflop/s per thread (min, mean)  mean / one thread\n");
  for (int c = 0; c < n; ++c) {
    double lo;
    const double mean = run(counts[c], &lo);
    if (c == 0) base = mean;
    printf("%7d  %8.1f %8.1f  %6.3f\n", counts[c], lo, mean, mean / base);
  }
  return 0;
}
