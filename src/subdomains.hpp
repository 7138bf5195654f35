// SPDX-License-Identifier: MIT
// One frame reconstructed as subdomains (docs/scale-out.md): in this process
// one after another (out-of-core: each fits a memory budget), or spread over
// MPI ranks (src/mpi/). Every subdomain runs the same pipeline on its
// particles and ghosts (backends/kokkos/pipeline.hpp, with a Region); the
// pieces are stitched into the mesh the whole frame gives, bit for bit.
#pragma once

#include "core/decomposition.hpp"
#include "core/piece.hpp"
#include "core/stitch.hpp"
#include "../backends/kokkos/pipeline.hpp"

#include <array>
#include <exception>
#include <cstdint>
#include <functional>
#include <map>
#include <set>
#include <vector>

namespace nbmc {

// Runs one subdomain on the context's backend (the caller's dispatch).
using RunRegion = std::function<void(const ParticleInput& in, const Params& p, HostMesh& mesh, RunStats& st)>;

// Exchange hooks between the processes that share a frame (MPI); in one
// process both are local.
struct SubdomainComm {
  // Sends (subdomain, cell x, y, z) records to the processes running those
  // subdomains; returns the records addressed to this process's subdomains.
  std::function<std::vector<std::array<std::int64_t, 4>>(const std::vector<std::array<std::int64_t, 4>>&)> exchange;
  // Logical OR over the processes.
  std::function<bool(bool)> any;
  // Error agreement: called by every process after each local phase with
  // what it threw (or null); throws the same error on every process when
  // any failed. In one process: rethrows.
  std::function<void(std::exception_ptr)> agree;
};

// Fills `xyz` with the positions (packed doubles) of the particles and ghosts
// of the i-th of `mine`, and with per-particle radii (p.radius_ref > 0)
// `radii` with theirs, in the same order (left empty otherwise).
using PackParticles = std::function<void(std::size_t i, std::vector<double>& xyz, std::vector<double>& radii)>;

// Runs the subdomains `mine` of d until no band growth crosses into
// a subdomain that has not seen it, and returns their pieces (indexed like
// `mine`). Stats of the runs are added to st; entries filled for `mine`.
std::vector<Piece> run_subdomain_job(const Decomposition& d, const Params& p, const std::vector<int>& mine,
                                     const PackParticles& particles,
                                     const RunRegion& run, const SubdomainComm& comm, RunStats& st,
                                     SubdomainReport& rep);

// The whole in-process path: splits (or, with `automatic`, decides whether
// and how to split under budget_bytes, into at least `at_least` pieces),
// runs, stitches into mesh. Returns false when `automatic` decided not to
// split (the caller then runs the frame whole, and calls again with
// at_least = 2 if that run fails with an error split_would_help accepts).
// radii: one per particle with per-particle radii (p.radius_ref > 0), else null.
bool reconstruct_subdomains(const SubdomainSetting& setting, std::uint64_t budget_bytes, const double* xyz,
                            const double* radii, std::size_t count, const Params& p, const RunRegion& run,
                            HostMesh& mesh, RunStats& st, SubdomainReport& rep, std::uint64_t at_least = 1);

// Whether splitting the frame (further) can get past error e: a memory
// budget, an allocation that failed, a per-run size limit.
inline bool split_would_help(const Error& e) {
  return e.split_helps || e.status == NBMC_ERROR_MEMORY_BUDGET || e.status == NBMC_ERROR_OUT_OF_MEMORY;
}

// Stitches pieces into a host mesh (normals when asked); the time in seconds.
StitchResult stitch_into(const std::vector<Piece>& pieces, bool normals, bool f64, HostMesh& mesh, double& seconds);

// Monotonic clock in seconds (the report's per-subdomain and stitch times).
double seconds_now();

// Merges a subdomain run's stats into the frame's (sums of the work done).
void add_run_stats(RunStats& total, const RunStats& one);

}  // namespace nbmc
