// SPDX-License-Identifier: MIT
#include "backends.hpp"
#include "subdomains.hpp"
#include "core/clusters.hpp"
#include "core/parallel.hpp"
#include "core/repair_scratch.hpp"

#include <Kokkos_Core.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <deque>
#include <exception>
#include <functional>
#include <future>
#include <mutex>
#include <sstream>
#include <thread>
#if defined(_OPENMP)
#include <omp.h>
#endif

namespace nbmc {

void Progress::operator()(int stage, double fraction) const {
  if (fn && !fn(stage, fraction)) throw Error(NBMC_ERROR_CANCELLED, "cancelled by the progress callback");
}

const char* version_string() {
  static const std::string s = [] {
    std::ostringstream o;
    o << NBMC_VERSION_MAJOR << '.' << NBMC_VERSION_MINOR << '.' << NBMC_VERSION_PATCH << " (backends: serial";
#if defined(KOKKOS_ENABLE_OPENMP)
    o << " openmp";
#endif
#if defined(KOKKOS_ENABLE_CUDA)
    o << " cuda";
#endif
    o << "; Kokkos " << KOKKOS_VERSION / 10000 << '.' << (KOKKOS_VERSION / 100) % 100 << '.' << KOKKOS_VERSION % 100
      << ")";
    return o.str();
  }();
  return s.c_str();
}

const char* backend_name(int32_t b) {
  switch (b) {
    case NBMC_BACKEND_AUTO: return "auto";
    case NBMC_BACKEND_SERIAL: return "serial";
    case NBMC_BACKEND_OPENMP: return "openmp";
    case NBMC_BACKEND_CUDA: return "cuda";
    default: return "unknown";
  }
}

namespace {

#if defined(KOKKOS_ENABLE_CUDA)
int cuda_device_count() {
  int n = 0;
  if (cudaGetDeviceCount(&n) != cudaSuccess) {
    cudaGetLastError();
    return 0;
  }
  return n;
}
#endif

std::mutex g_runtime_mutex;
int g_contexts = 0;
bool g_we_initialised = false;
bool g_finalized = false;  // Kokkos 3.4 cannot be initialised again after finalize
bool g_atexit_registered = false;
// Kokkos' Serial and OpenMP spaces are single global instances in Kokkos 3.4:
// reconstructions on one backend are serialised (contexts stay independent).
std::mutex g_run_mutex[4];

// Kokkos 3.4's OpenMP space accepts parallel dispatch only from the thread
// that initialised it. When nbmc owns the runtime, that is this worker
// thread, and every reconstruction runs on it, whichever thread called.
class KokkosThread {
 public:
  void start(const Kokkos::InitArguments& args) {
    std::promise<void> ready;
    auto started = ready.get_future();
    thread_ = std::thread([this, args, &ready]() mutable {
      try {
#if defined(_OPENMP)
        omp_set_max_active_levels(2);  // partition_master nests one level
#endif
        Kokkos::initialize(args);
        ready.set_value();
      } catch (...) {
        ready.set_exception(std::current_exception());
        return;
      }
      loop();
      Kokkos::finalize();
    });
    try {
      started.get();
    } catch (...) {
      thread_.join();
      throw;
    }
  }
  bool running() const { return thread_.joinable(); }
  bool on_worker() const { return std::this_thread::get_id() == thread_.get_id(); }
  void run(const std::function<void()>& fn) {
    if (!running() || on_worker()) {
      fn();
      return;
    }
    std::packaged_task<void()> task(fn);
    auto done = task.get_future();
    {
      std::lock_guard<std::mutex> lock(m_);
      jobs_.push_back(std::move(task));
    }
    cv_.notify_one();
    done.get();  // rethrows what fn threw
  }
  void stop() {
    if (!running()) return;
    {
      std::lock_guard<std::mutex> lock(m_);
      stop_ = true;
    }
    cv_.notify_one();
    thread_.join();
  }

