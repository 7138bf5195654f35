// SPDX-License-Identifier: MIT
// Every bad input and every misuse returns its documented status and a
// message; the context stays usable afterwards.
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

using namespace nbmc_test;

namespace {

struct Ctx {
  nbmc_context* c = nullptr;
  Ctx() {
    nbmc_context_desc d;
    nbmc_context_desc_init(&d);
    d.backend = NBMC_BACKEND_OPENMP;
    EXPECT_EQ(nbmc_context_create(&d, &c), NBMC_OK);
  }
  ~Ctx() { nbmc_context_destroy(c); }
  std::string error() const { return nbmc_context_last_error(c); }
};

const Points kSphere = sphere(0, 0, 0, 0.5, 0.1);

int32_t reconstruct_with(Ctx& ctx, const nbmc_params& p, nbmc_mesh** m) {
  EXPECT_EQ(nbmc_context_set_particles_f64(ctx.c, kSphere.data(), kSphere.size() / 3, 0), NBMC_OK);
  return nbmc_context_reconstruct(ctx.c, &p, m);
}

void expect_usable(Ctx& ctx) {
  nbmc_mesh* m = nullptr;
  ASSERT_EQ(reconstruct_with(ctx, params(0.1), &m), NBMC_OK) << ctx.error();
  EXPECT_GT(nbmc_mesh_triangle_count(m), 0u);
  EXPECT_STREQ(ctx.error().c_str(), "");
  nbmc_mesh_destroy(m);
}

}  // namespace

TEST(Version, MatchesHeader) {
  EXPECT_EQ(nbmc_version(), uint32_t(NBMC_VERSION));
  EXPECT_NE(std::string(nbmc_version_string()).find("openmp"), std::string::npos);
  EXPECT_STREQ(nbmc_status_string(NBMC_OK), "ok");
  EXPECT_STREQ(nbmc_status_string(12345), "unknown status");
  EXPECT_STREQ(nbmc_stage_name(NBMC_STAGE_FIELD), "field");
  // The host post-processing stage comes right after the pipeline's stages.
  EXPECT_STREQ(nbmc_stage_name(NBMC_STAGE_POSTPROCESS), "postprocess");
  EXPECT_STREQ(nbmc_stage_name(NBMC_STAGE_ATTRIBUTES), "attributes");
  EXPECT_EQ(nbmc_stage_name(NBMC_STAGE_ATTRIBUTES + 1), nullptr);
  EXPECT_EQ(nbmc_backend_available(NBMC_BACKEND_SERIAL), 1);
  EXPECT_EQ(nbmc_backend_available(NBMC_BACKEND_OPENMP), 1);
  EXPECT_EQ(nbmc_backend_available(99), 0);
}

TEST(BadInput, NaNAndInfPositions) {
  Ctx ctx;
  for (double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                     -std::numeric_limits<double>::infinity(), 1e30}) {
    Points p = kSphere;
    p[3 * 7 + 1] = bad;
    EXPECT_EQ(nbmc_context_set_particles_f64(ctx.c, p.data(), p.size() / 3, 0), NBMC_ERROR_INVALID_PARTICLES);
    EXPECT_NE(ctx.error().find("particle 7"), std::string::npos) << ctx.error();
  }
  std::vector<float> f(kSphere.begin(), kSphere.end());
  f[0] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(nbmc_context_set_particles_f32(ctx.c, f.data(), f.size() / 3, 0), NBMC_ERROR_INVALID_PARTICLES);
  // the rejected upload leaves no particles behind
  nbmc_params p = params(0.1);
  nbmc_mesh* m = nullptr;
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &p, &m), NBMC_ERROR_NO_PARTICLES);
  expect_usable(ctx);
}

TEST(BadInput, ZeroParticlesAndNoUpload) {
  Ctx ctx;
  nbmc_params p = params(0.1);
  nbmc_mesh* m = nullptr;
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &p, &m), NBMC_ERROR_NO_PARTICLES);
  EXPECT_NE(ctx.error().find("no particles"), std::string::npos);
  const double one[3] = {0, 0, 0};
  EXPECT_EQ(nbmc_context_set_particles_f64(ctx.c, one, 0, 0), NBMC_ERROR_NO_PARTICLES);
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &p, &m), NBMC_ERROR_NO_PARTICLES);
  nbmc_stats s;
  nbmc_stats_init(&s);
  EXPECT_EQ(nbmc_context_stats(ctx.c, &s), NBMC_ERROR_NO_PARTICLES);
  expect_usable(ctx);
}

