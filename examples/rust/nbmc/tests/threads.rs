// SPDX-License-Identifier: MIT
//! The thread-safety contract of nbmc.h: a context may move between threads,
//! and different contexts may run on different threads at once.
//! (Kokkos 3.4 accepts work only from the thread that initialised it; nbmc
//! runs Kokkos on a thread of its own, so any calling thread works.)
use nbmc::{Backend, Context, ContextOptions, Params};
use std::path::PathBuf;
use std::sync::Arc;

fn sample() -> Vec<[f32; 3]> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/double_dam_break_4732.xyz");
    let bytes = std::fs::read(path).unwrap();
    let f = |b: &[u8]| f32::from_le_bytes(b.try_into().unwrap());
    bytes.chunks_exact(12).map(|p| [f(&p[0..4]), f(&p[4..8]), f(&p[8..12])]).collect()
}

fn reconstruct_on_new_threads(backend: Backend) {
    let particles = Arc::new(sample());
    // One context created here and moved, two created on their threads.
    let mut moved = Context::with_options(ContextOptions { backend, ..Default::default() }).unwrap();
    moved.set_particles_f32(&particles).unwrap();
    let mut handles =
        vec![std::thread::spawn(move || moved.reconstruct(&Params::new(0.05)).map(|m| m.triangle_count()))];
    for _ in 0..2 {
        let p = Arc::clone(&particles);
        handles.push(std::thread::spawn(move || {
            let mut ctx = Context::with_options(ContextOptions { backend, ..Default::default() })?;
            ctx.set_particles_f32(&p)?;
            ctx.reconstruct(&Params::new(0.05)).map(|m| m.triangle_count())
        }));
    }
    let counts: Vec<usize> = handles.into_iter().map(|h| h.join().unwrap().unwrap()).collect();
    assert!(counts.iter().all(|&c| c > 0 && c == counts[0]), "{counts:?}");
}

#[test]
fn contexts_on_several_threads_auto_backend() {
    reconstruct_on_new_threads(Backend::Auto);
}

#[test]
fn contexts_on_several_threads_serial_backend() {
    reconstruct_on_new_threads(Backend::Serial);
}
