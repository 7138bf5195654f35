// SPDX-License-Identifier: MIT
// NBMC_HD marks a plain C++ function of src/core that also runs on GPUs (in
// device code compiled by nvcc): __host__ __device__ there, inline
// elsewhere. Such functions use only what device code has (no standard
// algorithms or containers; sqrt from <cmath>, which CUDA provides on the
// device with the host's IEEE rounding).
#pragma once

#if defined(__CUDACC__) || defined(__HIPCC__)
#define NBMC_HD __host__ __device__ inline
#else
#define NBMC_HD inline
#endif
