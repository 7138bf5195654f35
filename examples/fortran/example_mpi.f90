! SPDX-License-Identifier: MIT
!
! nbmc in situ from an MPI Fortran solver (mpi_f08): every rank owns a slab of
! a block of particles, reconstructs collectively, and checks that the pieces
! carry consistent global vertex ids and that the gathered mesh equals what
! one process makes of all the particles.
!
!   mpirun -n 3 ./example_mpi
program example_mpi
  use, intrinsic :: iso_c_binding
  use mpi_f08
  use nbmc
  use nbmc_mpi
  implicit none
  integer, parameter :: nx = 24, ny = 14, nz = 12
  real(c_double), parameter :: r = 0.05d0
  real(c_double), allocatable :: all(:, :), mine(:, :)
  type(nbmc_context) :: ctx, whole
  type(nbmc_mesh) :: piece, mesh, ref
  type(nbmc_params) :: params
  integer(c_int64_t), pointer :: ids(:)
  integer(c_int64_t) :: max_id, total
  integer(c_int64_t) :: nv, nv_ref, nt, nt_ref
  integer :: rank, nranks, i, j, k, n, m

  call MPI_Init()
  call MPI_Comm_rank(MPI_COMM_WORLD, rank)
  call MPI_Comm_size(MPI_COMM_WORLD, nranks)

  ! The same block on every rank (slightly wavy, so that surfaces are not flat).
  allocate(all(3, nx * ny * nz))
  n = 0
  do k = 0, nz - 1
    do j = 0, ny - 1
      do i = 0, nx - 1
        n = n + 1
        all(:, n) = [i * r, j * r + 0.01d0 * sin(0.7d0 * i), k * r + 0.01d0 * cos(0.5d0 * j)]
      end do
    end do
  end do
  ! This rank's slab along x.
  m = count(int(all(1, :) / (nx * r) * nranks) == rank)
  allocate(mine(3, m))
  mine = reshape(pack(all, spread(int(all(1, :) / (nx * r) * nranks) == rank, 1, 3)), [3, m])

  call check(nbmc_context_create(ctx), 'nbmc_context_create', ctx)
  call check(nbmc_mpi_context_set_comm(ctx, MPI_COMM_WORLD), 'nbmc_mpi_context_set_comm', ctx)
  call check(nbmc_context_set_particles(ctx, mine), 'nbmc_context_set_particles', ctx)
  call nbmc_params_init(params, spacing=r)

  ! Pieces with global vertex ids.
  call check(nbmc_mpi_reconstruct(ctx, params, NBMC_MPI_PIECES, 0_c_int32_t, piece), 'pieces', ctx)
  ids => nbmc_mesh_global_vertex_ids(piece)
  if (.not. associated(ids)) error stop 'a piece without global vertex ids'
  total = nbmc_mesh_global_vertex_count(piece)
  max_id = maxval(ids)
  call MPI_Allreduce(MPI_IN_PLACE, max_id, 1, MPI_INTEGER8, MPI_MAX, MPI_COMM_WORLD)
  if (max_id /= total - 1) error stop 'global vertex ids do not run from 0 to count - 1'
  write (*, '(a, i0, a, i0, a, i0, a)') 'rank ', rank, ': piece of ', nbmc_mesh_vertex_count(piece), &
    ' vertices (', total, ' in the whole mesh)'

  ! The whole mesh on rank 0, and the same of all particles in one process.
  call check(nbmc_mpi_reconstruct(ctx, params, NBMC_MPI_GATHER, 0_c_int32_t, mesh), 'gather', ctx)
  if (rank == 0) then
    call check(nbmc_context_create(whole), 'nbmc_context_create', whole)
    call check(nbmc_context_set_particles(whole, all), 'nbmc_context_set_particles', whole)
    call check(nbmc_context_reconstruct(whole, params, ref), 'nbmc_context_reconstruct', whole)
    nv = nbmc_mesh_vertex_count(mesh)
    nv_ref = nbmc_mesh_vertex_count(ref)
    nt = nbmc_mesh_triangle_count(mesh)
    nt_ref = nbmc_mesh_triangle_count(ref)
    if (nv /= nv_ref .or. nt /= nt_ref) error stop 'gathered mesh differs'
    if (maxval(abs(nbmc_mesh_positions(mesh) - nbmc_mesh_positions(ref))) > 0.0) error stop 'gathered positions differ'
    write (*, '(a, i0, a, i0, a)') 'gathered on rank 0: ', nt, &
      ' triangles, the same as one process (', nranks, ' ranks)'
    call nbmc_mesh_close(ref)
    call nbmc_context_close(whole)
  else
    if (nbmc_mesh_triangle_count(mesh) /= 0) error stop 'a non-root rank got a mesh'
  end if
  call nbmc_mesh_close(piece)
  call nbmc_mesh_close(mesh)
  call nbmc_context_close(ctx)
  call MPI_Finalize()

contains

  subroutine check(st, what, c)
    integer(c_int32_t), intent(in) :: st
    character(*), intent(in) :: what
    type(nbmc_context), intent(in) :: c
    if (st /= NBMC_OK) then
      print *, what, ' failed: ', nbmc_context_last_error(c)
      error stop 1
    end if
  end subroutine check

end program example_mpi