TEST(BadInput, OneParticleAndCoincidentParticlesAreValid) {
  Ctx ctx;
  const double one[3] = {1, 2, 3};
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, one, 1, 0), NBMC_OK);
  nbmc_params p = params(0.1);
  nbmc_mesh* m = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(ctx.c, &p, &m), NBMC_OK) << ctx.error();
  EXPECT_GT(nbmc_mesh_triangle_count(m), 8u);  // a small closed sphere
  nbmc_mesh_destroy(m);
  std::vector<double> same(3000, 0.25);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, same.data(), 1000, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_reconstruct(ctx.c, &p, &m), NBMC_OK) << ctx.error();
  EXPECT_GT(nbmc_mesh_triangle_count(m), 8u);
  EXPECT_TRUE(check_mesh(Mesh{std::vector<float>(nbmc_mesh_positions(m), nbmc_mesh_positions(m) + 3 * nbmc_mesh_vertex_count(m)),
                              {},
                              std::vector<uint32_t>(nbmc_mesh_triangles(m), nbmc_mesh_triangles(m) + 3 * nbmc_mesh_triangle_count(m))})
                  .closed);
  nbmc_mesh_destroy(m);
}

TEST(BadInput, InvalidParameters) {
  Ctx ctx;
  struct Case {
    const char* name;
    void (*edit)(nbmc_params&);
    int32_t status;
    const char* message;
  };
  const Case cases[] = {
      {"spacing 0", [](nbmc_params& p) { p.spacing = 0; }, NBMC_ERROR_INVALID_PARAMETER, "spacing"},
      {"spacing < 0", [](nbmc_params& p) { p.spacing = -1; }, NBMC_ERROR_INVALID_PARAMETER, "spacing"},
      {"spacing NaN", [](nbmc_params& p) { p.spacing = std::nan(""); }, NBMC_ERROR_INVALID_PARAMETER, "spacing"},
      {"cell 0", [](nbmc_params& p) { p.cell_size = 0; }, NBMC_ERROR_INVALID_PARAMETER, "cell_size"},
      {"radius < 0", [](nbmc_params& p) { p.influence_radius = -4; }, NBMC_ERROR_INVALID_PARAMETER, "influence_radius"},
      {"band inf", [](nbmc_params& p) { p.band_width = INFINITY; }, NBMC_ERROR_INVALID_PARAMETER, "band_width"},
      {"iso >= R", [](nbmc_params& p) { p.iso_radius = 5; }, NBMC_ERROR_INVALID_PARAMETER, "iso_radius"},
      {"surface radius > 2R", [](nbmc_params& p) { p.surface_radius = 9; }, NBMC_ERROR_INVALID_PARAMETER,
       "surface_radius"},
      {"t_low >= t_high", [](nbmc_params& p) { p.t_low = 4; }, NBMC_ERROR_INVALID_PARAMETER, "t_low"},
      {"method", [](nbmc_params& p) { p.method = 7; }, NBMC_ERROR_INVALID_PARAMETER, "method"},
      {"field", [](nbmc_params& p) { p.field = -1; }, NBMC_ERROR_INVALID_PARAMETER, "field"},
      {"unit", [](nbmc_params& p) { p.length_unit = 3; }, NBMC_ERROR_INVALID_PARAMETER, "length_unit"},
      {"bbox inverted", [](nbmc_params& p) { p.use_bbox = 1; p.bbox_min[0] = 1; p.bbox_max[0] = 0; },
       NBMC_ERROR_INVALID_PARAMETER, "bounding box"},
      {"cell absurdly small", [](nbmc_params& p) { p.cell_size = 1e-4; }, NBMC_ERROR_DOMAIN_TOO_LARGE, "too small"},
      {"bbox without particles", [](nbmc_params& p) {
         p.use_bbox = 1;
         p.bbox_min[0] = p.bbox_min[1] = p.bbox_min[2] = 10;
         p.bbox_max[0] = p.bbox_max[1] = p.bbox_max[2] = 11;
       }, NBMC_ERROR_NO_PARTICLES, "bounding box"},
  };
  for (const Case& c : cases) {
    nbmc_params p = params(0.1);
    c.edit(p);
    nbmc_mesh* m = reinterpret_cast<nbmc_mesh*>(0x1);
    EXPECT_EQ(reconstruct_with(ctx, p, &m), c.status) << c.name << ": " << ctx.error();
    EXPECT_EQ(m, nullptr) << c.name;
    EXPECT_NE(ctx.error().find(c.message), std::string::npos) << c.name << ": " << ctx.error();
  }
  expect_usable(ctx);
}