 private:
  void loop() {
    while (true) {
      std::packaged_task<void()> job;
      {
        std::unique_lock<std::mutex> lock(m_);
        cv_.wait(lock, [this] { return stop_ || !jobs_.empty(); });
        if (jobs_.empty()) return;  // stop requested and nothing left
        job = std::move(jobs_.front());
        jobs_.pop_front();
      }
      job();
    }
  }
  std::thread thread_;
  std::mutex m_;
  std::condition_variable cv_;
  std::deque<std::packaged_task<void()>> jobs_;
  bool stop_ = false;
};

KokkosThread& kokkos_thread() {
  static KokkosThread* t = new KokkosThread();  // never destroyed: used from atexit
  return *t;
}

int pool_threads() {
#if defined(KOKKOS_ENABLE_OPENMP)
  return Kokkos::OpenMP::impl_thread_pool_size();
#else
  return 1;
#endif
}

// Finalises the runtime nbmc initialised, on the thread that owns it.
void stop_runtime() {
  if (kokkos_thread().running())
    kokkos_thread().stop();  // finalises on the worker
  else if (Kokkos::is_initialized())
    Kokkos::finalize();
}

void finalize_at_exit() {
  std::lock_guard<std::mutex> lock(g_runtime_mutex);
  if (g_we_initialised && !g_finalized) {
    stop_runtime();
    g_finalized = true;
  }
  g_we_initialised = false;
}

}  // namespace

bool backend_available(int32_t b) {
  switch (b) {
    case NBMC_BACKEND_AUTO:
    case NBMC_BACKEND_SERIAL: return true;
    case NBMC_BACKEND_OPENMP:
#if defined(KOKKOS_ENABLE_OPENMP)
      return true;
#else
      return false;
#endif
    case NBMC_BACKEND_CUDA:
#if defined(KOKKOS_ENABLE_CUDA)
      return cuda_device_count() > 0;
#else
      return false;
#endif
    default: return false;
  }
}

int32_t auto_backend() {
  if (backend_available(NBMC_BACKEND_CUDA)) return NBMC_BACKEND_CUDA;
  if (backend_available(NBMC_BACKEND_OPENMP)) return NBMC_BACKEND_OPENMP;
  return NBMC_BACKEND_SERIAL;
}

int max_threads() {
  const int hw = int(std::max(1u, std::thread::hardware_concurrency()));
  return std::max(4 * hw, 16);
}

void runtime_acquire(nbmc_context& ctx) {
  std::lock_guard<std::mutex> lock(g_runtime_mutex);
  if (g_finalized)
    throw Error(NBMC_ERROR_BACKEND_UNAVAILABLE, "the Kokkos runtime has already been finalized in this process");
  if (!Kokkos::is_initialized()) {
    Kokkos::InitArguments args;
    // The OpenMP pool holds at least 4 threads so that contexts can ask for
    // 1..4 threads on small machines; each context uses only its own count.
    const int hw = int(std::max(1u, std::thread::hardware_concurrency()));
    int want = std::max(hw, 4);
    if (ctx.backend == NBMC_BACKEND_OPENMP && ctx.num_threads > want) want = std::min(ctx.num_threads, max_threads());
    args.num_threads = want;
    args.device_id = ctx.device_id;
    args.disable_warnings = true;
    if (ctx.flags & NBMC_CONTEXT_KOKKOS_ON_CALLING_THREAD) {
#if defined(_OPENMP)
      omp_set_max_active_levels(2);  // partition_master nests one level
#endif
      Kokkos::initialize(args);
    } else {
      kokkos_thread().start(args);
    }
    g_we_initialised = true;
    if (!g_atexit_registered) {
      std::atexit(finalize_at_exit);
      g_atexit_registered = true;
    }
  }
  ++g_contexts;
}

void runtime_release(nbmc_context&) {
  std::lock_guard<std::mutex> lock(g_runtime_mutex);
  // The last context gone: the host blocks kept for a next frame go too
  // (core/host_cache.hpp; blocks of meshes still alive stay theirs), the
  // clean-up's kept scratch first (core/repair_scratch.hpp: its blocks go
  // back to the host cache).
  if (--g_contexts == 0) {
    mesh::detail::RepairScratchPool::instance().release();
    HostBlockCache::instance().release();
  }
}

bool runtime_finalize() {
  std::lock_guard<std::mutex> lock(g_runtime_mutex);
  if (g_contexts > 0) return false;
  if (g_we_initialised && !g_finalized) {
    stop_runtime();
    g_finalized = true;
  }
  g_we_initialised = false;
  return true;
}

namespace {
double length(const nbmc_params& in, double v, double r) {
  return in.length_unit == NBMC_UNIT_SPACING ? v * r : v;
}
void require(bool ok, const std::string& msg) {
  if (!ok) throw Error(NBMC_ERROR_INVALID_PARAMETER, msg);
}
std::string num(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}
}  // namespace

Params resolve_params(const nbmc_params& in) {
  require(std::isfinite(in.spacing) && in.spacing > 0, "spacing must be a positive number (got " + num(in.spacing) + ")");
  require(in.length_unit == NBMC_UNIT_SPACING || in.length_unit == NBMC_UNIT_ABSOLUTE,
          "length_unit must be NBMC_UNIT_SPACING or NBMC_UNIT_ABSOLUTE");
  require(in.method == NBMC_METHOD_SSP07 || in.method == NBMC_METHOD_ZB05 || in.method == NBMC_METHOD_SPH ||
              in.method == NBMC_METHOD_YT10,
          "unknown method " + std::to_string(in.method));
  require(in.field >= NBMC_FIELD_NARROW_BAND && in.field <= NBMC_FIELD_SCATTER,
          "unknown field strategy " + std::to_string(in.field));
  const struct {
    const char* name;
    double v;
  } lengths[] = {{"cell_size", in.cell_size},           {"influence_radius", in.influence_radius},
                 {"band_width", in.band_width},         {"surface_radius", in.surface_radius},
                 {"iso_radius", in.iso_radius}};
  for (const auto& l : lengths)
    require(std::isfinite(l.v) && l.v > 0, std::string(l.name) + " must be a positive number (got " + num(l.v) + ")");
  require(std::isfinite(in.t_low) && std::isfinite(in.t_high) && in.t_low < in.t_high,
          "t_low must be smaller than t_high (got " + num(in.t_low) + ", " + num(in.t_high) + ")");
  // Checked whatever the method, like t_low and t_high (a caller built
  // against an older header gets the default 0.6).
  require(std::isfinite(in.iso_threshold) && in.iso_threshold > 0 && in.iso_threshold < 1,
          "iso_threshold must lie strictly between 0 and 1, a fraction of the rest density (got " +
              num(in.iso_threshold) + ")");
  require(in.isolated == NBMC_ISOLATED_KEEP || in.isolated == NBMC_ISOLATED_DROP ||
              in.isolated == NBMC_ISOLATED_SPHERE,
          "isolated must be NBMC_ISOLATED_KEEP, NBMC_ISOLATED_DROP or NBMC_ISOLATED_SPHERE (got " +
              std::to_string(in.isolated) + ")");
  require(in.min_cluster >= 1, "min_cluster must be at least 1 (got " + std::to_string(in.min_cluster) + ")");
  // Yu & Turk's anisotropy: checked whatever the method, like iso_threshold
  // (a caller built against an older header gets the defaults).
  require(std::isfinite(in.aniso_kr) && in.aniso_kr >= 1,
          "aniso_kr must be at least 1, the largest ratio of a kernel's axes (got " + num(in.aniso_kr) + ")");
  require(std::isfinite(in.aniso_ks) && in.aniso_ks > 0, "aniso_ks must be a positive number (got " +
                                                             num(in.aniso_ks) + ")");
  require(std::isfinite(in.aniso_kn) && in.aniso_kn > 0 && in.aniso_kn <= kYt10MaxAxis,
          "aniso_kn must lie in (0, " + num(kYt10MaxAxis) + "], a kernel scale (got " + num(in.aniso_kn) + ")");
  require(std::isfinite(in.aniso_lambda) && in.aniso_lambda >= 0 && in.aniso_lambda <= 1,
          "aniso_lambda must lie in [0, 1] (got " + num(in.aniso_lambda) + ")");
  require(in.aniso_neighbours >= 0,
          "aniso_neighbours must be >= 0 (got " + std::to_string(in.aniso_neighbours) + ")");
  require(std::isfinite(in.max_distance) && in.max_distance >= 0,
          "max_distance must be a finite length >= 0 (0: no distance guard; got " + num(in.max_distance) + ")");
  require(std::isfinite(in.color_threshold) && in.color_threshold >= 0, "color_threshold must be >= 0");
  require(in.neighbour_threshold >= 0, "neighbour_threshold must be >= 0");
  Params p;
  const double r = in.spacing;
  p.spacing = r;
  p.cell_size = length(in, in.cell_size, r);
  p.influence_radius = length(in, in.influence_radius, r);
  p.band_width = length(in, in.band_width, r);
  p.surface_radius = length(in, in.surface_radius, r);
  p.iso_radius = length(in, in.iso_radius, r);
  // (the SPH density and YT10 do not use iso_radius)
  require(is_density_field(Method(in.method)) || p.iso_radius < p.influence_radius,
          "iso_radius must be smaller than influence_radius");
  require(p.surface_radius <= 2 * p.influence_radius,
          "surface_radius may be at most twice the influence radius (got " + num(p.surface_radius) + " and " +
              num(p.influence_radius) + ")");
  p.method = Method(in.method);
  p.field = FieldKind(in.field);
  p.t_low = in.t_low;
  p.t_high = in.t_high;
  p.iso_threshold = in.iso_threshold;
  p.aniso_kr = in.aniso_kr;
  p.aniso_ks = in.aniso_ks;
  p.aniso_kn = in.aniso_kn;
  p.aniso_lambda = in.aniso_lambda;
  p.aniso_neighbours = in.aniso_neighbours;
  p.max_distance = length(in, in.max_distance, r);
  p.drop_isolated = in.isolated == NBMC_ISOLATED_DROP || in.isolated == NBMC_ISOLATED_SPHERE;
  p.min_cluster = std::uint32_t(in.min_cluster);
  p.color_threshold = in.color_threshold;
  p.neighbour_threshold = in.neighbour_threshold;
  p.normals = in.compute_normals != 0;
  p.double_positions = in.double_positions != 0;
  p.use_bbox = in.use_bbox != 0;
  if (p.use_bbox)
    for (int a = 0; a < 3; ++a) {
      require(std::isfinite(in.bbox_min[a]) && std::isfinite(in.bbox_max[a]) && in.bbox_min[a] < in.bbox_max[a],
              "the bounding box must be finite with bbox_min < bbox_max on every axis");
      p.bbox_min[a] = in.bbox_min[a];
      p.bbox_max[a] = in.bbox_max[a];
    }
  return p;
}

void check_domain(const Params& p) {
  // Band vertices around one surface particle; beyond this the cell size is
  // absurdly small for the band (and the grid would not be indexable anyway).
  const double per_axis = 2 * p.band_width / p.cell_size + 1;
  if (per_axis > 2048) {
    std::ostringstream s;
    s << "cell size " << p.cell_size << " is too small for band width " << p.band_width << " (" << per_axis
      << " band vertices per axis around each particle; at most 2048)";
    throw Error(NBMC_ERROR_DOMAIN_TOO_LARGE, s.str());
  }
  const double per_axis_r = 2 * p.influence_radius / p.cell_size + 1;
  if (per_axis_r > 4096) {
    std::ostringstream s;
    s << "cell size " << p.cell_size << " is too small for influence radius " << p.influence_radius;
    throw Error(NBMC_ERROR_DOMAIN_TOO_LARGE, s.str());
  }
}

void release_host_particles(nbmc_context& ctx) {
  if (ctx.pinned) cuda_unpin(ctx.pinned);
  ctx.pinned = nullptr;
  ParticleVector().swap(ctx.particles);
}

double* prepare_host_particles(nbmc_context& ctx, std::size_t n) {
  const std::size_t cap = ctx.particles.capacity();
  if (cap < n || cap > 2 * n) {
    release_host_particles(ctx);
    ctx.particles.reserve(n);
  }
  ctx.particles.resize(n);  // uninitialised (NoInitAllocator)
  return ctx.particles.data();
}

// Pinned after the copy, not before: the copy's threads fault the fresh
// pages in in parallel, whereas pinning untouched pages populates them on
// one thread. 1.65 M particles (40 MB) on the H200 machine: pinning first
// took 10.1-10.6 ms of a 13.5 ms upload; pinning touched pages takes about
// 2.3 ms (bench/RESULTS.md, "Upload"). The pinned copy to the device then
// takes 0.75 ms against 4.6 ms from pageable memory.
void pin_host_particles(nbmc_context& ctx) {
  if (ctx.backend != NBMC_BACKEND_CUDA || ctx.pinned || ctx.particles.empty()) return;
  if (cuda_pin(ctx.particles.data(), ctx.particles.capacity() * sizeof(double))) ctx.pinned = ctx.particles.data();
}

std::size_t host_threads_of(const nbmc_context& ctx) {
  if (ctx.backend == NBMC_BACKEND_SERIAL) return 1;
  return ctx.num_threads > 0 ? std::size_t(ctx.num_threads) : 0;
}

namespace {
// The host loops of a call on the Kokkos thread run on its OpenMP threads
// (ScopedHostExecutor in core/parallel.hpp): libgomp's threads spin for
// milliseconds after each parallel region, and other threads started then
// share the cores with them (an H100 machine's 16 cores: the copy of the
// mesh from the GPU took 6-9 ms on the pool's threads, 2.7-3.2 ms on
// these; bench/RESULTS.md). Not inside a parallel region (a task's own
// loop, or a partition of a smaller context) and not with fewer threads
// than tasks: the tasks may wait for each other.
bool openmp_host_executor(std::size_t n, HostTask task, const void* ctx) {
#if defined(_OPENMP) && defined(KOKKOS_ENABLE_OPENMP)
  if (omp_in_parallel() || n > std::size_t(omp_get_max_threads()) || n > std::size_t(pool_threads())) return false;
  std::atomic<bool> whole{true};
#pragma omp parallel num_threads(int(n))
  {
    if (std::size_t(omp_get_num_threads()) == n)
      task(ctx, std::size_t(omp_get_thread_num()));
    else
      whole.store(false, std::memory_order_relaxed);  // (a smaller team: nobody runs a task)
  }
  return whole.load(std::memory_order_relaxed);
#else
  (void)n; (void)task; (void)ctx;
  return false;
#endif
}
}  // namespace

void run_on_kokkos_thread(nbmc_context& ctx, const std::function<void()>& fn) {
  std::lock_guard<std::mutex> lock(g_run_mutex[ctx.backend]);
  const std::size_t threads = host_threads_of(ctx);
  kokkos_thread().run([&] {
    const ScopedHostThreads limit(threads);  // (stitching, subdomain packing, post-processing)
    const ScopedHostExecutor executor(openmp_host_executor);
    fn();
  });
}

namespace {
// Runs run(backend) on the context's backend, the OpenMP one with the
// context's thread count; the caller holds the backend's lock on nbmc's
// Kokkos thread.
template <class F>
void on_backend(nbmc_context& ctx, F&& run) {
  switch (ctx.backend) {
    case NBMC_BACKEND_SERIAL: run(NBMC_BACKEND_SERIAL); break;
    case NBMC_BACKEND_OPENMP: {
#if defined(KOKKOS_ENABLE_OPENMP)
      const int pool = pool_threads();
      const int hw = int(std::max(1u, std::thread::hardware_concurrency()));
      const int threads = std::min(pool, ctx.num_threads > 0 ? ctx.num_threads : hw);
      if (threads >= pool) {
        run(NBMC_BACKEND_OPENMP);
      } else {
        std::exception_ptr err;
        Kokkos::OpenMP::partition_master(
            [&](int, int) {
              try {
                run(NBMC_BACKEND_OPENMP);
              } catch (...) {
                err = std::current_exception();
              }
            },
            1, threads);
        if (err) std::rethrow_exception(err);
      }
#endif
      break;
    }
    case NBMC_BACKEND_CUDA: run(NBMC_BACKEND_CUDA); break;
    default: throw Error(NBMC_ERROR_BACKEND_UNAVAILABLE, "backend not available");
  }
}

// One reconstruction (a frame, or a subdomain of one) on the context's
// backend; the caller holds the backend's lock on nbmc's Kokkos thread.
void dispatch(nbmc_context& ctx, const ParticleInput& in, const Params& p, const Progress& progress,
            bool mesh_on_device, HostMesh& mesh, RunStats& st) {
  on_backend(ctx, [&](int32_t backend) {
    switch (backend) {
      case NBMC_BACKEND_SERIAL: reconstruct_serial(in, p, ctx.memory, progress, mesh, st); break;
      case NBMC_BACKEND_OPENMP: reconstruct_openmp(in, p, ctx.memory, progress, mesh, st); break;
      default: reconstruct_cuda(in, p, ctx.memory, progress, mesh_on_device, mesh, st, ctx.device_id); break;
    }
  });
}

}  // namespace

bool interpolate_attributes_on_backend(nbmc_context& ctx, const AttributeJob& job) {
  bool done = false;
  run_on_kokkos_thread(ctx, [&] {
    on_backend(ctx, [&](int32_t backend) {
      switch (backend) {
        case NBMC_BACKEND_SERIAL: done = interpolate_attributes_serial(job, ctx.memory); break;
        case NBMC_BACKEND_OPENMP: done = interpolate_attributes_openmp(job, ctx.memory); break;
        default: done = interpolate_attributes_cuda(job, ctx.memory); break;
      }
    });
  });
  return done;
}

void run_region(nbmc_context& ctx, const ParticleInput& in, const Params& p, const Progress& progress, HostMesh& mesh,
                RunStats& st) {
  run_on_kokkos_thread(ctx, [&] { dispatch(ctx, in, p, progress, false, mesh, st); });
}

void run_backend(nbmc_context& ctx, const Params& p, HostMesh& mesh, RunStats& st,
                 std::vector<std::uint32_t>* kept_out) {
  Progress progress;
  if (ctx.progress_fn) {
    nbmc_progress_fn fn = ctx.progress_fn;
    void* user = ctx.progress_user;
    progress.fn = [fn, user](int stage, double f) { return fn(user, stage, f) == 0; };
  }
  std::lock_guard<std::mutex> lock(g_run_mutex[ctx.backend]);
  ctx.memory.reset_peak();
  ParticleInput in;
  if (ctx.device_particles.count) {
    in.xyz = static_cast<const double*>(ctx.device_particles.data.get());
    in.count = ctx.device_particles.count;
    in.on_device = true;
  } else {
    in.xyz = ctx.particles.data();
    in.count = ctx.particles.size() / 3;
  }
  // Per-particle radii (host memory, the particles' order) when they differ;
  // equal radii run as a uniform frame (scale_for_radii).
  if (p.radius_ref > 0) in.radii = ctx.radii.data();
  const bool mesh_on_device = ctx.mesh_memory == NBMC_MEMORY_DEVICE;
  auto run_one = [&](const ParticleInput& in, const Params& p, bool mesh_on_device, HostMesh& mesh, RunStats& st) {
    dispatch(ctx, in, p, progress, mesh_on_device, mesh, st);
  };
  ctx.subdomain_report = SubdomainReport();
  ClusterFilter clusters;
  ParticleVector kept;  // the particles the isolated-particle filter keeps
  std::vector<double> kept_radii;
  // The input's positions on the host: particles in device memory are
  // copied into `host` first.
  auto host_positions = [&](ParticleVector& host) -> const double* {
    if (!in.on_device) return in.xyz;
    host.resize(3 * in.count);
    download_particles(in.xyz, in.count, host.data());
    return host.data();
  };
  auto job = [&]() {
    if (p.drop_isolated) {
      ParticleVector host;
      const double* xyz = host_positions(host);
      clusters = drop_small_clusters(xyz, in.count, p.surface_radius, p.min_cluster);
      if (clusters.kept.empty())
        throw Error(NBMC_ERROR_NO_PARTICLES, "every particle lies in a cluster of fewer than min_cluster (" +
                                                 std::to_string(p.min_cluster) + ") particles (isolated = drop)");
      kept.resize(3 * clusters.kept.size());
      for (std::size_t i = 0; i < clusters.kept.size(); ++i)
        for (int a = 0; a < 3; ++a) kept[3 * i + a] = xyz[3 * std::size_t(clusters.kept[i]) + a];
      if (in.radii) {
        kept_radii.resize(clusters.kept.size());
        for (std::size_t i = 0; i < clusters.kept.size(); ++i) kept_radii[i] = in.radii[clusters.kept[i]];
        in.radii = kept_radii.data();
      }
      in.xyz = kept.data();
      in.count = clusters.kept.size();
      in.on_device = false;
    }
    if (ctx.subdomains.split()) {
      // Subdomains work on host positions: particles in device memory are
      // copied to the host first (the GPU then holds one subdomain at a time).
      ParticleVector host;
      const double* xyz = host_positions(host);
      std::uint64_t budget = ctx.memory.budget;
      if (!budget && ctx.backend == NBMC_BACKEND_CUDA) budget = cuda_free_memory() / 10 * 8;
      const RunRegion run = [&](const ParticleInput& part, const Params& q, HostMesh& m, RunStats& s) {
        run_one(part, q, false, m, s);
      };
      auto split = [&](std::uint64_t at_least) {
        if (!reconstruct_subdomains(ctx.subdomains, budget, xyz, in.radii, in.count, p, run, mesh, st,
                                    ctx.subdomain_report, at_least))
          return false;
        if (mesh_on_device) move_mesh_to_device(mesh);
        return true;
      };
      if (split(1)) return;
      if (ctx.subdomains.automatic) {
        // `auto` estimated that the frame fits; if the whole run still hits
        // a limit that splitting avoids, split after all.
        try {
          run_one(in, p, mesh_on_device, mesh, st);
          return;
        } catch (const Error& e) {
          if (!split_would_help(e)) throw;
        }
        mesh = HostMesh();
        st = RunStats();
        if (split(2)) return;
      }
    }
    run_one(in, p, mesh_on_device, mesh, st);
  };
  kokkos_thread().run(job);
  st.dropped_particles = clusters.dropped_particles;
  st.dropped_clusters = clusters.dropped_clusters;
  if (kept_out) kept_out->swap(clusters.kept);
  ctx.peak_memory = ctx.memory.peak.load();
}

}  // namespace nbmc
