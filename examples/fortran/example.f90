! SPDX-License-Identifier: MIT
!
! A toy "solver" that calls nbmc from its time loop: a block of fluid particles
! falls, spins about the vertical axis and settles layer by layer on the floor.
! Every OUTPUT_EVERY steps the surface is reconstructed and written as an OBJ
! file by Fortran code. Every status is checked.
!
!   example [OUTPUT_DIR]        (default: the current directory)
program example
  use, intrinsic :: iso_c_binding
  use, intrinsic :: iso_fortran_env, only: error_unit, output_unit
  use nbmc
  implicit none

  integer, parameter :: nx = 14, ny = 10, nz = 14, n = nx * ny * nz
  integer, parameter :: nsteps = 60, output_every = 20
  real(c_double), parameter :: spacing = 0.05d0, dt = 0.01d0, gravity = -9.81d0
  real(c_double), parameter :: omega = 2.0d0      ! spin, rad/s
  real(c_double), parameter :: restitution = 0.2d0

  ! state(1:3, i) position, state(4:6, i) velocity: uploaded with a stride.
  real(c_double), allocatable :: state(:, :), rest_height(:)
  real(c_float), allocatable :: vcopy(:, :)
  integer(c_int32_t), allocatable :: tcopy(:, :)
  real(c_double) :: cx, cz, x, z, c, s
  type(nbmc_context) :: ctx
  type(nbmc_mesh) :: mesh
  type(nbmc_params) :: params
  type(nbmc_stats) :: stats
  integer(c_int32_t) :: status, backend
  integer :: i, ix, iy, iz, step, frames
  character(len=:), allocatable :: outdir
  character(len=512) :: arg

  if (command_argument_count() >= 1) then
    call get_command_argument(1, arg)
    outdir = trim(arg)
  else
    outdir = '.'
  end if

  write (output_unit, '(a, a)') 'nbmc ', nbmc_version_string()
  if (.not. nbmc_abi_ok()) then
    write (error_unit, '(a, i0)') 'error: nbmc.f90 does not match the loaded library, version ', &
         nbmc_library_version()
    error stop 1
  end if

  ! ------------------------------------------------------------ initial state
  allocate (state(6, n), rest_height(n))
  i = 0
  do iz = 0, nz - 1
    do iy = 0, ny - 1
      do ix = 0, nx - 1
        i = i + 1
        state(1:3, i) = [ix * spacing, 0.4d0 + iy * spacing, iz * spacing]
        state(4:6, i) = 0
        rest_height(i) = iy * spacing   ! where this layer comes to rest
      end do
    end do
  end do
  cx = 0.5d0 * (nx - 1) * spacing
  cz = 0.5d0 * (nz - 1) * spacing

  ! ------------------------------------------------------------------ nbmc set-up
  status = nbmc_context_create(ctx)
  call check(status, 'nbmc_context_create')   ! ctx is null: reports the create error
  status = nbmc_context_backend(ctx, backend)
  call check(status, 'nbmc_context_backend')
  write (output_unit, '(a, i0, a, i0, a)') 'backend ', backend, ', ', n, ' particles'

  ! A failure is reported, not fatal: reconstructing before any upload.
  call nbmc_params_init(params, spacing=spacing)
  status = nbmc_context_reconstruct(ctx, params, mesh)
  if (status /= NBMC_ERROR_NO_PARTICLES .or. c_associated(mesh%ptr)) then
    write (error_unit, '(a, i0)') 'error: expected NBMC_ERROR_NO_PARTICLES, got ', status
    error stop 1
  end if
  write (output_unit, '(a, a, a, a)') 'expected failure: ', nbmc_status_string(status), ': ', &
       nbmc_context_last_error(ctx)

  ! ---------------------------------------------------------------- time loop
  frames = 0
  do step = 0, nsteps
    if (mod(step, output_every) == 0) then
      ! Positions are rows 1:3 of state(6, n): the leading dimension is the stride.
      status = nbmc_context_set_particles(ctx, state)
      call check(status, 'nbmc_context_set_particles')
      ! Per-particle data follows the particles onto the mesh: set after
      ! every upload (an upload removes them). velocity(3, n), layer(n).
      status = nbmc_context_set_attribute(ctx, 'velocity', state(4:6, :))
      call check(status, 'nbmc_context_set_attribute velocity')
      status = nbmc_context_set_attribute(ctx, 'layer', rest_height)
      call check(status, 'nbmc_context_set_attribute layer')
      status = nbmc_context_reconstruct(ctx, params, mesh)
      call check(status, 'nbmc_context_reconstruct')
      status = nbmc_context_stats(ctx, stats)
      call check(status, 'nbmc_context_stats')
      call write_obj(mesh, step)
      write (output_unit, '(a, i3, a, i0, a, i0, a, f6.3, a)') 'step ', step, ': ', &
           nbmc_mesh_vertex_count(mesh), ' vertices, ', nbmc_mesh_triangle_count(mesh), &
           ' triangles (', stats%total_seconds, ' s)'
      frames = frames + 1
    end if

    ! Advance: gravity, floor contact per layer, rigid spin about the y axis.
    c = cos(omega * dt)
    s = sin(omega * dt)
    do i = 1, n
      state(5, i) = state(5, i) + gravity * dt
      state(2, i) = state(2, i) + state(5, i) * dt
      if (state(2, i) < rest_height(i)) then
        state(2, i) = rest_height(i)
        state(5, i) = -restitution * state(5, i)
      end if
      x = state(1, i) - cx
      z = state(3, i) - cz
      state(1, i) = cx + c * x - s * z
      state(3, i) = cz + s * x + c * z
    end do
  end do

  ! The attributes interpolated onto the last mesh: pointers (components, nv)
  ! into it. A layer height is a kernel mean of rest heights: within their range.
  block
    real(c_float), pointer :: vel(:, :), layer(:, :), none(:, :)
    integer(c_int32_t) :: comps
    character(len=:), allocatable :: first
    integer(c_int64_t) :: nv
    first = nbmc_mesh_attribute_name(mesh, 1_c_int32_t)
    if (nbmc_mesh_attribute_count(mesh) /= 2 .or. first /= 'velocity') &
         error stop 'expected the attributes velocity and layer'
    nv = nbmc_mesh_vertex_count(mesh)
    vel => nbmc_mesh_attribute(mesh, 'velocity', comps)
    if (.not. associated(vel)) error stop 'velocity attribute missing'
    if (comps /= 3 .or. size(vel, 2, kind=c_int64_t) /= nv) error stop 'velocity attribute of the wrong shape'
    layer => nbmc_mesh_attribute(mesh, 'layer')
    if (.not. associated(layer)) error stop 'layer attribute missing'
    if (minval(layer) < -1e-6 .or. maxval(layer) > (ny - 1) * spacing + 1e-6) error stop 'layer out of range'
    none => nbmc_mesh_attribute(mesh, 'nope', comps)
    if (associated(none)) error stop 'unknown attribute found'
    if (comps /= 0) error stop 'unknown attribute has components'
    write (output_unit, '(a, f8.4, a, f8.4)') 'layer on the mesh: ', minval(layer), ' to ', maxval(layer)
  end block

  ! The last mesh once more, through nbmc's own writer (binary PLY, with the
  ! attributes).
  status = nbmc_mesh_write(mesh, outdir // '/final.ply')
  if (status /= NBMC_OK) then
    write (error_unit, '(a, a, a, a)') 'error: nbmc_mesh_write failed: ', nbmc_status_string(status), ': ', &
         nbmc_last_error()
    error stop 1
  end if

  ! Where the mesh lives, and a copy into Fortran arrays: what a GPU solver
  ! with NBMC_MEMORY_DEVICE meshes would use (see nbmc.f90); here the mesh is
  ! in host memory and the copy equals the arrays the pointers show.
  if (nbmc_mesh_memory(mesh) /= NBMC_MEMORY_HOST) error stop 'expected a mesh in host memory'
  allocate (vcopy(3, nbmc_mesh_vertex_count(mesh)), tcopy(3, nbmc_mesh_triangle_count(mesh)))
  status = nbmc_mesh_copy_to_host(mesh, positions=vcopy, triangles=tcopy)
  call check(status, 'nbmc_mesh_copy_to_host')
  if (maxval(abs(vcopy - nbmc_mesh_positions(mesh))) > 0 .or. any(tcopy /= nbmc_mesh_triangles(mesh))) &
       error stop 'nbmc_mesh_copy_to_host differs from the mesh'
  ! Double-precision positions (params%double_positions): the same surface,
  ! its positions in real(c_double); a float mesh has none.
  if (associated(nbmc_mesh_positions_f64(mesh))) error stop 'a float mesh has double positions'
  params%double_positions = 1
  status = nbmc_context_reconstruct(ctx, params, mesh)
  call check(status, 'nbmc_context_reconstruct (double_positions)')
  if (.not. associated(nbmc_mesh_positions_f64(mesh))) error stop 'double positions missing'
  if (maxval(abs(real(nbmc_mesh_positions_f64(mesh), c_float) - nbmc_mesh_positions(mesh))) > 0) &
       error stop 'the float positions are not the doubles rounded'
  params%double_positions = 0
  ! Decimation to a quarter of the triangles (the mesh stays closed), and
  ! isolated particles (clusters of fewer than min_cluster) as spheres
  ! s(4, n): x, y, z, radius; here every particle is in the block, so none.
  params%decimate_fraction = 0.25d0
  params%isolated = NBMC_ISOLATED_SPHERE
  status = nbmc_context_reconstruct(ctx, params, mesh)
  call check(status, 'nbmc_context_reconstruct (decimate_fraction, NBMC_ISOLATED_SPHERE)')
  status = nbmc_context_stats(ctx, stats)
  call check(status, 'nbmc_context_stats')
  if (nbmc_mesh_triangle_count(mesh) /= stats%triangle_count .or. &
      4 * stats%triangle_count > stats%pre_decimation_triangle_count + 3) error stop 'decimation: counts'
  ! The clean-up's counts account for every triangle it removed.
  if (stats%raw_triangle_count - stats%pre_decimation_triangle_count /= &
      2 * stats%cleanup_collapses + 6 * stats%cleanup_cuts + stats%cleanup_removed_component_triangles .or. &
      stats%cleanup_bad_triangles_after > stats%cleanup_bad_triangles_before) error stop 'clean-up: counts'
  if (nbmc_mesh_sphere_count(mesh) /= stats%dropped_particle_count) error stop 'spheres: count'
  if (nbmc_mesh_sphere_count(mesh) == 0 .and. associated(nbmc_mesh_spheres(mesh))) error stop 'spheres: none expected'
  params%decimate_fraction = 1
  params%isolated = NBMC_ISOLATED_KEEP
  ! Per-particle radii: all equal to the spacing give the mesh without radii;
  ! the lower layers half as large give another closed surface; bad radii a
  ! clear status; clearing them gives the first mesh back.
  block
    real(c_double), allocatable :: radii(:)
    integer(c_int64_t) :: nv0, nt0
    status = nbmc_context_reconstruct(ctx, params, mesh)
    call check(status, 'nbmc_context_reconstruct (no radii)')
    nv0 = nbmc_mesh_vertex_count(mesh)
    nt0 = nbmc_mesh_triangle_count(mesh)
    allocate (radii(n))
    radii = spacing
    status = nbmc_context_set_radii(ctx, radii)
    call check(status, 'nbmc_context_set_radii (equal)')
    status = nbmc_context_reconstruct(ctx, params, mesh)
    call check(status, 'nbmc_context_reconstruct (equal radii)')
    if (nbmc_mesh_vertex_count(mesh) /= nv0 .or. nbmc_mesh_triangle_count(mesh) /= nt0) &
         error stop 'equal radii changed the mesh'
    where (rest_height < 0.5d0 * (ny - 1) * spacing) radii = 0.5d0 * spacing
    status = nbmc_context_set_radii(ctx, real(radii, c_float))
    call check(status, 'nbmc_context_set_radii (two sizes)')
    status = nbmc_context_reconstruct(ctx, params, mesh)
    call check(status, 'nbmc_context_reconstruct (two sizes)')
    if (nbmc_mesh_triangle_count(mesh) == nt0) error stop 'two radii gave the uniform mesh'
    write (output_unit, '(a, i0, a)') 'radii of two sizes: ', nbmc_mesh_triangle_count(mesh), ' triangles'
    radii(1) = -1
    if (nbmc_context_set_radii(ctx, radii) /= NBMC_ERROR_INVALID_PARAMETER) error stop 'a negative radius passed'
    if (nbmc_context_set_radii(ctx, radii(2:)) /= NBMC_ERROR_INVALID_ARGUMENT) error stop 'a short radii array passed'
    status = nbmc_context_clear_radii(ctx)
    call check(status, 'nbmc_context_clear_radii')
    status = nbmc_context_reconstruct(ctx, params, mesh)
    call check(status, 'nbmc_context_reconstruct (radii cleared)')
    if (nbmc_mesh_triangle_count(mesh) /= nt0) error stop 'clearing the radii did not restore the mesh'
  end block
  ! Device memory needs the CUDA backend; elsewhere the call fails cleanly.
  if (backend /= NBMC_BACKEND_CUDA) then
    status = nbmc_context_set_mesh_memory(ctx, NBMC_MEMORY_DEVICE)
    if (status /= NBMC_ERROR_BACKEND_UNAVAILABLE) then
      write (error_unit, '(a, i0)') 'error: expected NBMC_ERROR_BACKEND_UNAVAILABLE, got ', status
      error stop 1
    end if
    write (output_unit, '(a, a)') 'expected failure: ', nbmc_context_last_error(ctx)
  end if

  ! ----------------------------------------------------------------- clean-up
  call nbmc_mesh_close(mesh)
  call nbmc_context_close(ctx)
  if (c_associated(ctx%ptr) .or. c_associated(mesh%ptr)) error stop 'close did not null the handles'
  call nbmc_context_close(ctx)                    ! closing a null handle is a no-op
  status = nbmc_kokkos_finalize()                 ! Kokkos was started by nbmc
  call check(status, 'nbmc_kokkos_finalize')
  write (output_unit, '(i0, a, a)') frames, ' meshes written to ', outdir

contains

  subroutine check(status, what)
    integer(c_int32_t), intent(in) :: status
    character(len=*), intent(in) :: what
    if (status == NBMC_OK) return
    write (error_unit, '(a, a, a, a, i0, a, a)') 'error: ', what, ' failed: ', &
         nbmc_status_string(status), ' (status ', status, '): ', nbmc_context_last_error(ctx)
    call nbmc_mesh_close(mesh)
    call nbmc_context_close(ctx)
    error stop 1
  end subroutine check

  ! Writes frame_NNNN.obj: positions, normals, 1-based faces. The mesh arrays
  ! are pointers into nbmc's memory: no copy is made.
  subroutine write_obj(mesh, step)
    type(nbmc_mesh), intent(in) :: mesh
    integer, intent(in) :: step
    real(c_float), pointer :: pos(:, :), nrm(:, :)
    integer(c_int32_t), pointer :: tri(:, :)
    integer(c_int64_t) :: k, nv
    integer :: u, ios
    character(len=:), allocatable :: path
    character(len=16) :: name

    pos => nbmc_mesh_positions(mesh)
    nrm => nbmc_mesh_normals(mesh)
    tri => nbmc_mesh_triangles(mesh)
    nv = nbmc_mesh_vertex_count(mesh)
    if (.not. associated(pos) .or. .not. associated(tri)) then
      write (error_unit, '(a, i0)') 'error: empty mesh at step ', step
      error stop 1
    end if
    if (any(tri < 0) .or. any(tri >= nv)) error stop 'triangle index out of range'

    write (name, '(a, i4.4, a)') 'frame_', step, '.obj'
    path = outdir // '/' // trim(name)
    open (newunit=u, file=path, status='replace', action='write', iostat=ios)
    if (ios /= 0) then
      write (error_unit, '(a, a)') 'error: cannot create ', path
      error stop 1
    end if
    write (u, '(a, i0)') '# nbmc Fortran example, step ', step
    do k = 1, nv
      write (u, '(a, 3(1x, es15.8))') 'v', pos(:, k)
    end do
    if (associated(nrm)) then
      do k = 1, nv
        write (u, '(a, 3(1x, f10.7))') 'vn', nrm(:, k)
      end do
      do k = 1, size(tri, 2, kind=c_int64_t)
        write (u, '(a, 3(1x, i0, a, i0))') 'f', (tri(i, k) + 1, '//', tri(i, k) + 1, i = 1, 3)
      end do
    else
      do k = 1, size(tri, 2, kind=c_int64_t)
        write (u, '(a, 3(1x, i0))') 'f', tri(:, k) + 1
      end do
    end if
    close (u, iostat=ios)
    if (ios /= 0) then
      write (error_unit, '(a, a)') 'error: cannot write ', path
      error stop 1
    end if
  end subroutine write_obj

end program example
