// SPDX-License-Identifier: MIT
//! Raw, hand-written declarations of the nbmc C ABI (`include/nbmc.h`).
//!
//! Everything here mirrors the header one to one: the opaque handles, the
//! `#[repr(C)]` structs, every `NBMC_*` constant and every `nbmc_*` function.
//! `tests/layout.rs` compiles a C program against the real header and checks
//! sizes, field offsets, constant values and function signatures, so a change
//! to the header that is not mirrored here fails `cargo test`.
//!
//! Use the `nbmc` crate for a safe API.
#![allow(non_camel_case_types)]

// std::os::raw rather than core::ffi (and no #![no_std]): core::ffi::c_char
// needs Rust 1.64, and the crates build with Debian 12's rustc 1.63.
use std::os::raw::{c_char, c_void};

// ------------------------------------------------------------------ version
pub const NBMC_VERSION_MAJOR: u32 = 0;
pub const NBMC_VERSION_MINOR: u32 = 1;
pub const NBMC_VERSION_PATCH: u32 = 0;
pub const NBMC_VERSION: u32 = NBMC_VERSION_MAJOR * 10000 + NBMC_VERSION_MINOR * 100 + NBMC_VERSION_PATCH;

// ------------------------------------------------------------------- status
pub const NBMC_OK: i32 = 0;
pub const NBMC_ERROR_INVALID_ARGUMENT: i32 = 1;
pub const NBMC_ERROR_INVALID_PARTICLES: i32 = 2;
pub const NBMC_ERROR_NO_PARTICLES: i32 = 3;
pub const NBMC_ERROR_INVALID_PARAMETER: i32 = 4;
pub const NBMC_ERROR_DOMAIN_TOO_LARGE: i32 = 5;
pub const NBMC_ERROR_OUT_OF_MEMORY: i32 = 6;
pub const NBMC_ERROR_BACKEND_UNAVAILABLE: i32 = 7;
pub const NBMC_ERROR_IO: i32 = 8;
pub const NBMC_ERROR_INTERNAL: i32 = 9;
pub const NBMC_ERROR_MEMORY_BUDGET: i32 = 10;
pub const NBMC_ERROR_CANCELLED: i32 = 11;
pub const NBMC_ERROR_FORMAT: i32 = 12;

// ---------------------------------------------------------------- constants
pub const NBMC_BACKEND_AUTO: i32 = 0;
pub const NBMC_BACKEND_SERIAL: i32 = 1;
pub const NBMC_BACKEND_OPENMP: i32 = 2;
pub const NBMC_BACKEND_CUDA: i32 = 3;

pub const NBMC_METHOD_SSP07: i32 = 0;
pub const NBMC_METHOD_ZB05: i32 = 1;
pub const NBMC_METHOD_SPH: i32 = 2;
pub const NBMC_METHOD_YT10: i32 = 3;

pub const NBMC_ISOLATED_KEEP: i32 = 0;
pub const NBMC_ISOLATED_DROP: i32 = 1;
pub const NBMC_ISOLATED_SPHERE: i32 = 2;

pub const NBMC_SMOOTH_UNIFORM: i32 = 0;
pub const NBMC_SMOOTH_FEATURE: i32 = 1;

pub const NBMC_FIELD_NARROW_BAND: i32 = 0;
pub const NBMC_FIELD_DENSE: i32 = 1;
pub const NBMC_FIELD_SCATTER: i32 = 2;

/// Context flag: initialise Kokkos on the calling thread (see nbmc.h).
pub const NBMC_CONTEXT_KOKKOS_ON_CALLING_THREAD: u32 = 1;

/// Where arrays handed to or returned by nbmc live: ordinary host memory (default).
pub const NBMC_MEMORY_HOST: i32 = 0;
/// CUDA memory of the context's GPU (CUDA backend only).
pub const NBMC_MEMORY_DEVICE: i32 = 1;

pub const NBMC_UNIT_SPACING: i32 = 0;
pub const NBMC_UNIT_ABSOLUTE: i32 = 1;

