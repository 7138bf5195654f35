// SPDX-License-Identifier: MIT
// The mesh post-processing section of include/nbmc.h: nbmc_mesh_check, and
// the clean-up / smoothing hook of nbmc_context_reconstruct. The steps run
// on the host (on its threads where they are parallel), for every backend:
// device meshes are copied to the host and back, and compacted on the GPU
// after a clean-up that is the last step (postprocess_device).
#include "capi_mesh.hpp"

#include "backends.hpp"
#include "core/mesh_check.hpp"
#include "core/mesh_cleanup.hpp"
#include "core/mesh_decimate.hpp"
#include "core/mesh_flip.hpp"
#include "core/mesh_memory.hpp"
#include "core/mesh_smooth.hpp"
#include "core/trace.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <new>
#include <stdexcept>
#include <string>
#include <utility>

namespace nbmc {

void check_postprocess_params(const nbmc_params& params) {
  if (params.smooth_iterations < 0 || params.smooth_iterations > 100000)
    throw Error(NBMC_ERROR_INVALID_PARAMETER, "smooth_iterations must be in [0, 100000] (got " +
                                                  std::to_string(params.smooth_iterations) + ")");
  if (params.smooth_weighting != NBMC_SMOOTH_UNIFORM && params.smooth_weighting != NBMC_SMOOTH_FEATURE)
    throw Error(NBMC_ERROR_INVALID_PARAMETER,
                "smooth_weighting must be NBMC_SMOOTH_UNIFORM or NBMC_SMOOTH_FEATURE (got " +
                    std::to_string(params.smooth_weighting) + ")");
  if (!(params.decimate_fraction > 0 && params.decimate_fraction <= 1))
    throw Error(NBMC_ERROR_INVALID_PARAMETER, "decimate_fraction must be in (0, 1] (got " +
                                                  std::to_string(params.decimate_fraction) + "; 1 = no decimation)");
}

namespace {

// Counts one post-processing step against the context's memory budget while
// it runs: the step's estimate (core/mesh_memory.hpp) and the mesh it works
// on (the host mesh, and for a mesh in GPU memory its device arrays too).
// Over the budget it throws NBMC_ERROR_MEMORY_BUDGET before the step
// touches the mesh (the reconstruction then returns no mesh at all); a
// mesh of more than max_triangles, which the step's 32-bit list offsets
// cannot address, NBMC_ERROR_DOMAIN_TOO_LARGE (core/mesh_memory.hpp).
class StepMemory {
 public:
  StepMemory(MemoryTracker& tracker, std::uint64_t step_bytes, std::uint64_t mesh_bytes, const char* step,
             const char* turn_off, std::uint64_t nv, std::uint64_t nt, std::uint64_t max_triangles)
      : t_(tracker), bytes_(step_bytes + mesh_bytes) {
    mesh::require_addressable(step, turn_off, nv, nt, max_triangles);
    const std::uint64_t in_use = t_.current.load();
    if (t_.budget && in_use + bytes_ > t_.budget) {
      const double mib = 1.0 / (1024.0 * 1024.0);
      char msg[768];
      std::snprintf(msg, sizeof msg,
                    "%s of %llu vertices and %llu triangles needs an estimated %.1f MiB (%.1f MiB "
                    "of working memory + %.1f MiB for the mesh; %.1f MiB in use), over the memory budget of %.1f "
                    "MiB; raise the budget or turn %s off (%s)",
                    step, (unsigned long long)nv, (unsigned long long)nt, double(bytes_) * mib,
                    double(step_bytes) * mib, double(mesh_bytes) * mib, double(in_use) * mib,
                    double(t_.budget) * mib, step, turn_off);
      throw Error(NBMC_ERROR_MEMORY_BUDGET, msg);
    }
    t_.add(bytes_);
  }
  ~StepMemory() { t_.sub(bytes_); }
  StepMemory(const StepMemory&) = delete;
  StepMemory& operator=(const StepMemory&) = delete;

