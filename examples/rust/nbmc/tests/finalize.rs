// SPDX-License-Identifier: MIT
//! nbmc_kokkos_finalize: its own process (test binary), because no context can
//! be created after it.
use nbmc::{Context, Error, Params};

#[test]
fn finalize_after_the_last_context() {
    let mut ctx = Context::new().unwrap();
    ctx.set_particles_f64(&[[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.05, 0.0]]).unwrap();
    let mesh = ctx.reconstruct(&Params::new(0.05)).unwrap();

    // Refused while a context is alive.
    assert_eq!(nbmc::kokkos_finalize().unwrap_err().code, Error::INVALID_ARGUMENT);
    drop(ctx);
    nbmc::kokkos_finalize().unwrap();
    // Meshes stay valid after the runtime is gone.
    let _ = mesh.positions().len();
    drop(mesh);
    // Kokkos cannot be initialised twice in one process.
    assert_eq!(Context::new().unwrap_err().code, Error::BACKEND_UNAVAILABLE);
    // A second finalize is harmless.
    nbmc::kokkos_finalize().unwrap();
}
