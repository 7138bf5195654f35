! SPDX-License-Identifier: MIT
!
! Fortran 2008 bindings of include/nbmc_mpi.h (libnbmc_mpi) for mpi_f08
! programs: the communicator goes to C as its Fortran handle (MPI_VAL), which
! the library converts with MPI_Comm_f2c. Build with the MPI Fortran compiler
! (mpifort) and link nbmc::nbmc_mpi.
!
!   use mpi_f08
!   use nbmc
!   use nbmc_mpi
!   status = nbmc_mpi_context_set_comm(ctx, MPI_COMM_WORLD)   ! collective
!   status = nbmc_context_set_particles(ctx, my_pos)           ! the particles this rank owns
!   status = nbmc_mpi_reconstruct(ctx, params, NBMC_MPI_PIECES, 0, mesh)
!   ids => nbmc_mesh_global_vertex_ids(mesh)                   ! 0-based ids, one per vertex
module nbmc_mpi
  use, intrinsic :: iso_c_binding
  use mpi_f08, only: MPI_Comm
  use nbmc, only: nbmc_context, nbmc_mesh, nbmc_params, nbmc_mesh_close, nbmc_mesh_vertex_count
  implicit none
  private

  integer(c_int32_t), parameter, public :: NBMC_MPI_GATHER = 0 ! the whole mesh on the root
  integer(c_int32_t), parameter, public :: NBMC_MPI_PIECES = 1 ! every rank its piece

  public :: nbmc_mpi_context_set_comm, nbmc_mpi_reconstruct, nbmc_mesh_global_vertex_ids
  public :: nbmc_mesh_global_vertex_count, nbmc_mpi_context_rank, nbmc_mpi_context_size

  interface
    function c_set_comm_f(ctx, comm) bind(c, name="nbmc_mpi_context_set_comm_f") result(status)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: ctx
      integer(c_int32_t), value :: comm
      integer(c_int32_t) :: status
    end function c_set_comm_f
    function c_mpi_reconstruct(ctx, params, output, root, mesh) bind(c, name="nbmc_mpi_reconstruct") result(status)
      import :: c_ptr, c_int32_t, nbmc_params
      type(c_ptr), value :: ctx
      type(nbmc_params), intent(in) :: params
      integer(c_int32_t), value :: output, root
      type(c_ptr), intent(out) :: mesh
      integer(c_int32_t) :: status
    end function c_mpi_reconstruct
    function c_rank(ctx) bind(c, name="nbmc_mpi_context_rank") result(r)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: ctx
      integer(c_int32_t) :: r
    end function c_rank
    function c_size(ctx) bind(c, name="nbmc_mpi_context_size") result(r)
      import :: c_ptr, c_int32_t
      type(c_ptr), value :: ctx
      integer(c_int32_t) :: r
    end function c_size
    function c_global_ids(mesh) bind(c, name="nbmc_mesh_global_vertex_ids") result(p)
      import :: c_ptr
      type(c_ptr), value :: mesh
      type(c_ptr) :: p
    end function c_global_ids
    function c_global_count(mesh) bind(c, name="nbmc_mesh_global_vertex_count") result(n)
      import :: c_ptr, c_int64_t
      type(c_ptr), value :: mesh
      integer(c_int64_t) :: n
    end function c_global_count
  end interface

contains

  !> Binds ctx to (a duplicate of) comm; collective over comm.
  function nbmc_mpi_context_set_comm(ctx, comm) result(status)
    type(nbmc_context), intent(inout) :: ctx
    type(MPI_Comm), intent(in) :: comm
    integer(c_int32_t) :: status
    status = c_set_comm_f(ctx%ptr, int(comm%MPI_VAL, c_int32_t))
  end function nbmc_mpi_context_set_comm

  !> Collective reconstruction of the particles of all ranks.
  function nbmc_mpi_reconstruct(ctx, params, output, root, mesh) result(status)
    type(nbmc_context), intent(inout) :: ctx
    type(nbmc_params), intent(in) :: params
    integer(c_int32_t), intent(in) :: output, root
    type(nbmc_mesh), intent(inout) :: mesh
    integer(c_int32_t) :: status
    call nbmc_mesh_close(mesh)
    status = c_mpi_reconstruct(ctx%ptr, params, output, root, mesh%ptr)
  end function nbmc_mpi_reconstruct

  integer(c_int32_t) function nbmc_mpi_context_rank(ctx)
    type(nbmc_context), intent(in) :: ctx
    nbmc_mpi_context_rank = c_rank(ctx%ptr)
  end function nbmc_mpi_context_rank

  integer(c_int32_t) function nbmc_mpi_context_size(ctx)
    type(nbmc_context), intent(in) :: ctx
    nbmc_mpi_context_size = c_size(ctx%ptr)
  end function nbmc_mpi_context_size

  !> A piece's global vertex ids (0-based; null for a mesh that is no piece),
  !> valid until the mesh is closed.
  function nbmc_mesh_global_vertex_ids(mesh) result(ids)
    type(nbmc_mesh), intent(in) :: mesh
    integer(c_int64_t), pointer :: ids(:)
    type(c_ptr) :: p
    ids => null()
    p = c_global_ids(mesh%ptr)
    if (c_associated(p)) call c_f_pointer(p, ids, [nbmc_mesh_vertex_count(mesh)])
  end function nbmc_mesh_global_vertex_ids

  integer(c_int64_t) function nbmc_mesh_global_vertex_count(mesh)
    type(nbmc_mesh), intent(in) :: mesh
    nbmc_mesh_global_vertex_count = c_global_count(mesh%ptr)
  end function nbmc_mesh_global_vertex_count

end module nbmc_mpi
