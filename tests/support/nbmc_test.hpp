// SPDX-License-Identifier: MIT
// Test helpers: particle lattices of analytic shapes, a C-API runner, and a
// mesh checker (closed, manifold, oriented, components; splashsurf's
// check_mesh_consistency in spirit).
#pragma once

#include "nbmc.h"

#include <array>
#include <cstdint>
#include <functional>
#include <set>
#include <string>
#include <vector>

namespace nbmc_test {

using Points = std::vector<double>;  // x, y, z per particle

// Cubic lattice of spacing r over [lo, hi] keeping points where inside(x,y,z).
Points lattice(const double lo[3], const double hi[3], double r,
               const std::function<bool(double, double, double)>& inside);
Points sphere(double cx, double cy, double cz, double radius, double r);
Points box(const double lo[3], const double hi[3], double r);
Points torus(double R, double a, double r);  // around the z axis at the origin
Points concat(const Points& a, const Points& b);
Points read_xyz(const std::string& path);  // raw float32 triples

struct Mesh {
  std::vector<float> positions, normals;
  std::vector<std::uint32_t> triangles;
  std::size_t vertex_count() const { return positions.size() / 3; }
  std::size_t triangle_count() const { return triangles.size() / 3; }
};

struct Result {
  int32_t status = -1;
  std::string message;
  Mesh mesh;
  nbmc_stats stats{};
};

// Default parameters with the given spacing (relative units).
nbmc_params params(double spacing);
// Reconstructs on a fresh context (backend, threads).
Result reconstruct(const Points& p, const nbmc_params& prm, int32_t backend = NBMC_BACKEND_OPENMP, int threads = 0);

struct MeshReport {
  bool closed = false;          // every edge shared by exactly two triangles
  bool edge_manifold = false;   // no edge shared by more than two triangles
  bool vertex_manifold = false; // the triangles around every vertex form one fan
  bool oriented = false;        // each shared edge used in opposite directions
  std::size_t boundary_edges = 0, nonmanifold_edges = 0, misoriented_edges = 0, nonmanifold_vertices = 0;
  std::size_t degenerate_triangles = 0, unreferenced_vertices = 0;
  std::size_t components = 0;   // connected through shared edges
  double volume = 0;            // signed (positive when oriented outward)
  double area = 0;
  std::string summary() const;
};
MeshReport check_mesh(const Mesh& m);

// A mesh's triangles as vertex-position triples, each rotated so that its
// smallest vertex comes first (which keeps the orientation): compares meshes
// whose vertices are numbered differently.
using Tri = std::array<float, 9>;
std::set<Tri> triangle_set(const Mesh& m);

}  // namespace nbmc_test