TEST(BadInput, HugeDomainIsRejectedNotAllocated) {
  Ctx ctx;
  Points p = kSphere;
  p.insert(p.end(), {1e12, 0, 0});  // a particle a long way off: the grid cannot be indexed
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, p.data(), p.size() / 3, 0), NBMC_OK);
  nbmc_params prm = params(0.1);
  nbmc_mesh* m = nullptr;
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_ERROR_DOMAIN_TOO_LARGE);
  EXPECT_NE(ctx.error().find("grid vertices"), std::string::npos) << ctx.error();
  // With a bounding box around the bulk the same particles work.
  prm.use_bbox = 1;
  for (int a = 0; a < 3; ++a) {
    prm.bbox_min[a] = -1;
    prm.bbox_max[a] = 1;
  }
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_OK) << ctx.error();
  nbmc_mesh_destroy(m);
}

TEST(Misuse, NullPointersAndStructSizes) {
  EXPECT_EQ(nbmc_context_create(nullptr, nullptr), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_NE(std::string(nbmc_context_last_error(nullptr)).find("out is NULL"), std::string::npos);
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.struct_size = 4;
  nbmc_context* c = reinterpret_cast<nbmc_context*>(0x1);
  EXPECT_EQ(nbmc_context_create(&d, &c), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(c, nullptr);
  nbmc_context_desc_init(&d);
  d.backend = 17;
  EXPECT_EQ(nbmc_context_create(&d, &c), NBMC_ERROR_INVALID_ARGUMENT);
  nbmc_context_desc_init(&d);
  d.num_threads = -2;
  EXPECT_EQ(nbmc_context_create(&d, &c), NBMC_ERROR_INVALID_ARGUMENT);
  nbmc_context_desc_init(&d);
  d.backend = NBMC_BACKEND_CUDA;
  if (!nbmc_backend_available(NBMC_BACKEND_CUDA)) {
    EXPECT_EQ(nbmc_context_create(&d, &c), NBMC_ERROR_BACKEND_UNAVAILABLE);
    EXPECT_NE(std::string(nbmc_context_last_error(nullptr)).find("cuda"), std::string::npos);
  }

  Ctx ctx;
  nbmc_params p = params(0.1);
  nbmc_mesh* m = nullptr;
  EXPECT_EQ(nbmc_context_set_particles_f64(nullptr, kSphere.data(), 1, 0), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_set_particles_f64(ctx.c, nullptr, 1, 0), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_set_particles_f64(ctx.c, kSphere.data(), 1, 8), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_reconstruct(nullptr, &p, &m), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, nullptr, &m), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &p, nullptr), NBMC_ERROR_INVALID_ARGUMENT);
  nbmc_params small = p;
  small.struct_size = 8;
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &small, &m), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_NE(ctx.error().find("struct_size"), std::string::npos);
  EXPECT_EQ(nbmc_context_stats(ctx.c, nullptr), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_backend(nullptr, nullptr), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_set_progress(nullptr, nullptr, nullptr), NBMC_ERROR_INVALID_ARGUMENT);
  // NULL handles are no-ops / zero.
  nbmc_context_destroy(nullptr);
  nbmc_mesh_destroy(nullptr);
  EXPECT_EQ(nbmc_mesh_vertex_count(nullptr), 0u);
  EXPECT_EQ(nbmc_mesh_triangle_count(nullptr), 0u);
  EXPECT_EQ(nbmc_mesh_positions(nullptr), nullptr);
  EXPECT_EQ(nbmc_mesh_normals(nullptr), nullptr);
  EXPECT_EQ(nbmc_mesh_triangles(nullptr), nullptr);
  nbmc_params_init(nullptr);
  nbmc_stats_init(nullptr);
  nbmc_context_desc_init(nullptr);
  expect_usable(ctx);
}