 private:
  MemoryTracker& t_;
  std::uint64_t bytes_;
};

// The post-processing of a mesh in host memory, on its float or double
// positions (PosVec). device_bytes: the mesh's device arrays, when it lives
// in GPU memory (counted with the host copy), else 0. changed (may be
// null): where the clean-up is the last step, the places where its result
// differs from its input (cleanup_mesh's `changed`); else it stays as it
// was (not valid).
template <class PosVec>
void postprocess_positions(const nbmc_params& params, PosVec& positions, HostMesh& m, mesh::PostprocessStats& ps,
                           const FeatureParticles* fp, double cell, MemoryTracker& tracker,
                           std::uint64_t device_bytes, mesh::ChangedEntries* changed) {
  const bool clean_is_last = params.smooth_iterations <= 0 && !(params.decimate_fraction < 1);
  auto counts = [&] {
    return std::make_pair(std::uint64_t(positions.size() / 3), std::uint64_t(m.triangles.size() / 3));
  };
  auto held = [&] {
    const auto c = counts();
    return mesh::mesh_bytes(c.first, c.second, m.f64, !m.normals.empty()) + device_bytes;
  };
  auto clean = [&](bool first) {
    const auto c = counts();
    const StepMemory mem(tracker, mesh::cleanup_bytes(c.first, c.second), held(), "the mesh clean-up",
                         "nbmc_params.cleanup = 0; CLI --no-cleanup", c.first, c.second, mesh::cleanup_max_triangles);
    // (The first run on the pipeline's mesh takes its incidence, when the
    // pipeline built one; the result is the same.)
    const mesh::CleanupResult r =
        mesh::cleanup_mesh(positions, m.normals, m.triangles, cell, first && !m.incidence.empty() ? &m.incidence : nullptr,
                           first && clean_is_last ? changed : nullptr);
    m.incidence.clear();
    // After smoothing, the fairing flips (core/mesh_flip.hpp): the
    // diagonals that bend the surface least; no vertex moves. Not in the
    // default clean-up: on the 1.65 M frame at r/2 they cost about 0.50 s of
    // host CPU time (chunk-parallel since, 0.86 s before), against 0.24 s
    // for the whole default post-processing on 2 threads (bench/RESULTS.md
    // "Fairing flips, chunk-parallel").
    if (!first) {
      const mesh::FlipResult f = mesh::flip_edges_fairing(positions.data(), positions.size() / 3, m.triangles);
      host_trace("clean-up: fairing flips", f.flips);
      ps.fairing_flips += f.flips;
    }
    ps.collapses += r.collapses;
    ps.flips += r.flips;
    ps.moves += r.moves;
    ps.cuts += r.cuts;
    ps.removed_component_triangles += r.small_component_triangles + r.degenerate_component_triangles;
    if (first) ps.bad_before = r.bad_before;
    ps.bad_after = r.bad_after;
  };
  if (params.cleanup) clean(true);
  if (params.smooth_iterations > 0) {
    {
      const auto c = counts();
      const bool feature = params.smooth_weighting == NBMC_SMOOTH_FEATURE;
      const StepMemory mem(tracker, mesh::smooth_bytes(c.first, c.second, feature && fp ? fp->count : 0), held(),
                           "the mesh smoothing", "nbmc_params.smooth_iterations = 0; CLI --smooth 0", c.first,
                           c.second, mesh::smooth_max_triangles);
      std::vector<double> weights;
      if (feature) {
        if (!fp || !fp->xyz)
          throw Error(NBMC_ERROR_INTERNAL, "feature-weighted smoothing without the particles");
        const std::size_t nv = positions.size() / 3;
        weights = mesh::particle_density_ratio(positions.data(), nv, fp->xyz, fp->count, fp->radius, fp->spacing);
        for (double& w : weights) w = mesh::feature_weight(w);
      }
      const mesh::SmoothResult s =
          mesh::smooth_mesh(positions, m.normals, m.triangles, params.smooth_iterations, mesh::kTaubinLambda,
                            mesh::kTaubinMu, weights.empty() ? nullptr : &weights);
      ps.volume_before_smoothing = s.volume_before;
      ps.volume_after_smoothing = s.volume_after;
      ps.volume_change = s.volume_before != 0 ? s.volume_after / s.volume_before - 1 : 0;
    }
    // Smoothing can pull nearly coincident vertices together again (the
    // clusters the clean-up widened): clean what it made.
    if (params.cleanup) clean(false);
  }
  ps.pre_decimation_triangles = m.triangles.size() / 3;
  if (params.decimate_fraction < 1) {
    const auto c = counts();
    const StepMemory mem(tracker, mesh::decimate_bytes(c.first, c.second), held(), "the mesh decimation",
                         "nbmc_params.decimate_fraction = 1; CLI: no --decimate", c.first, c.second,
                         mesh::check_max_triangles);
    const mesh::DecimateResult d = mesh::decimate_mesh(positions, m.normals, m.triangles, params.decimate_fraction);
    ps.decimate_collapses = d.collapses;
  }
}

void postprocess_host(const nbmc_params& params, HostMesh& m, mesh::PostprocessStats& ps, const FeatureParticles* fp,
                      double cell, MemoryTracker& tracker, std::uint64_t device_bytes = 0,
                      mesh::ChangedEntries* changed = nullptr) {
  if (m.f64) postprocess_positions(params, m.positions64, m, ps, fp, cell, tracker, device_bytes, changed);
  else postprocess_positions(params, m.positions, m, ps, fp, cell, tracker, device_bytes, changed);
}

// A mesh left in GPU memory: copied to the host (with the clean-up's
// incidence built on the GPU), post-processed there, and copied back into
// its own device arrays (the counts only shrink). Where the clean-up is the
// last step (the defaults), only the places where its compacted result
// differs from the mesh the device arrays still hold go back (of the 1.65 M
// frame's 2.5 M vertices and triangles at r/2, about 8,000: the whole
// upload took 3.2-3.6 ms, bench/RESULTS.md sessions 38 and 39).
void postprocess_device(const nbmc_params& params, HostMesh& m, mesh::PostprocessStats& ps,
                        const FeatureParticles* fp, double cell, MemoryTracker& tracker) {
  if (m.triangle_count() == 0) return;
  const std::uint64_t device_bytes =
      mesh::mesh_bytes(m.vertex_count(), m.triangle_count(), false, m.d_normals != nullptr);
  struct Release {
    ~Release() { release_device_pool(); }
  } release;  // (after the upload, and on every way out: see download_mesh_for_postprocess)
  HostMesh h;
  download_mesh_for_postprocess(m, h, params.cleanup != 0, tracker);
  host_trace("post-processing: download", m.triangle_count());
  mesh::ChangedEntries changed;
  postprocess_host(params, h, ps, fp, cell, tracker, device_bytes, &changed);
  if (changed.valid && upload_changed_entries(m, h, changed, tracker)) return;
  upload_mesh_after_postprocess(m, h);
  host_trace("post-processing: upload", h.triangles.size() / 3);
}

}  // namespace

mesh::PostprocessStats postprocess_mesh(const nbmc_params& params, HostMesh& m, RunStats& st, MemoryTracker& tracker,
                                        const FeatureParticles* fp) {
  mesh::PostprocessStats ps;
  ps.raw_triangles = ps.pre_decimation_triangles = m.triangle_count();
  struct ClearIncidence {  // (whatever happens, not kept with the mesh)
    HostMesh& m;
    ~ClearIncidence() { m.incidence.clear(); }
  } clear_incidence{m};
  if (!params.cleanup && params.smooth_iterations <= 0 && !(params.decimate_fraction < 1)) return ps;
  const auto t0 = std::chrono::steady_clock::now();
  host_trace("post-processing: start", m.triangle_count());
  if (m.on_device) postprocess_device(params, m, ps, fp, st.cell, tracker);
  else postprocess_host(params, m, ps, fp, st.cell, tracker);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  st.vertices = m.vertex_count();
  st.triangles = m.triangle_count();
  st.stage[NBMC_STAGE_POSTPROCESS] += s;
  st.total += s;
  return ps;
}

}  // namespace nbmc

