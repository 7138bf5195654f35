! SPDX-License-Identifier: MIT
!
! Fortran 2008 bindings of the nbmc C ABI (include/nbmc.h).
!
! The C functions are private bind(c) interfaces; the public procedures take
! Fortran strings, logicals and arrays. Handles are derived types holding a
! type(c_ptr); nbmc_context_close / nbmc_mesh_close free them and null them,
! and closing a null handle is a no-op.
!
!   use nbmc
!   type(nbmc_context) :: ctx
!   type(nbmc_mesh)    :: mesh
!   type(nbmc_params)  :: params
!   real(c_double)     :: pos(3, n)     ! x, y, z of particle i in pos(:, i)
!   if (nbmc_context_create(ctx) /= NBMC_OK) print *, nbmc_context_last_error(ctx)
!   status = nbmc_context_set_particles(ctx, pos)            ! copies
!   call nbmc_params_init(params, spacing=0.05d0)
!   status = nbmc_context_reconstruct(ctx, params, mesh)
!   ! nbmc_mesh_positions(mesh) is a real(c_float) pointer (3, nv) into the mesh,
!   ! nbmc_mesh_triangles(mesh) an integer(c_int32_t) pointer (3, nt) of 0-based
!   ! vertex indices; both are valid until nbmc_mesh_close(mesh).
!   call nbmc_mesh_close(mesh)
!   call nbmc_context_close(ctx)
!
! Per-particle data (after each upload, which removes earlier attributes):
!   status = nbmc_context_set_attribute(ctx, 'velocity', vel)   ! vel(3, n) or rho(n), real32/64
!   status = nbmc_context_reconstruct(ctx, params, mesh)
!   a => nbmc_mesh_attribute(mesh, 'velocity', comps)        ! real(c_float) (comps, nv), host memory
! The module checks that the array has one item per particle of the last
! upload made through it (ctx%particles).
!
! Per-particle radii (variable-resolution particles; also removed by every
! upload), radii(n) real32/64, absolute: a radius is a particle's r, the
! spacing it would have in a uniform frame (docs/api.md):
!   status = nbmc_context_set_radii(ctx, radii)
!   status = nbmc_context_clear_radii(ctx)
!
! Names follow the C API; nbmc_version() is nbmc_library_version() here (Fortran
! is case-insensitive and NBMC_VERSION is the constant), nbmc_*_destroy are
! nbmc_*_close.
!
! C's uint32_t and uint64_t map to integer(c_int32_t) and integer(c_int64_t):
! the values nbmc produces stay below 2**31 and 2**63.
!
! GPU solvers (CUDA backend only; other backends return
! NBMC_ERROR_BACKEND_UNAVAILABLE). Device arrays travel as type(c_ptr):
!
!   ! OpenACC: inside host_data use_device, c_loc gives the device address
!   !$acc host_data use_device(pos)
!   status = nbmc_context_set_particles_device_f64(ctx, c_loc(pos), &
!                                                  size(pos, 2, kind=c_int64_t), 0_c_int64_t)
!   !$acc end host_data
!
!   ! CUDA Fortran: real(c_double), device :: pos_d(3, n)
!   status = nbmc_context_set_particles_device_f64(ctx, transfer(c_devloc(pos_d), c_null_ptr), n64, 0_c_int64_t)
!
! The call returns when nbmc has its own copy. byte_stride is in bytes as for
! host uploads (pos_d(6, n) with x, y, z first: 6 * 8). With
! status = nbmc_context_set_mesh_memory(ctx, NBMC_MEMORY_DEVICE) later meshes
! stay on the GPU: nbmc_mesh_memory(mesh) is then NBMC_MEMORY_DEVICE, the
! Fortran-pointer getters nbmc_mesh_positions/_normals/_triangles return
! unassociated pointers (host code must not touch device memory), and
! nbmc_mesh_c_arrays gives the device addresses (CUDA Fortran: turn them into
! type(c_devptr) with transfer and call c_f_pointer for a device pointer
! array; OpenACC: deviceptr in a routine that takes them as arguments).
! nbmc_mesh_copy_to_host copies any mesh into Fortran arrays and
! nbmc_mesh_write writes a device mesh too; nbmc_mesh_close frees the device
! arrays.
module nbmc
  use, intrinsic :: iso_c_binding
  implicit none
  private

  ! ---------------------------------------------------------------- version
  integer(c_int32_t), parameter, public :: NBMC_VERSION_MAJOR = 0
  integer(c_int32_t), parameter, public :: NBMC_VERSION_MINOR = 1
  integer(c_int32_t), parameter, public :: NBMC_VERSION_PATCH = 0
  integer(c_int32_t), parameter, public :: NBMC_VERSION = &
       NBMC_VERSION_MAJOR * 10000 + NBMC_VERSION_MINOR * 100 + NBMC_VERSION_PATCH

  ! ----------------------------------------------------------------- status
  integer(c_int32_t), parameter, public :: NBMC_OK                        = 0
  integer(c_int32_t), parameter, public :: NBMC_ERROR_INVALID_ARGUMENT    = 1
  integer(c_int32_t), parameter, public :: NBMC_ERROR_INVALID_PARTICLES   = 2
  integer(c_int32_t), parameter, public :: NBMC_ERROR_NO_PARTICLES        = 3
  integer(c_int32_t), parameter, public :: NBMC_ERROR_INVALID_PARAMETER   = 4
  integer(c_int32_t), parameter, public :: NBMC_ERROR_DOMAIN_TOO_LARGE    = 5
  integer(c_int32_t), parameter, public :: NBMC_ERROR_OUT_OF_MEMORY       = 6
  integer(c_int32_t), parameter, public :: NBMC_ERROR_BACKEND_UNAVAILABLE = 7
  integer(c_int32_t), parameter, public :: NBMC_ERROR_IO                  = 8
  integer(c_int32_t), parameter, public :: NBMC_ERROR_INTERNAL            = 9
  integer(c_int32_t), parameter, public :: NBMC_ERROR_MEMORY_BUDGET       = 10
  integer(c_int32_t), parameter, public :: NBMC_ERROR_CANCELLED           = 11
  integer(c_int32_t), parameter, public :: NBMC_ERROR_FORMAT              = 12

  ! -------------------------------------------------------------- constants
  integer(c_int32_t), parameter, public :: NBMC_BACKEND_AUTO   = 0
  integer(c_int32_t), parameter, public :: NBMC_BACKEND_SERIAL = 1
  integer(c_int32_t), parameter, public :: NBMC_BACKEND_OPENMP = 2
  integer(c_int32_t), parameter, public :: NBMC_BACKEND_CUDA   = 3

  integer(c_int32_t), parameter, public :: NBMC_METHOD_SSP07 = 0
  integer(c_int32_t), parameter, public :: NBMC_METHOD_ZB05  = 1
  integer(c_int32_t), parameter, public :: NBMC_METHOD_SPH   = 2
  integer(c_int32_t), parameter, public :: NBMC_METHOD_YT10  = 3

  integer(c_int32_t), parameter, public :: NBMC_ISOLATED_KEEP = 0
  integer(c_int32_t), parameter, public :: NBMC_ISOLATED_DROP = 1
  integer(c_int32_t), parameter, public :: NBMC_ISOLATED_SPHERE = 2

  integer(c_int32_t), parameter, public :: NBMC_SMOOTH_UNIFORM = 0
  integer(c_int32_t), parameter, public :: NBMC_SMOOTH_FEATURE = 1

  integer(c_int32_t), parameter, public :: NBMC_FIELD_NARROW_BAND = 0
  integer(c_int32_t), parameter, public :: NBMC_FIELD_DENSE       = 1
  integer(c_int32_t), parameter, public :: NBMC_FIELD_SCATTER     = 2

  integer(c_int32_t), parameter, public :: NBMC_UNIT_SPACING  = 0
  integer(c_int32_t), parameter, public :: NBMC_UNIT_ABSOLUTE = 1
  integer(c_int32_t), parameter, public :: NBMC_CONTEXT_KOKKOS_ON_CALLING_THREAD = 1  ! flag bit (uint32_t)

  ! Where arrays handed to or returned by nbmc live.
  integer(c_int32_t), parameter, public :: NBMC_MEMORY_HOST   = 0  ! host memory (default)
  integer(c_int32_t), parameter, public :: NBMC_MEMORY_DEVICE = 1  ! CUDA memory of the context's GPU

  integer(c_int32_t), parameter, public :: NBMC_STAGE_UPLOAD            = 0
  integer(c_int32_t), parameter, public :: NBMC_STAGE_NEIGHBOURHOOD     = 1
  integer(c_int32_t), parameter, public :: NBMC_STAGE_SURFACE_PARTICLES = 2
  integer(c_int32_t), parameter, public :: NBMC_STAGE_BAND              = 3
  integer(c_int32_t), parameter, public :: NBMC_STAGE_FIELD             = 4
  integer(c_int32_t), parameter, public :: NBMC_STAGE_TRIANGULATION     = 5
  integer(c_int32_t), parameter, public :: NBMC_STAGE_OUTPUT            = 6
  integer(c_int32_t), parameter, public :: NBMC_STAGE_COUNT             = 7
  integer(c_int32_t), parameter, public :: NBMC_STAGE_SLOTS             = 16
  integer(c_int32_t), parameter, public :: NBMC_STAGE_POSTPROCESS       = 7
  integer(c_int32_t), parameter, public :: NBMC_STAGE_ATTRIBUTES        = 8

  ! ---------------------------------------------------------------- handles
  ! The component is public for calls this module does not wrap; leave it
  ! alone otherwise.
  type, public :: nbmc_context
    type(c_ptr) :: ptr = c_null_ptr
    ! Particles of the last upload through this module (0 after a failed
    ! one); nbmc_context_set_attribute checks its arrays against it.
    integer(c_int64_t) :: particles = 0
  end type nbmc_context

  type, public :: nbmc_mesh
    type(c_ptr) :: ptr = c_null_ptr
  end type nbmc_mesh

  ! ---------------------------------------------------------------- structs
  ! Field for field the C structs; fill them with the *_init routines.
  type, bind(c), public :: nbmc_context_desc
    integer(c_int32_t) :: struct_size = 0   ! uint32_t
    integer(c_int32_t) :: backend = 0
    integer(c_int32_t) :: num_threads = 0
    integer(c_int32_t) :: device_id = 0
    integer(c_int32_t) :: flags = 0         ! uint32_t
    integer(c_int32_t) :: reserved0 = 0     ! uint32_t
  end type nbmc_context_desc

  type, bind(c), public :: nbmc_params
    integer(c_int32_t) :: struct_size = 0   ! uint32_t
    integer(c_int32_t) :: length_unit = 0
    real(c_double)     :: spacing = 0
    real(c_double)     :: cell_size = 0
    real(c_double)     :: influence_radius = 0
    real(c_double)     :: band_width = 0
    real(c_double)     :: surface_radius = 0
    real(c_double)     :: iso_radius = 0
    integer(c_int32_t) :: method = 0
    integer(c_int32_t) :: field = 0
    real(c_double)     :: t_low = 0
    real(c_double)     :: t_high = 0
    real(c_double)     :: color_threshold = 0
    integer(c_int32_t) :: neighbour_threshold = 0
    integer(c_int32_t) :: compute_normals = 0
    integer(c_int32_t) :: use_bbox = 0
    integer(c_int32_t) :: reserved0 = 0
    real(c_double)     :: bbox_min(3) = 0
    real(c_double)     :: bbox_max(3) = 0
    integer(c_int32_t) :: cleanup = 0             ! appended (post-processing)
    integer(c_int32_t) :: smooth_iterations = 0
    real(c_double)     :: iso_threshold = 0       ! appended (NBMC_METHOD_SPH)
    integer(c_int32_t) :: isolated = 0            ! appended (isolated-particle filter)
    integer(c_int32_t) :: min_cluster = 0
    integer(c_int32_t) :: double_positions = 0    ! appended (double-precision positions)
    real(c_double)     :: decimate_fraction = 0   ! appended (decimation, feature-weighted smoothing)
    integer(c_int32_t) :: smooth_weighting = 0
    integer(c_int32_t) :: reserved1 = 0
    real(c_double)     :: aniso_kr = 0            ! appended (NBMC_METHOD_YT10)
    real(c_double)     :: aniso_ks = 0
    real(c_double)     :: aniso_kn = 0
    real(c_double)     :: aniso_lambda = 0
    integer(c_int32_t) :: aniso_neighbours = 0
    integer(c_int32_t) :: reserved2 = 0
    real(c_double)     :: max_distance = 0        ! appended (distance guard)
  end type nbmc_params

  type, bind(c), public :: nbmc_stats
    integer(c_int32_t) :: struct_size = 0   ! uint32_t
    integer(c_int32_t) :: reserved0 = 0
    integer(c_int64_t) :: particle_count = 0
    integer(c_int64_t) :: surface_particle_count = 0
    integer(c_int64_t) :: occupied_cell_count = 0
    integer(c_int64_t) :: band_vertex_count = 0
    integer(c_int64_t) :: band_block_count = 0
    integer(c_int64_t) :: grid_vertex_count = 0
    integer(c_int64_t) :: triangulated_cell_count = 0
    integer(c_int64_t) :: vertex_count = 0
    integer(c_int64_t) :: triangle_count = 0
    integer(c_int64_t) :: grid_dims(3) = 0
    integer(c_int64_t) :: peak_memory_bytes = 0
    integer(c_int64_t) :: neighbour_evaluations = 0
    real(c_double)     :: stage_seconds(0:15) = 0   ! indexed by NBMC_STAGE_*
    real(c_double)     :: total_seconds = 0
    real(c_double)     :: grid_origin(3) = 0
    real(c_double)     :: cell_size = 0
    integer(c_int64_t) :: raw_triangle_count = 0  ! appended (post-processing)
    real(c_double)     :: smoothing_volume_change = 0
    integer(c_int64_t) :: dropped_particle_count = 0  ! appended (isolated-particle filter)
    integer(c_int64_t) :: dropped_cluster_count = 0
    integer(c_int64_t) :: pre_decimation_triangle_count = 0  ! appended (decimation)
    integer(c_int64_t) :: cleanup_bad_triangles_before = 0  ! appended (clean-up counts)
    integer(c_int64_t) :: cleanup_bad_triangles_after = 0
    integer(c_int64_t) :: cleanup_moves = 0
    integer(c_int64_t) :: cleanup_flips = 0
    integer(c_int64_t) :: cleanup_collapses = 0
    integer(c_int64_t) :: cleanup_cuts = 0
    integer(c_int64_t) :: cleanup_removed_component_triangles = 0
  end type nbmc_stats

  ! Signature of a progress callback (nbmc_progress_fn); pass c_funloc(f).
  ! Return 0 to continue, non-zero to cancel.
  abstract interface
    function nbmc_progress_fn(user, stage, fraction) result(stop) bind(c)
      import :: c_ptr, c_int32_t, c_double
      type(c_ptr), value :: user
      integer(c_int32_t), value :: stage
      real(c_double), value :: fraction
      integer(c_int32_t) :: stop
    end function nbmc_progress_fn
  end interface
  public :: nbmc_progress_fn

  ! ------------------------------------------------------ public procedures
  public :: nbmc_library_version, nbmc_version_string, nbmc_status_string, nbmc_stage_name
  public :: nbmc_backend_available
  public :: nbmc_context_desc_init, nbmc_context_create, nbmc_context_close
  public :: nbmc_context_last_error, nbmc_context_backend
  public :: nbmc_context_set_particles, nbmc_context_set_particles_f32, nbmc_context_set_particles_f64
  public :: nbmc_context_set_particles_device_f32, nbmc_context_set_particles_device_f64
  public :: nbmc_context_set_mesh_memory
  public :: nbmc_context_set_progress
  public :: nbmc_context_set_memory_budget
  public :: nbmc_params_init, nbmc_context_reconstruct
  public :: nbmc_stats_init, nbmc_context_stats
  public :: nbmc_mesh_vertex_count, nbmc_mesh_triangle_count
  public :: nbmc_mesh_positions, nbmc_mesh_normals, nbmc_mesh_triangles, nbmc_mesh_close
  public :: nbmc_mesh_positions_f64
  public :: nbmc_mesh_sphere_count, nbmc_mesh_spheres
  public :: nbmc_mesh_memory, nbmc_mesh_copy_to_host, nbmc_mesh_c_arrays
  public :: nbmc_context_load_particles, nbmc_mesh_write, nbmc_last_error
  public :: nbmc_kokkos_finalize
  public :: nbmc_context_set_attribute, nbmc_context_remove_attribute
  public :: nbmc_context_set_attribute_device_f32, nbmc_context_set_attribute_device_f64
  public :: nbmc_mesh_attribute_count, nbmc_mesh_attribute_name, nbmc_mesh_attribute
  public :: nbmc_context_set_radii, nbmc_context_clear_radii
  public :: nbmc_context_set_radii_device_f32, nbmc_context_set_radii_device_f64
  public :: nbmc_abi_ok

  !> Uploads (copies) positions pos(3, n), real(c_float) or real(c_double).
  !> A leading dimension above 3 is a stride: pos(6, n) holding x, y, z, vx,
  !> vy, vz uploads the first three rows.
  interface nbmc_context_set_particles
    module procedure nbmc_context_set_particles_f32, nbmc_context_set_particles_f64
  end interface nbmc_context_set_particles

  !> Sets (copies) the per-particle attribute name for the particles uploaded
  !> last: values(n) (a scalar) or values(3, n) (a vector, e.g. velocity),
  !> real(c_float) or real(c_double), n the particle count. The next
  !> reconstruction interpolates it onto the mesh (nbmc_mesh_attribute).
  !> Every particle upload removes all attributes: set them after the
  !> particles, each frame. Trailing blanks of name are ignored.
  interface nbmc_context_set_attribute
    module procedure set_attribute_f32_1, set_attribute_f64_1, set_attribute_f32_2, set_attribute_f64_2
  end interface nbmc_context_set_attribute

  !> Sets (copies) per-particle radii(n), real(c_float) or real(c_double),
  !> for the particles uploaded last (n their count): each particle takes the
  !> lengths of params (given for a particle of radius params%spacing) times
  !> its radius over params%spacing; the cell size stays the frame's. They
  !> stay until nbmc_context_clear_radii or the next upload. A NaN, infinite,
  !> zero or negative radius gives NBMC_ERROR_INVALID_PARAMETER, a wrong n
  !> NBMC_ERROR_INVALID_ARGUMENT.
  interface nbmc_context_set_radii
    module procedure set_radii_f32, set_radii_f64
  end interface nbmc_context_set_radii

  ! -------------------------------------------------- the C ABI (private)
  interface
    function c_strlen(s) bind(c, name="strlen") result(n)
      import :: c_ptr, c_size_t
      type(c_ptr), value :: s
      integer(c_size_t) :: n
    end function c_strlen

    function c_version() bind(c, name="nbmc_version") result(v)
      import :: c_int32_t
      integer(c_int32_t) :: v
    end function c_version

    function c_version_string() bind(c, name="nbmc_version_string") result(s)
      import :: c_ptr
      type(c_ptr) :: s
    end function c_version_string

    function c_status_string(status) bind(c, name="nbmc_status_string") result(s)
      import :: c_ptr, c_int32_t
      integer(c_int32_t), value :: status
      type(c_ptr) :: s
    end function c_status_string

    function c_stage_name(stage) bind(c, name="nbmc_stage_name") result(s)
      import :: c_ptr, c_int32_t
      integer(c_int32_t), value :: stage
      type(c_ptr) :: s
    end function c_stage_name

    function c_backend_available(backend) bind(c, name="nbmc_backend_available") result(r)
      import :: c_int32_t
      integer(c_int32_t), value :: backend
      integer(c_int32_t) :: r
    end function c_backend_available

    ! The three initialisers again, on raw memory, for nbmc_abi_ok.
    subroutine c_context_desc_init_raw(p) bind(c, name="nbmc_context_desc_init")
      import :: c_ptr
      type(c_ptr), value :: p
    end subroutine c_context_desc_init_raw
    subroutine c_params_init_raw(p) bind(c, name="nbmc_params_init")
      import :: c_ptr
      type(c_ptr), value :: p
    end subroutine c_params_init_raw
    subroutine c_stats_init_raw(p) bind(c, name="nbmc_stats_init")
      import :: c_ptr
      type(c_ptr), value :: p
    end subroutine c_stats_init_raw

    subroutine c_context_desc_init(desc) bind(c, name="nbmc_context_desc_init")
      import :: nbmc_context_desc
      type(nbmc_context_desc), intent(inout) :: desc
    end subroutine c_context_desc_init

    function c_context_create(desc, out) bind(c, name="nbmc_context_create") result(status)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: desc
      type(c_ptr), intent(out) :: out
      integer(c_int32_t) :: status
    end function c_context_create

    subroutine c_context_destroy(ctx) bind(c, name="nbmc_context_destroy")
      import :: c_ptr
      type(c_ptr), value :: ctx
    end subroutine c_context_destroy

    function c_context_last_error(ctx) bind(c, name="nbmc_context_last_error") result(s)
      import :: c_ptr
      type(c_ptr), value :: ctx
      type(c_ptr) :: s
    end function c_context_last_error

    function c_context_backend(ctx, backend) bind(c, name="nbmc_context_backend") result(status)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: ctx
      integer(c_int32_t), intent(out) :: backend
      integer(c_int32_t) :: status
    end function c_context_backend

    function c_context_set_particles_f32(ctx, xyz, count, byte_stride) &
         bind(c, name="nbmc_context_set_particles_f32") result(status)
      import :: c_ptr, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx
      type(c_ptr), value :: xyz
      integer(c_int64_t), value :: count, byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_particles_f32

    function c_context_set_particles_f64(ctx, xyz, count, byte_stride) &
         bind(c, name="nbmc_context_set_particles_f64") result(status)
      import :: c_ptr, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx
      type(c_ptr), value :: xyz
      integer(c_int64_t), value :: count, byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_particles_f64

    ! xyz: CUDA device memory (type(c_ptr) holding a device address).
    function c_context_set_particles_device_f32(ctx, xyz, count, byte_stride) &
         bind(c, name="nbmc_context_set_particles_device_f32") result(status)
      import :: c_ptr, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx
      type(c_ptr), value :: xyz
      integer(c_int64_t), value :: count, byte_stride  ! uint64_t
      integer(c_int32_t) :: status
    end function c_context_set_particles_device_f32

    function c_context_set_particles_device_f64(ctx, xyz, count, byte_stride) &
         bind(c, name="nbmc_context_set_particles_device_f64") result(status)
      import :: c_ptr, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx
      type(c_ptr), value :: xyz
      integer(c_int64_t), value :: count, byte_stride  ! uint64_t
      integer(c_int32_t) :: status
    end function c_context_set_particles_device_f64

    function c_context_set_mesh_memory(ctx, memory) bind(c, name="nbmc_context_set_mesh_memory") result(status)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: ctx
      integer(c_int32_t), value :: memory
      integer(c_int32_t) :: status
    end function c_context_set_mesh_memory

    function c_context_set_progress(ctx, fn, user) bind(c, name="nbmc_context_set_progress") result(status)
      import :: c_ptr, c_funptr, c_int32_t
      type(c_ptr), value :: ctx
      type(c_funptr), value :: fn
      type(c_ptr), value :: user
      integer(c_int32_t) :: status
    end function c_context_set_progress

    function c_context_set_memory_budget(ctx, bytes) bind(c, name="nbmc_context_set_memory_budget") result(status)
      import :: c_ptr, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx
      integer(c_int64_t), value :: bytes  ! uint64_t
      integer(c_int32_t) :: status
    end function c_context_set_memory_budget

    subroutine c_params_init(params) bind(c, name="nbmc_params_init")
      import :: nbmc_params
      type(nbmc_params), intent(inout) :: params
    end subroutine c_params_init

    function c_context_reconstruct(ctx, params, mesh) bind(c, name="nbmc_context_reconstruct") result(status)
      import :: c_ptr, c_int32_t, nbmc_params
      type(c_ptr), value :: ctx
      type(nbmc_params), intent(in) :: params
      type(c_ptr), intent(out) :: mesh
      integer(c_int32_t) :: status
    end function c_context_reconstruct

    subroutine c_stats_init(stats) bind(c, name="nbmc_stats_init")
      import :: nbmc_stats
      type(nbmc_stats), intent(inout) :: stats
    end subroutine c_stats_init

    function c_context_stats(ctx, stats) bind(c, name="nbmc_context_stats") result(status)
      import :: c_ptr, c_int32_t, nbmc_stats
      type(c_ptr), value :: ctx
      type(nbmc_stats), intent(inout) :: stats
      integer(c_int32_t) :: status
    end function c_context_stats

    function c_mesh_vertex_count(mesh) bind(c, name="nbmc_mesh_vertex_count") result(n)
      import :: c_ptr, c_int64_t
      type(c_ptr), value :: mesh
      integer(c_int64_t) :: n
    end function c_mesh_vertex_count

    function c_mesh_triangle_count(mesh) bind(c, name="nbmc_mesh_triangle_count") result(n)
      import :: c_ptr, c_int64_t
      type(c_ptr), value :: mesh
      integer(c_int64_t) :: n
    end function c_mesh_triangle_count

    function c_mesh_positions(mesh) bind(c, name="nbmc_mesh_positions") result(p)
      import :: c_ptr
      type(c_ptr), value :: mesh
      type(c_ptr) :: p
    end function c_mesh_positions

    function c_mesh_positions_f64(mesh) bind(c, name="nbmc_mesh_positions_f64") result(p)
      import :: c_ptr
      type(c_ptr), value :: mesh
      type(c_ptr) :: p
    end function c_mesh_positions_f64

    function c_mesh_sphere_count(mesh) bind(c, name="nbmc_mesh_sphere_count") result(n)
      import :: c_ptr, c_int64_t
      type(c_ptr), value :: mesh
      integer(c_int64_t) :: n
    end function c_mesh_sphere_count

    function c_mesh_spheres(mesh) bind(c, name="nbmc_mesh_spheres") result(p)
      import :: c_ptr
      type(c_ptr), value :: mesh
      type(c_ptr) :: p
    end function c_mesh_spheres

    function c_mesh_normals(mesh) bind(c, name="nbmc_mesh_normals") result(p)
      import :: c_ptr
      type(c_ptr), value :: mesh
      type(c_ptr) :: p
    end function c_mesh_normals

    function c_mesh_triangles(mesh) bind(c, name="nbmc_mesh_triangles") result(p)
      import :: c_ptr
      type(c_ptr), value :: mesh
      type(c_ptr) :: p
    end function c_mesh_triangles

    function c_context_set_attribute_f32(ctx, name, data, components, byte_stride) &
         bind(c, name="nbmc_context_set_attribute_f32") result(status)
      import :: c_ptr, c_char, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx, data
      character(kind=c_char), intent(in) :: name(*)
      integer(c_int32_t), value :: components
      integer(c_int64_t), value :: byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_attribute_f32

    function c_context_set_attribute_f64(ctx, name, data, components, byte_stride) &
         bind(c, name="nbmc_context_set_attribute_f64") result(status)
      import :: c_ptr, c_char, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx, data
      character(kind=c_char), intent(in) :: name(*)
      integer(c_int32_t), value :: components
      integer(c_int64_t), value :: byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_attribute_f64

    function c_context_set_attribute_device_f32(ctx, name, data, components, byte_stride) &
         bind(c, name="nbmc_context_set_attribute_device_f32") result(status)
      import :: c_ptr, c_char, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx, data
      character(kind=c_char), intent(in) :: name(*)
      integer(c_int32_t), value :: components
      integer(c_int64_t), value :: byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_attribute_device_f32

    function c_context_set_attribute_device_f64(ctx, name, data, components, byte_stride) &
         bind(c, name="nbmc_context_set_attribute_device_f64") result(status)
      import :: c_ptr, c_char, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx, data
      character(kind=c_char), intent(in) :: name(*)
      integer(c_int32_t), value :: components
      integer(c_int64_t), value :: byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_attribute_device_f64

    function c_context_set_radii_f32(ctx, radii, count, byte_stride) &
         bind(c, name="nbmc_context_set_radii_f32") result(status)
      import :: c_ptr, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx, radii
      integer(c_int64_t), value :: count, byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_radii_f32

    function c_context_set_radii_f64(ctx, radii, count, byte_stride) &
         bind(c, name="nbmc_context_set_radii_f64") result(status)
      import :: c_ptr, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx, radii
      integer(c_int64_t), value :: count, byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_radii_f64

    function c_context_set_radii_device_f32(ctx, radii, count, byte_stride) &
         bind(c, name="nbmc_context_set_radii_device_f32") result(status)
      import :: c_ptr, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx, radii
      integer(c_int64_t), value :: count, byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_radii_device_f32

    function c_context_set_radii_device_f64(ctx, radii, count, byte_stride) &
         bind(c, name="nbmc_context_set_radii_device_f64") result(status)
      import :: c_ptr, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx, radii
      integer(c_int64_t), value :: count, byte_stride
      integer(c_int32_t) :: status
    end function c_context_set_radii_device_f64

    function c_mesh_attribute_count(mesh) bind(c, name="nbmc_mesh_attribute_count") result(n)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: mesh
      integer(c_int32_t) :: n
    end function c_mesh_attribute_count

    function c_mesh_attribute_name(mesh, i) bind(c, name="nbmc_mesh_attribute_name") result(p)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: mesh
      integer(c_int32_t), value :: i
      type(c_ptr) :: p
    end function c_mesh_attribute_name

    function c_mesh_attribute(mesh, name, components) bind(c, name="nbmc_mesh_attribute") result(p)
      import :: c_ptr, c_char, c_int32_t
      type(c_ptr), value :: mesh
      character(kind=c_char), intent(in) :: name(*)
      integer(c_int32_t), intent(out) :: components
      type(c_ptr) :: p
    end function c_mesh_attribute

    subroutine c_mesh_destroy(mesh) bind(c, name="nbmc_mesh_destroy")
      import :: c_ptr
      type(c_ptr), value :: mesh
    end subroutine c_mesh_destroy

    function c_mesh_memory(mesh) bind(c, name="nbmc_mesh_memory") result(memory)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: mesh
      integer(c_int32_t) :: memory
    end function c_mesh_memory

    function c_mesh_copy_to_host(mesh, positions, normals, triangles) &
         bind(c, name="nbmc_mesh_copy_to_host") result(status)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: mesh
      type(c_ptr), value :: positions, normals, triangles  ! host buffers or NULL
      integer(c_int32_t) :: status
    end function c_mesh_copy_to_host

    function c_context_load_particles(ctx, path, format, count_out) &
         bind(c, name="nbmc_context_load_particles") result(status)
      import :: c_ptr, c_char, c_int32_t, c_int64_t
      type(c_ptr), value :: ctx
      character(kind=c_char), intent(in) :: path(*)
      type(c_ptr), value :: format
      integer(c_int64_t), intent(out) :: count_out
      integer(c_int32_t) :: status
    end function c_context_load_particles

    function c_mesh_write(mesh, path, format) bind(c, name="nbmc_mesh_write") result(status)
      import :: c_ptr, c_char, c_int32_t
      type(c_ptr), value :: mesh
      character(kind=c_char), intent(in) :: path(*)
      type(c_ptr), value :: format
      integer(c_int32_t) :: status
    end function c_mesh_write

    function c_last_error() bind(c, name="nbmc_last_error") result(s)
      import :: c_ptr
      type(c_ptr) :: s
    end function c_last_error

    function c_kokkos_finalize() bind(c, name="nbmc_kokkos_finalize") result(status)
      import :: c_int32_t
      integer(c_int32_t) :: status
    end function c_kokkos_finalize
  end interface