pub const NBMC_STAGE_UPLOAD: i32 = 0;
pub const NBMC_STAGE_NEIGHBOURHOOD: i32 = 1;
pub const NBMC_STAGE_SURFACE_PARTICLES: i32 = 2;
pub const NBMC_STAGE_BAND: i32 = 3;
pub const NBMC_STAGE_FIELD: i32 = 4;
pub const NBMC_STAGE_TRIANGULATION: i32 = 5;
pub const NBMC_STAGE_OUTPUT: i32 = 6;
pub const NBMC_STAGE_COUNT: i32 = 7;
pub const NBMC_STAGE_SLOTS: usize = 16;
pub const NBMC_STAGE_POSTPROCESS: i32 = 7;
pub const NBMC_STAGE_ATTRIBUTES: i32 = 8;
pub const NBMC_SUBDOMAINS_AUTO: i32 = -1;

// ------------------------------------------------------------- opaque types
/// `nbmc_context`: never constructed in Rust, only pointed to.
#[repr(C)]
pub struct nbmc_context {
    _opaque: [u8; 0],
    // Not Send, Sync or Unpin: a raw handle carries no guarantees.
    _marker: core::marker::PhantomData<(*mut u8, core::marker::PhantomPinned)>,
}

/// `nbmc_mesh`: never constructed in Rust, only pointed to.
#[repr(C)]
pub struct nbmc_mesh {
    _opaque: [u8; 0],
    _marker: core::marker::PhantomData<(*mut u8, core::marker::PhantomPinned)>,
}