TEST(Misuse, StridedUploadsMatchPackedOnes) {
  // [x, y, z, extra] records (stride 32 bytes for doubles, 16 for floats).
  std::vector<double> rec;
  std::vector<float> recf;
  for (std::size_t i = 0; i < kSphere.size() / 3; ++i) {
    rec.insert(rec.end(), {kSphere[3 * i], kSphere[3 * i + 1], kSphere[3 * i + 2], -1.0});
    recf.insert(recf.end(), {float(kSphere[3 * i]), float(kSphere[3 * i + 1]), float(kSphere[3 * i + 2]), 7.f});
  }
  Ctx a, b, c;
  nbmc_params p = params(0.1);
  nbmc_mesh *ma = nullptr, *mb = nullptr, *mc = nullptr;
  ASSERT_EQ(nbmc_context_set_particles_f64(a.c, kSphere.data(), kSphere.size() / 3, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_particles_f64(b.c, rec.data(), kSphere.size() / 3, 32), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_particles_f32(c.c, recf.data(), kSphere.size() / 3, 16), NBMC_OK);
  ASSERT_EQ(nbmc_context_reconstruct(a.c, &p, &ma), NBMC_OK);
  ASSERT_EQ(nbmc_context_reconstruct(b.c, &p, &mb), NBMC_OK);
  ASSERT_EQ(nbmc_context_reconstruct(c.c, &p, &mc), NBMC_OK);
  ASSERT_EQ(nbmc_mesh_triangle_count(ma), nbmc_mesh_triangle_count(mb));
  EXPECT_EQ(0, std::memcmp(nbmc_mesh_positions(ma), nbmc_mesh_positions(mb), 12 * nbmc_mesh_vertex_count(ma)));
  EXPECT_EQ(nbmc_mesh_triangle_count(ma), nbmc_mesh_triangle_count(mc));  // float input: same shape
  nbmc_mesh_destroy(ma);
  nbmc_mesh_destroy(mb);
  // A mesh outlives its context.
  nbmc_context_destroy(c.c);
  c.c = nullptr;
  EXPECT_GT(nbmc_mesh_triangle_count(mc), 0u);
  EXPECT_NE(nbmc_mesh_positions(mc), nullptr);
  nbmc_mesh_destroy(mc);
}

TEST(Progress, ReportsStagesAndCancels) {
  Ctx ctx;
  struct State {
    int calls = 0, last_stage = -1;
    bool monotone = true;
    int cancel_at_stage = -1;
  } st;
  auto cb = [](void* user, int32_t stage, double f) -> int32_t {
    State& s = *static_cast<State*>(user);
    ++s.calls;
    if (stage < s.last_stage || f < 0 || f > 1) s.monotone = false;
    s.last_stage = stage;
    return stage == s.cancel_at_stage ? 1 : 0;
  };
  ASSERT_EQ(nbmc_context_set_progress(ctx.c, cb, &st), NBMC_OK);
  nbmc_mesh* m = nullptr;
  ASSERT_EQ(reconstruct_with(ctx, params(0.1), &m), NBMC_OK);
  EXPECT_GT(st.calls, NBMC_STAGE_COUNT);
  EXPECT_TRUE(st.monotone);
  EXPECT_EQ(st.last_stage, NBMC_STAGE_OUTPUT);
  nbmc_mesh_destroy(m);
  st = State{};
  st.cancel_at_stage = NBMC_STAGE_FIELD;
  EXPECT_EQ(reconstruct_with(ctx, params(0.1), &m), NBMC_ERROR_CANCELLED);
  EXPECT_EQ(m, nullptr);
  EXPECT_NE(ctx.error().find("cancel"), std::string::npos);
  ASSERT_EQ(nbmc_context_set_progress(ctx.c, nullptr, nullptr), NBMC_OK);
  expect_usable(ctx);
}

// Device memory (NBMC_MEMORY_DEVICE, nbmc_context_set_particles_device_*)
// needs the CUDA backend; on a CPU backend the calls fail cleanly and leave
// the context usable. Host meshes say where they live and copy out exactly
// what the getters show. (The CUDA side: tests/gpu/device_pointers.cpp.)
TEST(DeviceMemory, NeedsTheCudaBackend) {
  Ctx ctx;
  float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  EXPECT_EQ(nbmc_context_set_particles_device_f32(ctx.c, xyz, 3, 0), NBMC_ERROR_BACKEND_UNAVAILABLE);
  EXPECT_NE(ctx.error().find("CUDA"), std::string::npos) << ctx.error();
  double dxyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  EXPECT_EQ(nbmc_context_set_particles_device_f64(ctx.c, dxyz, 3, 0), NBMC_ERROR_BACKEND_UNAVAILABLE);
  nbmc_mesh* m = nullptr;
  const nbmc_params p = params(0.1);
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &p, &m), NBMC_ERROR_NO_PARTICLES);  // the failed upload kept nothing
  EXPECT_EQ(nbmc_context_set_mesh_memory(ctx.c, NBMC_MEMORY_DEVICE), NBMC_ERROR_BACKEND_UNAVAILABLE);
  EXPECT_EQ(nbmc_context_set_mesh_memory(ctx.c, 7), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_set_mesh_memory(ctx.c, NBMC_MEMORY_HOST), NBMC_OK);
  EXPECT_EQ(nbmc_context_set_mesh_memory(nullptr, NBMC_MEMORY_HOST), NBMC_ERROR_INVALID_ARGUMENT);
  expect_usable(ctx);
}