extern "C" {

void nbmc_mesh_check_result_init(nbmc_mesh_check_result* r) {
  if (!r) return;
  std::memset(r, 0, sizeof(*r));
  r->struct_size = sizeof(nbmc_mesh_check_result);
}

int32_t nbmc_mesh_check(const nbmc_mesh* m, nbmc_mesh_check_result* out) {
  if (!m || !out || out->struct_size < sizeof(nbmc_mesh_check_result)) return NBMC_ERROR_INVALID_ARGUMENT;
  try {
    const nbmc::HostMesh& h = m->mesh;
    nbmc::mesh::require_addressable("the mesh check", "do not call nbmc_mesh_check; CLI: no --check", h.vertex_count(),
                              h.triangle_count(), nbmc::mesh::check_max_triangles);
    nbmc::HostMesh copy;  // a device mesh, brought to the host
    if (h.on_device) {
      copy.positions.resize(3 * h.vertex_count());
      copy.triangles.resize(3 * h.triangle_count());
      nbmc::download_mesh(h, copy.positions.data(), nullptr, copy.triangles.data());
    }
    const nbmc::HostMesh& src = h.on_device ? copy : h;
    const nbmc::mesh::CheckResult c =
        src.f64 ? nbmc::mesh::check_mesh(src.positions64.data(), src.positions64.size() / 3, src.triangles.data(),
                                         src.triangles.size() / 3)
                : nbmc::mesh::check_mesh(src.positions.data(), src.positions.size() / 3, src.triangles.data(),
                                         src.triangles.size() / 3);
    nbmc_mesh_check_result_init(out);
    out->closed = c.closed;
    out->manifold = c.manifold;
    out->oriented = c.oriented;
    out->vertex_count = c.vertices;
    out->triangle_count = c.triangles;
    out->edge_count = c.edges;
    out->boundary_edge_count = c.boundary_edges;
    out->nonmanifold_edge_count = c.nonmanifold_edges;
    out->misoriented_edge_count = c.misoriented_edges;
    out->nonmanifold_vertex_count = c.nonmanifold_vertices;
    out->unreferenced_vertex_count = c.unreferenced_vertices;
    out->degenerate_triangle_count = c.degenerate_triangles;
    out->sliver_triangle_count = c.sliver_triangles;
    out->component_count = c.components;
    out->euler_characteristic = c.euler_characteristic;
    out->volume = c.volume;
    out->area = c.area;
    out->min_angle_degrees = c.min_angle_degrees;
    return NBMC_OK;
  } catch (const std::bad_alloc&) {
    return NBMC_ERROR_OUT_OF_MEMORY;
  } catch (const nbmc::Error& e) {
    return e.status;
  } catch (const std::invalid_argument&) {
    return NBMC_ERROR_INVALID_ARGUMENT;
  } catch (...) {
    return NBMC_ERROR_INTERNAL;
  }
}

}  // extern "C"