contains

  ! A copy of a NUL-terminated C string ('' for NULL).
  function from_c(p) result(s)
    type(c_ptr), intent(in) :: p
    character(len=:), allocatable :: s
    character(kind=c_char), pointer :: chars(:)
    integer :: i, n
    if (.not. c_associated(p)) then
      s = ''
      return
    end if
    n = int(c_strlen(p))
    call c_f_pointer(p, chars, [n])
    allocate(character(len=n) :: s)
    do i = 1, n
      s(i:i) = chars(i)
    end do
  end function from_c

  ! ---------------------------------------------------------------- version

  !> .true. when the loaded library has this module's major version and its
  !> structs have the sizes of the bind(c) types here (each initialiser is run
  !> on a large scratch buffer and the struct_size it writes is compared).
  !> Call it once at start-up; .false. means nbmc.f90 does not match the library.
  logical function nbmc_abi_ok()
    integer(c_int64_t), target :: scratch(1024)
    integer(c_int32_t), pointer :: size_field
    type(nbmc_context_desc) :: d
    type(nbmc_params) :: p
    type(nbmc_stats) :: st
    integer(c_int32_t) :: version
    call c_f_pointer(c_loc(scratch), size_field)
    version = c_version()
    nbmc_abi_ok = version / 10000 == NBMC_VERSION_MAJOR .and. version >= NBMC_VERSION
    scratch = 0
    call c_context_desc_init_raw(c_loc(scratch))
    nbmc_abi_ok = nbmc_abi_ok .and. size_field == c_sizeof(d)
    scratch = 0
    call c_params_init_raw(c_loc(scratch))
    nbmc_abi_ok = nbmc_abi_ok .and. size_field == c_sizeof(p)
    scratch = 0
    call c_stats_init_raw(c_loc(scratch))
    nbmc_abi_ok = nbmc_abi_ok .and. size_field == c_sizeof(st)
  end function nbmc_abi_ok

  !> NBMC_VERSION of the loaded library (C: nbmc_version(); Fortran names are
  !> case-insensitive, so the function cannot share the constant's name).
  integer function nbmc_library_version()
    nbmc_library_version = int(c_version())
  end function nbmc_library_version

  !> "major.minor.patch" plus the compiled-in backends.
  function nbmc_version_string() result(s)
    character(len=:), allocatable :: s
    s = from_c(c_version_string())
  end function nbmc_version_string

  !> English name of a status code.
  function nbmc_status_string(status) result(s)
    integer(c_int32_t), intent(in) :: status
    character(len=:), allocatable :: s
    s = from_c(c_status_string(status))
  end function nbmc_status_string

  !> Name of a stage ('' when out of range).
  function nbmc_stage_name(stage) result(s)
    integer(c_int32_t), intent(in) :: stage
    character(len=:), allocatable :: s
    s = from_c(c_stage_name(stage))
  end function nbmc_stage_name

  !> Whether a backend is compiled in and usable here.
  logical function nbmc_backend_available(backend)
    integer(c_int32_t), intent(in) :: backend
    nbmc_backend_available = c_backend_available(backend) /= 0
  end function nbmc_backend_available

  ! ---------------------------------------------------------------- context

  subroutine nbmc_context_desc_init(desc)
    type(nbmc_context_desc), intent(out) :: desc
    call c_context_desc_init(desc)
  end subroutine nbmc_context_desc_init

  !> Creates a context (default options when desc is absent). On failure ctx
  !> stays null and nbmc_context_last_error(ctx) gives the reason.
  function nbmc_context_create(ctx, desc) result(status)
    type(nbmc_context), intent(out) :: ctx
    type(nbmc_context_desc), intent(in), optional, target :: desc
    integer(c_int32_t) :: status
    if (present(desc)) then
      status = c_context_create(c_loc(desc), ctx%ptr)
    else
      status = c_context_create(c_null_ptr, ctx%ptr)
    end if
  end function nbmc_context_create

  !> Destroys the context and nulls the handle (meshes stay valid).
  subroutine nbmc_context_close(ctx)
    type(nbmc_context), intent(inout) :: ctx
    call c_context_destroy(ctx%ptr)
    ctx%ptr = c_null_ptr
    ctx%particles = 0
  end subroutine nbmc_context_close

  !> Message of the last failed call on ctx; for a null ctx, that of the last
  !> failed nbmc_context_create on this thread.
  function nbmc_context_last_error(ctx) result(s)
    type(nbmc_context), intent(in) :: ctx
    character(len=:), allocatable :: s
    s = from_c(c_context_last_error(ctx%ptr))
  end function nbmc_context_last_error

  function nbmc_context_backend(ctx, backend) result(status)
    type(nbmc_context), intent(in) :: ctx
    integer(c_int32_t), intent(out) :: backend
    integer(c_int32_t) :: status
    status = c_context_backend(ctx%ptr, backend)
  end function nbmc_context_backend

  function nbmc_context_set_particles_f32(ctx, pos) result(status)
    type(nbmc_context), intent(inout) :: ctx
    real(c_float), intent(in), contiguous, target :: pos(:, :)
    integer(c_int32_t) :: status
    integer(c_int64_t) :: stride
    stride = int(size(pos, 1), c_int64_t) * c_sizeof(0.0_c_float)
    if (size(pos) == 0) then ! no element to take the address of
      status = c_context_set_particles_f32(ctx%ptr, c_null_ptr, 0_c_int64_t, stride)
    else
      status = c_context_set_particles_f32(ctx%ptr, c_loc(pos), size(pos, 2, kind=c_int64_t), stride)
    end if
    ctx%particles = 0
    if (status == NBMC_OK) ctx%particles = size(pos, 2, kind=c_int64_t)
  end function nbmc_context_set_particles_f32

  function nbmc_context_set_particles_f64(ctx, pos) result(status)
    type(nbmc_context), intent(inout) :: ctx
    real(c_double), intent(in), contiguous, target :: pos(:, :)
    integer(c_int32_t) :: status
    integer(c_int64_t) :: stride
    stride = int(size(pos, 1), c_int64_t) * c_sizeof(0.0_c_double)
    if (size(pos) == 0) then
      status = c_context_set_particles_f64(ctx%ptr, c_null_ptr, 0_c_int64_t, stride)
    else
      status = c_context_set_particles_f64(ctx%ptr, c_loc(pos), size(pos, 2, kind=c_int64_t), stride)
    end if
    ctx%particles = 0
    if (status == NBMC_OK) ctx%particles = size(pos, 2, kind=c_int64_t)
  end function nbmc_context_set_particles_f64

  !> Uploads (copies) count positions from CUDA device memory of the
  !> context's GPU: xyz is a device address (see the header of this file for
  !> OpenACC and CUDA Fortran), particle i at byte offset i * byte_stride
  !> (0 = packed; else a multiple of 4). CUDA backend only, else
  !> NBMC_ERROR_BACKEND_UNAVAILABLE; a host address gives
  !> NBMC_ERROR_INVALID_ARGUMENT. On failure the context keeps no particles.
  function nbmc_context_set_particles_device_f32(ctx, xyz, count, byte_stride) result(status)
    type(nbmc_context), intent(inout) :: ctx
    type(c_ptr), intent(in) :: xyz
    integer(c_int64_t), intent(in) :: count, byte_stride
    integer(c_int32_t) :: status
    status = c_context_set_particles_device_f32(ctx%ptr, xyz, count, byte_stride)
    ctx%particles = 0
    if (status == NBMC_OK) ctx%particles = count
  end function nbmc_context_set_particles_device_f32

  !> The same for real(c_double) positions (byte_stride a multiple of 8).
  function nbmc_context_set_particles_device_f64(ctx, xyz, count, byte_stride) result(status)
    type(nbmc_context), intent(inout) :: ctx
    type(c_ptr), intent(in) :: xyz
    integer(c_int64_t), intent(in) :: count, byte_stride
    integer(c_int32_t) :: status
    status = c_context_set_particles_device_f64(ctx%ptr, xyz, count, byte_stride)
    ctx%particles = 0
    if (status == NBMC_OK) ctx%particles = count
  end function nbmc_context_set_particles_device_f64

  !> Where the meshes of later reconstructions go: NBMC_MEMORY_HOST (default)
  !> or NBMC_MEMORY_DEVICE (CUDA backend only, else
  !> NBMC_ERROR_BACKEND_UNAVAILABLE).
  function nbmc_context_set_mesh_memory(ctx, memory) result(status)
    type(nbmc_context), intent(inout) :: ctx
    integer(c_int32_t), intent(in) :: memory
    integer(c_int32_t) :: status
    status = c_context_set_mesh_memory(ctx%ptr, memory)
  end function nbmc_context_set_mesh_memory

  !> Registers fn (c_funloc of a procedure with the nbmc_progress_fn
  !> interface) with user data; c_null_funptr removes it.
  function nbmc_context_set_progress(ctx, fn, user) result(status)
    type(nbmc_context), intent(inout) :: ctx
    type(c_funptr), intent(in) :: fn
    type(c_ptr), intent(in), optional :: user
    integer(c_int32_t) :: status
    if (present(user)) then
      status = c_context_set_progress(ctx%ptr, fn, user)
    else
      status = c_context_set_progress(ctx%ptr, fn, c_null_ptr)
    end if
  end function nbmc_context_set_progress

  !> Caps what nbmc may allocate for this context (bytes, host and device
  !> together; 0 = no cap): over it, NBMC_ERROR_MEMORY_BUDGET.
  function nbmc_context_set_memory_budget(ctx, bytes) result(status)
    type(nbmc_context), intent(inout) :: ctx
    integer(c_int64_t), intent(in) :: bytes
    integer(c_int32_t) :: status
    status = c_context_set_memory_budget(ctx%ptr, bytes)
  end function nbmc_context_set_memory_budget

  ! ------------------------------------------------------------- parameters

  !> The library's defaults; spacing (required before reconstructing) may be
  !> given here.
  subroutine nbmc_params_init(params, spacing)
    type(nbmc_params), intent(out) :: params
    real(c_double), intent(in), optional :: spacing
    call c_params_init(params)
    if (present(spacing)) params%spacing = spacing
  end subroutine nbmc_params_init

  !> Reconstructs the surface of the uploaded particles into a new mesh (null
  !> on failure; the context stays usable).
  function nbmc_context_reconstruct(ctx, params, mesh) result(status)
    type(nbmc_context), intent(inout) :: ctx
    type(nbmc_params), intent(in) :: params
    type(nbmc_mesh), intent(inout) :: mesh
    integer(c_int32_t) :: status
    call nbmc_mesh_close(mesh) ! do not leak a mesh the handle still holds
    status = c_context_reconstruct(ctx%ptr, params, mesh%ptr)
  end function nbmc_context_reconstruct

  subroutine nbmc_stats_init(stats)
    type(nbmc_stats), intent(out) :: stats
    call c_stats_init(stats)
  end subroutine nbmc_stats_init

  !> Figures of the last successful reconstruction on ctx.
  function nbmc_context_stats(ctx, stats) result(status)
    type(nbmc_context), intent(in) :: ctx
    type(nbmc_stats), intent(out) :: stats
    integer(c_int32_t) :: status
    call c_stats_init(stats)
    status = c_context_stats(ctx%ptr, stats)
  end function nbmc_context_stats

  ! ------------------------------------------------------------------- mesh

  integer(c_int64_t) function nbmc_mesh_vertex_count(mesh)
    type(nbmc_mesh), intent(in) :: mesh
    nbmc_mesh_vertex_count = c_mesh_vertex_count(mesh%ptr)
  end function nbmc_mesh_vertex_count

  integer(c_int64_t) function nbmc_mesh_triangle_count(mesh)
    type(nbmc_mesh), intent(in) :: mesh
    nbmc_mesh_triangle_count = c_mesh_triangle_count(mesh%ptr)
  end function nbmc_mesh_triangle_count

  !> Vertex positions pos(3, nv), pointing into the mesh (no copy); not
  !> associated for an empty mesh and for a mesh in device memory
  !> (nbmc_mesh_memory; use nbmc_mesh_copy_to_host or nbmc_mesh_c_arrays).
  function nbmc_mesh_positions(mesh) result(pos)
    type(nbmc_mesh), intent(in) :: mesh
    real(c_float), pointer :: pos(:, :)
    type(c_ptr) :: p
    nullify(pos)
    if (c_mesh_memory(mesh%ptr) /= NBMC_MEMORY_HOST) return
    p = c_mesh_positions(mesh%ptr)
    if (c_associated(p)) call c_f_pointer(p, pos, [3_c_int64_t, c_mesh_vertex_count(mesh%ptr)])
  end function nbmc_mesh_positions

  !> Double-precision vertex positions pos(3, nv) of a mesh reconstructed with
  !> params%double_positions = 1, pointing into the mesh (no copy); not
  !> associated for a float mesh and for an empty one.
  function nbmc_mesh_positions_f64(mesh) result(pos)
    type(nbmc_mesh), intent(in) :: mesh
    real(c_double), pointer :: pos(:, :)
    type(c_ptr) :: p
    nullify(pos)
    p = c_mesh_positions_f64(mesh%ptr)
    if (c_associated(p)) call c_f_pointer(p, pos, [3_c_int64_t, c_mesh_vertex_count(mesh%ptr)])
  end function nbmc_mesh_positions_f64

  !> params%isolated = NBMC_ISOLATED_SPHERE: the particles of the dropped
  !> clusters as spheres.
  function nbmc_mesh_sphere_count(mesh) result(n)
    type(nbmc_mesh), intent(in) :: mesh
    integer(c_int64_t) :: n
    n = c_mesh_sphere_count(mesh%ptr)
  end function nbmc_mesh_sphere_count

  !> The spheres s(4, n): x, y, z, radius each, pointing into the mesh (no
  !> copy, host memory); not associated when there are none.
  function nbmc_mesh_spheres(mesh) result(s)
    type(nbmc_mesh), intent(in) :: mesh
    real(c_float), pointer :: s(:, :)
    type(c_ptr) :: p
    nullify(s)
    p = c_mesh_spheres(mesh%ptr)
    if (c_associated(p)) call c_f_pointer(p, s, [4_c_int64_t, c_mesh_sphere_count(mesh%ptr)])
  end function nbmc_mesh_spheres

  !> Unit normals nrm(3, nv) pointing out of the fluid; not associated when
  !> the reconstruction had compute_normals = 0, and for a device mesh.
  function nbmc_mesh_normals(mesh) result(nrm)
    type(nbmc_mesh), intent(in) :: mesh
    real(c_float), pointer :: nrm(:, :)
    type(c_ptr) :: p
    nullify(nrm)
    if (c_mesh_memory(mesh%ptr) /= NBMC_MEMORY_HOST) return
    p = c_mesh_normals(mesh%ptr)
    if (c_associated(p)) call c_f_pointer(p, nrm, [3_c_int64_t, c_mesh_vertex_count(mesh%ptr)])
  end function nbmc_mesh_normals

  !> Triangles tri(3, nt) of 0-based vertex indices (add 1 for Fortran
  !> arrays), counter-clockwise seen from outside the fluid; not associated
  !> for an empty mesh and for a device mesh.
  function nbmc_mesh_triangles(mesh) result(tri)
    type(nbmc_mesh), intent(in) :: mesh
    integer(c_int32_t), pointer :: tri(:, :)
    type(c_ptr) :: p
    nullify(tri)
    if (c_mesh_memory(mesh%ptr) /= NBMC_MEMORY_HOST) return
    p = c_mesh_triangles(mesh%ptr)
    if (c_associated(p)) call c_f_pointer(p, tri, [3_c_int64_t, c_mesh_triangle_count(mesh%ptr)])
  end function nbmc_mesh_triangles

  !> Where the mesh's arrays live: NBMC_MEMORY_HOST or NBMC_MEMORY_DEVICE
  !> (NBMC_MEMORY_HOST for a null handle).
  integer(c_int32_t) function nbmc_mesh_memory(mesh)
    type(nbmc_mesh), intent(in) :: mesh
    nbmc_mesh_memory = c_mesh_memory(mesh%ptr)
  end function nbmc_mesh_memory

  !> Copies the mesh's arrays, host or device, into Fortran arrays
  !> positions(3, nv), normals(3, nv) and triangles(3, nt) (0-based indices);
  !> each is optional. An array of another size gives
  !> NBMC_ERROR_INVALID_ARGUMENT and nothing is copied; normals is left
  !> untouched when the mesh has none; a null mesh gives
  !> NBMC_ERROR_INVALID_ARGUMENT.
  function nbmc_mesh_copy_to_host(mesh, positions, normals, triangles) result(status)
    type(nbmc_mesh), intent(in) :: mesh
    real(c_float), intent(inout), contiguous, target, optional :: positions(:, :), normals(:, :)
    integer(c_int32_t), intent(inout), contiguous, target, optional :: triangles(:, :)
    integer(c_int32_t) :: status
    type(c_ptr) :: p, n, t
    integer(c_int64_t) :: nv, nt
    nv = c_mesh_vertex_count(mesh%ptr)
    nt = c_mesh_triangle_count(mesh%ptr)
    p = c_null_ptr
    n = c_null_ptr
    t = c_null_ptr
    status = NBMC_ERROR_INVALID_ARGUMENT
    if (present(positions)) then
      if (size(positions, kind=c_int64_t) /= 3 * nv) return
      if (nv > 0) p = c_loc(positions)
    end if
    if (present(normals)) then
      if (size(normals, kind=c_int64_t) /= 3 * nv) return
      if (nv > 0) n = c_loc(normals)
    end if
    if (present(triangles)) then
      if (size(triangles, kind=c_int64_t) /= 3 * nt) return
      if (nt > 0) t = c_loc(triangles)
    end if
    status = c_mesh_copy_to_host(mesh%ptr, p, n, t)
  end function nbmc_mesh_copy_to_host

  !> The C getters' addresses of the mesh's arrays, wherever they live:
  !> device addresses when nbmc_mesh_memory(mesh) is NBMC_MEMORY_DEVICE (for
  !> CUDA Fortran / OpenACC code; never dereference them on the host), host
  !> addresses otherwise. c_null_ptr for an empty mesh; normals is
  !> c_null_ptr without normals. Valid until nbmc_mesh_close(mesh).
  subroutine nbmc_mesh_c_arrays(mesh, positions, normals, triangles)
    type(nbmc_mesh), intent(in) :: mesh
    type(c_ptr), intent(out), optional :: positions, normals, triangles
    if (present(positions)) positions = c_mesh_positions(mesh%ptr)
    if (present(normals)) normals = c_mesh_normals(mesh%ptr)
    if (present(triangles)) triangles = c_mesh_triangles(mesh%ptr)
  end subroutine nbmc_mesh_c_arrays

  !> Frees the mesh and nulls the handle; pointers obtained from it dangle.
  subroutine nbmc_mesh_close(mesh)
    type(nbmc_mesh), intent(inout) :: mesh
    call c_mesh_destroy(mesh%ptr)
    mesh%ptr = c_null_ptr
  end subroutine nbmc_mesh_close

  ! ---------------------------------------------------------------- file I/O

  !> Reads the particle positions of a file with nbmc's readers and uploads
  !> them (as nbmc_context_set_particles). format: 'xyz', 'ply', 'vtk', 'bgeo',
  !> 'h5part', ... (docs/api.md); absent or '' = by the file name's extension.
  !> Trailing blanks of path are ignored. count (optional) is the number of
  !> particles read; the message of a failure is nbmc_context_last_error(ctx).
  function nbmc_context_load_particles(ctx, path, format, count) result(status)
    type(nbmc_context), intent(inout) :: ctx
    character(len=*), intent(in) :: path
    character(len=*), intent(in), optional :: format
    integer(c_int64_t), intent(out), optional :: count
    integer(c_int32_t) :: status
    character(kind=c_char, len=:), allocatable, target :: cformat
    integer(c_int64_t) :: n
    if (present(format)) then
      cformat = trim(format) // c_null_char
      status = c_context_load_particles(ctx%ptr, trim(path) // c_null_char, c_loc(cformat), n)
    else
      status = c_context_load_particles(ctx%ptr, trim(path) // c_null_char, c_null_ptr, n)
    end if
    if (present(count)) count = n
    ctx%particles = 0
    if (status == NBMC_OK) ctx%particles = n
  end function nbmc_context_load_particles

  !> Writes the mesh with nbmc's writers ('ply', 'obj', 'vtk', 'vtu', 'glb';
  !> absent or '' = by the extension); a device mesh is copied to the host
  !> first. The message of a failure is nbmc_last_error().
  function nbmc_mesh_write(mesh, path, format) result(status)
    type(nbmc_mesh), intent(in) :: mesh
    character(len=*), intent(in) :: path
    character(len=*), intent(in), optional :: format
    integer(c_int32_t) :: status
    character(kind=c_char, len=:), allocatable, target :: cformat
    if (present(format)) then
      cformat = trim(format) // c_null_char
      status = c_mesh_write(mesh%ptr, trim(path) // c_null_char, c_loc(cformat))
    else
      status = c_mesh_write(mesh%ptr, trim(path) // c_null_char, c_null_ptr)
    end if
  end function nbmc_mesh_write

  !> Message of the last failed call on this thread that has no context to
  !> keep it (nbmc_mesh_write).
  function nbmc_last_error() result(s)
    character(len=:), allocatable :: s
    s = from_c(c_last_error())
  end function nbmc_last_error

  ! ------------------------------------------------------------ attributes

  function set_attribute_f32_1(ctx, name, values) result(status)
    type(nbmc_context), intent(inout) :: ctx
    character(len=*), intent(in) :: name
    real(c_float), intent(in), contiguous, target :: values(:)
    integer(c_int32_t) :: status
    type(c_ptr) :: p
    p = c_null_ptr
    if (size(values) > 0) p = c_loc(values)
    status = attribute_checked(ctx, name, p, size(values, kind=c_int64_t), 1_c_int32_t, .false.)
  end function set_attribute_f32_1

  function set_attribute_f64_1(ctx, name, values) result(status)
    type(nbmc_context), intent(inout) :: ctx
    character(len=*), intent(in) :: name
    real(c_double), intent(in), contiguous, target :: values(:)
    integer(c_int32_t) :: status
    type(c_ptr) :: p
    p = c_null_ptr
    if (size(values) > 0) p = c_loc(values)
    status = attribute_checked(ctx, name, p, size(values, kind=c_int64_t), 1_c_int32_t, .true.)
  end function set_attribute_f64_1

  function set_attribute_f32_2(ctx, name, values) result(status)
    type(nbmc_context), intent(inout) :: ctx
    character(len=*), intent(in) :: name
    real(c_float), intent(in), contiguous, target :: values(:, :)
    integer(c_int32_t) :: status
    type(c_ptr) :: p
    p = c_null_ptr
    if (size(values) > 0) p = c_loc(values)
    status = attribute_checked(ctx, name, p, size(values, 2, kind=c_int64_t), int(size(values, 1), c_int32_t), .false.)
  end function set_attribute_f32_2

  function set_attribute_f64_2(ctx, name, values) result(status)
    type(nbmc_context), intent(inout) :: ctx
    character(len=*), intent(in) :: name
    real(c_double), intent(in), contiguous, target :: values(:, :)
    integer(c_int32_t) :: status
    type(c_ptr) :: p
    p = c_null_ptr
    if (size(values) > 0) p = c_loc(values)
    status = attribute_checked(ctx, name, p, size(values, 2, kind=c_int64_t), int(size(values, 1), c_int32_t), .true.)
  end function set_attribute_f64_2

  ! The C call, after checking that there is one item per particle: the C
  ! function reads as many items as the particles it holds. An empty array
  ! (nothing to take the address of) is refused here too.
  function attribute_checked(ctx, name, p, items, components, f64) result(status)
    type(nbmc_context), intent(inout) :: ctx
    character(len=*), intent(in) :: name
    type(c_ptr), intent(in) :: p
    integer(c_int64_t), intent(in) :: items
    integer(c_int32_t), intent(in) :: components
    logical, intent(in) :: f64
    integer(c_int32_t) :: status
    integer(c_int64_t) :: n
    n = ctx%particles
    if (items /= n .or. .not. c_associated(p)) then
      status = NBMC_ERROR_INVALID_ARGUMENT
      if (n == 0) status = NBMC_ERROR_NO_PARTICLES
      return
    end if
    if (f64) then
      status = c_context_set_attribute_f64(ctx%ptr, trim(name) // c_null_char, p, components, 0_c_int64_t)
    else
      status = c_context_set_attribute_f32(ctx%ptr, trim(name) // c_null_char, p, components, 0_c_int64_t)
    end if
  end function attribute_checked

  !> Removes the attribute name (NBMC_OK also when there is none).
  function nbmc_context_remove_attribute(ctx, name) result(status)
    type(nbmc_context), intent(inout) :: ctx
    character(len=*), intent(in) :: name
    integer(c_int32_t) :: status
    status = c_context_set_attribute_f64(ctx%ptr, trim(name) // c_null_char, c_null_ptr, 1_c_int32_t, 0_c_int64_t)
  end function nbmc_context_remove_attribute

  !> The attribute from CUDA device memory of the context's GPU (data a
  !> device address as for nbmc_context_set_particles_device_f32; one item
  !> of components values per particle, byte_stride apart, 0 = packed). CUDA
  !> backend only, else NBMC_ERROR_BACKEND_UNAVAILABLE.
  function nbmc_context_set_attribute_device_f32(ctx, name, data, components, byte_stride) result(status)
    type(nbmc_context), intent(inout) :: ctx
    character(len=*), intent(in) :: name
    type(c_ptr), intent(in) :: data
    integer(c_int32_t), intent(in) :: components
    integer(c_int64_t), intent(in) :: byte_stride
    integer(c_int32_t) :: status
    status = c_context_set_attribute_device_f32(ctx%ptr, trim(name) // c_null_char, data, components, byte_stride)
  end function nbmc_context_set_attribute_device_f32

  !> The same for real(c_double) values (byte_stride a multiple of 8).
  function nbmc_context_set_attribute_device_f64(ctx, name, data, components, byte_stride) result(status)
    type(nbmc_context), intent(inout) :: ctx
    character(len=*), intent(in) :: name
    type(c_ptr), intent(in) :: data
    integer(c_int32_t), intent(in) :: components
    integer(c_int64_t), intent(in) :: byte_stride
    integer(c_int32_t) :: status
    status = c_context_set_attribute_device_f64(ctx%ptr, trim(name) // c_null_char, data, components, byte_stride)
  end function nbmc_context_set_attribute_device_f64

  function set_radii_f32(ctx, radii) result(status)
    type(nbmc_context), intent(inout) :: ctx
    real(c_float), intent(in), contiguous, target :: radii(:)
    integer(c_int32_t) :: status
    if (size(radii) == 0) then  ! no array to point at: as the library would answer
      status = NBMC_ERROR_INVALID_ARGUMENT
      if (ctx%particles == 0) status = NBMC_ERROR_NO_PARTICLES
      return
    end if
    status = c_context_set_radii_f32(ctx%ptr, c_loc(radii), size(radii, kind=c_int64_t), 0_c_int64_t)
  end function set_radii_f32

  function set_radii_f64(ctx, radii) result(status)
    type(nbmc_context), intent(inout) :: ctx
    real(c_double), intent(in), contiguous, target :: radii(:)
    integer(c_int32_t) :: status
    if (size(radii) == 0) then
      status = NBMC_ERROR_INVALID_ARGUMENT
      if (ctx%particles == 0) status = NBMC_ERROR_NO_PARTICLES
      return
    end if
    status = c_context_set_radii_f64(ctx%ptr, c_loc(radii), size(radii, kind=c_int64_t), 0_c_int64_t)
  end function set_radii_f64

  !> Removes the per-particle radii (NBMC_OK also when there are none).
  function nbmc_context_clear_radii(ctx) result(status)
    type(nbmc_context), intent(inout) :: ctx
    integer(c_int32_t) :: status
    status = c_context_set_radii_f64(ctx%ptr, c_null_ptr, 0_c_int64_t, 0_c_int64_t)
  end function nbmc_context_clear_radii

  !> Radii from CUDA device memory of the context's GPU (radii a device
  !> address as for nbmc_context_set_particles_device_f32; count values, the
  !> particle count, byte_stride apart, 0 = packed). CUDA backend only, else
  !> NBMC_ERROR_BACKEND_UNAVAILABLE.
  function nbmc_context_set_radii_device_f32(ctx, radii, count, byte_stride) result(status)
    type(nbmc_context), intent(inout) :: ctx
    type(c_ptr), intent(in) :: radii
    integer(c_int64_t), intent(in) :: count, byte_stride
    integer(c_int32_t) :: status
    status = c_context_set_radii_device_f32(ctx%ptr, radii, count, byte_stride)
  end function nbmc_context_set_radii_device_f32

  !> The same for real(c_double) values (byte_stride a multiple of 8).
  function nbmc_context_set_radii_device_f64(ctx, radii, count, byte_stride) result(status)
    type(nbmc_context), intent(inout) :: ctx
    type(c_ptr), intent(in) :: radii
    integer(c_int64_t), intent(in) :: count, byte_stride
    integer(c_int32_t) :: status
    status = c_context_set_radii_device_f64(ctx%ptr, radii, count, byte_stride)
  end function nbmc_context_set_radii_device_f64

  !> Attributes interpolated onto the mesh (0 without).
  integer(c_int32_t) function nbmc_mesh_attribute_count(mesh)
    type(nbmc_mesh), intent(in) :: mesh
    nbmc_mesh_attribute_count = c_mesh_attribute_count(mesh%ptr)
  end function nbmc_mesh_attribute_count

  !> Name of attribute i, 1-based here (1 <= i <= nbmc_mesh_attribute_count);
  !> '' out of range.
  function nbmc_mesh_attribute_name(mesh, i) result(s)
    type(nbmc_mesh), intent(in) :: mesh
    integer(c_int32_t), intent(in) :: i
    character(len=:), allocatable :: s
    if (i < 1) then
      s = ''
    else
      s = from_c(c_mesh_attribute_name(mesh%ptr, i - 1))
    end if
  end function nbmc_mesh_attribute_name

  !> The values of attribute name as a pointer a(components, nv) into the
  !> mesh (host memory for every mesh), valid until nbmc_mesh_close; not
  !> associated when the mesh has no such attribute (nbmc_last_error() says
  !> why) or no vertices. components (optional) is 1 or 3, 0 when absent.
  function nbmc_mesh_attribute(mesh, name, components) result(a)
    type(nbmc_mesh), intent(in) :: mesh
    character(len=*), intent(in) :: name
    integer(c_int32_t), intent(out), optional :: components
    real(c_float), pointer :: a(:, :)
    type(c_ptr) :: p
    integer(c_int32_t) :: c
    nullify(a)
    p = c_mesh_attribute(mesh%ptr, trim(name) // c_null_char, c)
    if (present(components)) components = c
    if (c_associated(p)) call c_f_pointer(p, a, [int(c, c_int64_t), c_mesh_vertex_count(mesh%ptr)])
  end function nbmc_mesh_attribute

  ! ----------------------------------------------------------------- Kokkos

  !> Finalises the Kokkos runtime nbmc initialised; call after closing every
  !> context. NBMC_ERROR_INVALID_ARGUMENT while contexts are alive.
  function nbmc_kokkos_finalize() result(status)
    integer(c_int32_t) :: status
    status = c_kokkos_finalize()
  end function nbmc_kokkos_finalize

end module nbmc