TEST(DeviceMemory, HostMeshCopiesOutWhatTheGettersShow) {
  Ctx ctx;
  nbmc_mesh* m = nullptr;
  ASSERT_EQ(reconstruct_with(ctx, params(0.1), &m), NBMC_OK) << ctx.error();
  EXPECT_EQ(nbmc_mesh_memory(m), NBMC_MEMORY_HOST);
  EXPECT_EQ(nbmc_mesh_memory(nullptr), NBMC_MEMORY_HOST);
  const std::size_t nv = nbmc_mesh_vertex_count(m), nt = nbmc_mesh_triangle_count(m);
  ASSERT_GT(nt, 0u);
  std::vector<float> pos(3 * nv, -1.f), nrm(3 * nv, -1.f);
  std::vector<uint32_t> tri(3 * nt, 0xffffffffu);
  ASSERT_EQ(nbmc_mesh_copy_to_host(m, pos.data(), nrm.data(), tri.data()), NBMC_OK);
  EXPECT_EQ(std::memcmp(pos.data(), nbmc_mesh_positions(m), pos.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(nrm.data(), nbmc_mesh_normals(m), nrm.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(tri.data(), nbmc_mesh_triangles(m), tri.size() * sizeof(uint32_t)), 0);
  EXPECT_EQ(nbmc_mesh_copy_to_host(m, nullptr, nullptr, nullptr), NBMC_OK);
  EXPECT_EQ(nbmc_mesh_copy_to_host(nullptr, pos.data(), nullptr, nullptr), NBMC_ERROR_INVALID_ARGUMENT);
  nbmc_mesh_destroy(m);
}

// Large uploads are validated in parallel; the message still names the first
// bad particle and counts every bad coordinate, whatever the thread count.
TEST(BadInput, ParallelValidationNamesTheFirstBadParticle) {
  for (int threads : {1, 2, 3}) {
    nbmc_context_desc d;
    nbmc_context_desc_init(&d);
    d.backend = NBMC_BACKEND_OPENMP;
    d.num_threads = threads;
    nbmc_context* c = nullptr;
    ASSERT_EQ(nbmc_context_create(&d, &c), NBMC_OK);
    std::vector<float> xyz(3 * 300000, 1.0f);
    xyz[3 * 250001 + 2] = std::numeric_limits<float>::infinity();
    xyz[3 * 123457 + 0] = std::numeric_limits<float>::quiet_NaN();
    xyz[3 * 123457 + 1] = 2e15f;
    EXPECT_EQ(nbmc_context_set_particles_f32(c, xyz.data(), 300000, 0), NBMC_ERROR_INVALID_PARTICLES);
    const std::string msg = nbmc_context_last_error(c);
    EXPECT_NE(msg.find("3 coordinate(s)"), std::string::npos) << msg;
    EXPECT_NE(msg.find("first at particle 123457"), std::string::npos) << msg;
    nbmc_context_destroy(c);
  }
}