// ------------------------------------------------------------------ structs
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct nbmc_context_desc {
    pub struct_size: u32,
    pub backend: i32,
    pub num_threads: i32,
    pub device_id: i32,
    pub flags: u32,
    pub reserved0: u32,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct nbmc_params {
    pub struct_size: u32,
    pub length_unit: i32,
    pub spacing: f64,
    pub cell_size: f64,
    pub influence_radius: f64,
    pub band_width: f64,
    pub surface_radius: f64,
    pub iso_radius: f64,
    pub method: i32,
    pub field: i32,
    pub t_low: f64,
    pub t_high: f64,
    pub color_threshold: f64,
    pub neighbour_threshold: i32,
    pub compute_normals: i32,
    pub use_bbox: i32,
    pub reserved0: i32,
    pub bbox_min: [f64; 3],
    pub bbox_max: [f64; 3],
    // appended with the mesh post-processing
    pub cleanup: i32,
    pub smooth_iterations: i32,
    // appended with NBMC_METHOD_SPH
    pub iso_threshold: f64,
    // appended with the isolated-particle filter
    pub isolated: i32,
    pub min_cluster: i32,
    // appended with double-precision positions
    pub double_positions: i32,
    // appended with decimation and feature-weighted smoothing
    pub decimate_fraction: f64,
    pub smooth_weighting: i32,
    pub reserved1: i32,
    // appended with NBMC_METHOD_YT10
    pub aniso_kr: f64,
    pub aniso_ks: f64,
    pub aniso_kn: f64,
    pub aniso_lambda: f64,
    pub aniso_neighbours: i32,
    pub reserved2: i32,
    // appended with the distance guard
    pub max_distance: f64,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct nbmc_stats {
    pub struct_size: u32,
    pub reserved0: u32,
    pub particle_count: u64,
    pub surface_particle_count: u64,
    pub occupied_cell_count: u64,
    pub band_vertex_count: u64,
    pub band_block_count: u64,
    pub grid_vertex_count: u64,
    pub triangulated_cell_count: u64,
    pub vertex_count: u64,
    pub triangle_count: u64,
    pub grid_dims: [u64; 3],
    pub peak_memory_bytes: u64,
    pub neighbour_evaluations: u64,
    pub stage_seconds: [f64; NBMC_STAGE_SLOTS],
    pub total_seconds: f64,
    pub grid_origin: [f64; 3],
    pub cell_size: f64,
    // appended with the mesh post-processing
    pub raw_triangle_count: u64,
    pub smoothing_volume_change: f64,
    // appended with the isolated-particle filter
    pub dropped_particle_count: u64,
    pub dropped_cluster_count: u64,
    // appended with decimation
    pub pre_decimation_triangle_count: u64,
    // appended with the clean-up's counts
    pub cleanup_bad_triangles_before: u64,
    pub cleanup_bad_triangles_after: u64,
    pub cleanup_moves: u64,
    pub cleanup_flips: u64,
    pub cleanup_collapses: u64,
    pub cleanup_cuts: u64,
    pub cleanup_removed_component_triangles: u64,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct nbmc_mesh_check_result {
    pub struct_size: u32,
    pub closed: i32,
    pub manifold: i32,
    pub oriented: i32,
    pub vertex_count: u64,
    pub triangle_count: u64,
    pub edge_count: u64,
    pub boundary_edge_count: u64,
    pub nonmanifold_edge_count: u64,
    pub misoriented_edge_count: u64,
    pub nonmanifold_vertex_count: u64,
    pub unreferenced_vertex_count: u64,
    pub degenerate_triangle_count: u64,
    pub sliver_triangle_count: u64,
    pub component_count: u64,
    pub euler_characteristic: i64,
    pub volume: f64,
    pub area: f64,
    pub min_angle_degrees: f64,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct nbmc_subdomain_stats {
    pub struct_size: u32,
    pub parts: [i32; 3],
    pub count: u64,
    pub automatic: u32,
    pub reserved: u32,
    pub ghost_width: f64,
    pub ghost_particles: u64,
    pub reruns: u64,
    pub exchanged_cells: u64,
    pub shared_vertices: u64,
    pub budget_bytes: u64,
    pub stitch_seconds: f64,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct nbmc_subdomain_entry {
    pub struct_size: u32,
    pub coord: [i32; 3],
    pub cell_lo: [i64; 3],
    pub cell_hi: [i64; 3],
    pub particles: u64,
    pub ghost_particles: u64,
    pub vertex_count: u64,
    pub triangle_count: u64,
    pub runs: u32,
    pub rank: i32,
    pub seconds: f64,
}

/// `int32_t (*)(void* user, int32_t stage, double fraction)`; `None` is NULL.
/// The callback must not unwind: catch panics before returning to C.
pub type nbmc_progress_fn = Option<unsafe extern "C" fn(user: *mut c_void, stage: i32, fraction: f64) -> i32>;

// ---------------------------------------------------------------- functions
extern "C" {
    // version
    pub fn nbmc_version() -> u32;
    pub fn nbmc_version_string() -> *const c_char;
    pub fn nbmc_status_string(status: i32) -> *const c_char;
    pub fn nbmc_stage_name(stage: i32) -> *const c_char;
    pub fn nbmc_backend_available(backend: i32) -> i32;

    // context
    pub fn nbmc_context_desc_init(desc: *mut nbmc_context_desc);
    pub fn nbmc_context_create(desc: *const nbmc_context_desc, out: *mut *mut nbmc_context) -> i32;
    pub fn nbmc_context_destroy(ctx: *mut nbmc_context);
    pub fn nbmc_context_last_error(ctx: *const nbmc_context) -> *const c_char;
    pub fn nbmc_context_backend(ctx: *const nbmc_context, backend: *mut i32) -> i32;
    pub fn nbmc_context_set_particles_f32(ctx: *mut nbmc_context, xyz: *const f32, count: u64, byte_stride: u64)
        -> i32;
    pub fn nbmc_context_set_particles_f64(ctx: *mut nbmc_context, xyz: *const f64, count: u64, byte_stride: u64)
        -> i32;
    // `xyz` is CUDA device memory of the context's GPU (CUDA backend only).
    pub fn nbmc_context_set_particles_device_f32(
        ctx: *mut nbmc_context,
        xyz: *const f32,
        count: u64,
        byte_stride: u64,
    ) -> i32;
    pub fn nbmc_context_set_particles_device_f64(
        ctx: *mut nbmc_context,
        xyz: *const f64,
        count: u64,
        byte_stride: u64,
    ) -> i32;
    pub fn nbmc_context_set_mesh_memory(ctx: *mut nbmc_context, memory: i32) -> i32;
    pub fn nbmc_context_set_progress(ctx: *mut nbmc_context, fn_: nbmc_progress_fn, user: *mut c_void) -> i32;
    pub fn nbmc_context_set_memory_budget(ctx: *mut nbmc_context, bytes: u64) -> i32;

    // parameters
    pub fn nbmc_params_init(params: *mut nbmc_params);

    // reconstruct
    pub fn nbmc_context_reconstruct(
        ctx: *mut nbmc_context,
        params: *const nbmc_params,
        mesh: *mut *mut nbmc_mesh,
    ) -> i32;
    pub fn nbmc_stats_init(stats: *mut nbmc_stats);
    pub fn nbmc_context_stats(ctx: *const nbmc_context, stats: *mut nbmc_stats) -> i32;

    // mesh
    pub fn nbmc_mesh_vertex_count(mesh: *const nbmc_mesh) -> u64;
    pub fn nbmc_mesh_triangle_count(mesh: *const nbmc_mesh) -> u64;
    pub fn nbmc_mesh_positions(mesh: *const nbmc_mesh) -> *const f32;
    pub fn nbmc_mesh_normals(mesh: *const nbmc_mesh) -> *const f32;
    pub fn nbmc_mesh_triangles(mesh: *const nbmc_mesh) -> *const u32;
    pub fn nbmc_mesh_destroy(mesh: *mut nbmc_mesh);
    // double_positions: 3 * vertex_count doubles; null for a float mesh.
    pub fn nbmc_mesh_positions_f64(mesh: *const nbmc_mesh) -> *const f64;
    // NBMC_MEMORY_DEVICE: the three getters above return CUDA device pointers.
    pub fn nbmc_mesh_memory(mesh: *const nbmc_mesh) -> i32;
    pub fn nbmc_mesh_copy_to_host(
        mesh: *const nbmc_mesh,
        positions: *mut f32,
        normals: *mut f32,
        triangles: *mut u32,
    ) -> i32;

    // file I/O
    pub fn nbmc_context_load_particles(
        ctx: *mut nbmc_context,
        path: *const c_char,
        format: *const c_char,
        count_out: *mut u64,
    ) -> i32;
    pub fn nbmc_mesh_write(mesh: *const nbmc_mesh, path: *const c_char, format: *const c_char) -> i32;
    pub fn nbmc_last_error() -> *const c_char;

    // Kokkos
    pub fn nbmc_kokkos_finalize() -> i32;

    // mesh post-processing
    pub fn nbmc_mesh_check_result_init(result: *mut nbmc_mesh_check_result);
    pub fn nbmc_mesh_check(mesh: *const nbmc_mesh, result: *mut nbmc_mesh_check_result) -> i32;

    // subdomains, pieces of MPI reconstructions
    pub fn nbmc_context_set_subdomains(ctx: *mut nbmc_context, nx: i32, ny: i32, nz: i32) -> i32;
    pub fn nbmc_subdomain_stats_init(out: *mut nbmc_subdomain_stats);
    pub fn nbmc_subdomain_entry_init(out: *mut nbmc_subdomain_entry);
    pub fn nbmc_context_subdomain_stats(ctx: *const nbmc_context, out: *mut nbmc_subdomain_stats) -> i32;
    pub fn nbmc_context_subdomain_entry(ctx: *const nbmc_context, i: u64, out: *mut nbmc_subdomain_entry) -> i32;
    pub fn nbmc_mesh_global_vertex_ids(mesh: *const nbmc_mesh) -> *const u64;
    pub fn nbmc_mesh_global_vertex_count(mesh: *const nbmc_mesh) -> u64;

    // particle attributes (`data` NULL removes the attribute `name`)
    pub fn nbmc_context_set_attribute_f32(
        ctx: *mut nbmc_context,
        name: *const c_char,
        data: *const f32,
        components: u32,
        byte_stride: u64,
    ) -> i32;
    pub fn nbmc_context_set_attribute_f64(
        ctx: *mut nbmc_context,
        name: *const c_char,
        data: *const f64,
        components: u32,
        byte_stride: u64,
    ) -> i32;
    // `data` is CUDA device memory of the context's GPU (CUDA backend only).
    pub fn nbmc_context_set_attribute_device_f32(
        ctx: *mut nbmc_context,
        name: *const c_char,
        data: *const f32,
        components: u32,
        byte_stride: u64,
    ) -> i32;
    pub fn nbmc_context_set_attribute_device_f64(
        ctx: *mut nbmc_context,
        name: *const c_char,
        data: *const f64,
        components: u32,
        byte_stride: u64,
    ) -> i32;
    pub fn nbmc_mesh_attribute_count(mesh: *const nbmc_mesh) -> u32;
    pub fn nbmc_mesh_attribute_name(mesh: *const nbmc_mesh, i: u32) -> *const c_char;
    // Host memory for every mesh (also one in device memory).
    pub fn nbmc_mesh_attribute(mesh: *const nbmc_mesh, name: *const c_char, components: *mut u32) -> *const f32;

    // isolated particles as spheres (NBMC_ISOLATED_SPHERE): 4 floats each
    // (x, y, z, radius), host memory; null when there are none.
    pub fn nbmc_mesh_sphere_count(mesh: *const nbmc_mesh) -> u64;
    pub fn nbmc_mesh_spheres(mesh: *const nbmc_mesh) -> *const f32;
    // per-particle radii (`radii` NULL removes them; count = the particle count)
    pub fn nbmc_context_set_radii_f32(ctx: *mut nbmc_context, radii: *const f32, count: u64, byte_stride: u64) -> i32;
    pub fn nbmc_context_set_radii_f64(ctx: *mut nbmc_context, radii: *const f64, count: u64, byte_stride: u64) -> i32;
    // `radii` is CUDA device memory of the context's GPU (CUDA backend only).
    pub fn nbmc_context_set_radii_device_f32(
        ctx: *mut nbmc_context,
        radii: *const f32,
        count: u64,
        byte_stride: u64,
    ) -> i32;
    pub fn nbmc_context_set_radii_device_f64(
        ctx: *mut nbmc_context,
        radii: *const f64,
        count: u64,
        byte_stride: u64,
    ) -> i32;
}

/// include/nbmc_mpi.h (feature `mpi`, links libnbmc_mpi): one frame over the
/// ranks of an MPI communicator. The communicator crosses as its Fortran
/// handle (`MPI_Comm_c2f` of the C handle, an `i32` in every MPI library),
/// or, with `nbmc_mpi_context_set_comm`, as the C handle itself, whose type
/// depends on the MPI library (a pointer in Open MPI, an `int` in MPICH):
/// `MpiComm` is Open MPI's.
#[cfg(feature = "mpi")]
pub mod mpi {
    use super::{nbmc_context, nbmc_mesh, nbmc_params};
    use core::ffi::c_void;

    pub const NBMC_MPI_GATHER: i32 = 0;
    pub const NBMC_MPI_PIECES: i32 = 1;

    /// Open MPI's `MPI_Comm` (an opaque pointer).
    pub type MpiComm = *mut c_void;

    extern "C" {
        // comm: an MpiComm (Open MPI)
        pub fn nbmc_mpi_context_set_comm(ctx: *mut nbmc_context, comm: *mut c_void) -> i32;
        pub fn nbmc_mpi_context_set_comm_f(ctx: *mut nbmc_context, fortran_comm: i32) -> i32;
        pub fn nbmc_mpi_reconstruct(
            ctx: *mut nbmc_context,
            params: *const nbmc_params,
            output: i32,
            root: i32,
            mesh: *mut *mut nbmc_mesh,
        ) -> i32;
        pub fn nbmc_mpi_context_rank(ctx: *const nbmc_context) -> i32;
        pub fn nbmc_mpi_context_size(ctx: *const nbmc_context) -> i32;
    }
}
