// SPDX-License-Identifier: MIT
//! The safe API on the repository's sample frame, and its error paths with
//! their exact status codes.
//!
//! This test binary has its own runner (`harness = false`) so that every test
//! runs on the main thread: with nbmc 0.1.0 a context can only reconstruct on
//! the thread that initialised Kokkos (see tests/threads.rs), while libtest
//! runs each test on a thread of its own.
//!
//!   cargo test --test api [-- FILTER]
use nbmc::{
    Backend, Context, ContextOptions, Error, Isolated, LengthUnit, Memory, Mesh, Params, SmoothWeighting, Stage,
};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

const SPACING: f64 = 0.05;

fn sample_particles() -> Vec<[f32; 3]> {
    sample()
}

fn sample() -> Vec<[f32; 3]> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/double_dam_break_4732.xyz");
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let f = |b: &[u8]| f32::from_le_bytes(b.try_into().unwrap());
    bytes.chunks_exact(12).map(|p| [f(&p[0..4]), f(&p[4..8]), f(&p[8..12])]).collect()
}

/// Every triangle index is in range and every edge is shared by exactly two
/// triangles in opposite directions (closed, consistently oriented).
fn assert_closed(mesh: &Mesh) {
    let n = mesh.vertex_count() as u32;
    let mut edges = std::collections::HashMap::new();
    for t in mesh.triangles() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            assert!(a < n && b < n, "index out of range");
            *edges.entry((a, b)).or_insert(0) += 1;
        }
    }
    for (&(a, b), &c) in &edges {
        assert_eq!(c, 1, "directed edge ({a},{b}) used {c} times");
        assert_eq!(edges.get(&(b, a)), Some(&1), "edge ({a},{b}) has no opposite");
    }
}

fn reconstructs_the_sample_frame() {
    let particles = sample();
    assert_eq!(particles.len(), 4732);
    let mut ctx = Context::new().unwrap();
    ctx.set_particles_f32(&particles).unwrap();
    let mesh = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    assert!(mesh.triangle_count() > 10_000, "{mesh:?}");
    assert_eq!(mesh.positions().len(), mesh.vertex_count());
    assert_eq!(mesh.triangles().len(), mesh.triangle_count());
    let normals = mesh.normals().expect("normals are on by default");
    assert_eq!(normals.len(), mesh.vertex_count());
    for n in normals {
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!((l - 1.0).abs() < 1e-3, "normal length {l}");
    }
    assert_closed(&mesh);

    let stats = ctx.stats().unwrap();
    assert_eq!(stats.particle_count, 4732);
    assert_eq!(stats.triangle_count as usize, mesh.triangle_count());
    assert!(stats.total_seconds > 0.0);
    assert!((stats.cell_size - 0.5 * SPACING).abs() < 1e-12);
}

fn f32_f64_and_strided_uploads_agree() {
    let particles = sample();
    let mut ctx = Context::with_options(ContextOptions { num_threads: 2, ..Default::default() }).unwrap();
    ctx.set_particles_f32(&particles).unwrap();
    let a = ctx.reconstruct(&Params::new(SPACING)).unwrap();

    let doubles: Vec<[f64; 3]> = particles.iter().map(|p| p.map(f64::from)).collect();
    ctx.set_particles_f64(&doubles).unwrap();
    let b = ctx.reconstruct(&Params::new(SPACING)).unwrap();

    // [x, y, z, vx, vy, vz] per particle
    let interleaved: Vec<f32> = particles.iter().flat_map(|p| [p[0], p[1], p[2], 9.0, 9.0, 9.0]).collect();
    ctx.set_particles_strided_f32(&interleaved, particles.len(), 6).unwrap();
    let c = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    let interleaved64: Vec<f64> = doubles.iter().flat_map(|p| [p[0], p[1], p[2], -1.0]).collect();
    ctx.set_particles_strided_f64(&interleaved64, doubles.len(), 4).unwrap();
    let d = ctx.reconstruct(&Params::new(SPACING)).unwrap();

    for m in [&b, &c, &d] {
        assert_eq!(m.triangles(), a.triangles());
        assert_eq!(m.positions(), a.positions());
    }
}

fn mesh_outlives_its_context_and_is_shared_between_threads() {
    let particles = sample();
    let mut ctx = Context::new().unwrap();
    // Context is Send: upload on another thread (uploads do not touch Kokkos),
    // then move it back and reconstruct here.
    let mut ctx = std::thread::spawn(move || {
        ctx.set_particles_f32(&particles).unwrap();
        ctx
    })
    .join()
    .unwrap();
    let mesh = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    drop(ctx);
    assert!(mesh.triangle_count() > 0);
    // Mesh is Send + Sync: read it from two threads at once, drop it on a third.
    let mesh = Arc::new(mesh);
    let handles: Vec<_> = (0..2)
        .map(|_| {
            let m = Arc::clone(&mesh);
            std::thread::spawn(move || m.positions().iter().map(|p| p[1] as f64).sum::<f64>())
        })
        .collect();
    let sums: Vec<f64> = handles.into_iter().map(|h| h.join().unwrap()).collect();
    assert_eq!(sums[0], sums[1]);
    let m = Arc::try_unwrap(mesh).unwrap();
    std::thread::spawn(move || drop(m)).join().unwrap();
}

fn params_follow_the_library_defaults() {
    let p = Params::new(0.1);
    assert_eq!(p.length_unit, LengthUnit::Spacing);
    assert_eq!((p.cell_size, p.influence_radius, p.band_width), (0.5, 4.0, 2.0));
    assert_eq!((p.t_low, p.t_high, p.neighbour_threshold), (0.4, 3.5, 25));
    assert!(p.compute_normals && p.bbox.is_none());
    let raw = p.to_raw();
    assert_eq!(raw.struct_size as usize, std::mem::size_of::<nbmc_sys::nbmc_params>());
    assert_eq!(raw.spacing, 0.1);
    assert_eq!(raw.use_bbox, 0);

    // Absolute lengths and no normals reconstruct the same surface as the relative defaults.
    let particles = sample();
    let mut ctx = Context::new().unwrap();
    ctx.set_particles_f32(&particles).unwrap();
    let rel = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    let mut abs = Params::new(SPACING);
    abs.length_unit = LengthUnit::Absolute;
    abs.cell_size *= SPACING;
    abs.influence_radius *= SPACING;
    abs.band_width *= SPACING;
    abs.surface_radius *= SPACING;
    abs.iso_radius *= SPACING;
    abs.max_distance *= SPACING;
    abs.compute_normals = false;
    let m = ctx.reconstruct(&abs).unwrap();
    assert_eq!(m.triangle_count(), rel.triangle_count());
    assert!(m.normals().is_none());
}

fn errors_carry_exact_codes_and_messages() {
    let mut ctx = Context::new().unwrap();

    let e = ctx.reconstruct(&Params::new(SPACING)).unwrap_err();
    assert_eq!(e.code, Error::NO_PARTICLES, "{e}");

    let e = ctx.set_particles_f32(&[]).unwrap_err();
    assert_eq!(e.code, Error::NO_PARTICLES, "{e}");

    let e = ctx.set_particles_f32(&[[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0]]).unwrap_err();
    assert_eq!(e.code, Error::INVALID_PARTICLES);
    assert!(e.message.contains("particle 1"), "{e}");
    let e = ctx.set_particles_f64(&[[f64::INFINITY, 0.0, 0.0]]).unwrap_err();
    assert_eq!(e.code, Error::INVALID_PARTICLES);

    let e = ctx.set_particles_strided_f32(&[0.0; 6], 2, 4).unwrap_err();
    assert_eq!(e.code, Error::INVALID_ARGUMENT, "short slice: {e}");
    let e = ctx.set_particles_strided_f32(&[0.0; 8], 2, 2).unwrap_err();
    assert_eq!(e.code, Error::INVALID_ARGUMENT, "stride < 3: {e}");

    ctx.set_particles_f32(&sample()).unwrap();
    for bad in [0.0, -1.0, f64::NAN] {
        let e = ctx.reconstruct(&Params::new(bad)).unwrap_err();
        assert_eq!(e.code, Error::INVALID_PARAMETER);
        assert!(e.message.contains("spacing"), "{e}");
    }
    let mut p = Params::new(SPACING);
    p.t_low = 5.0;
    let e = ctx.reconstruct(&p).unwrap_err();
    assert_eq!(e.code, Error::INVALID_PARAMETER, "{e}");
    let mut p = Params::new(SPACING);
    p.cell_size = 1e-9;
    let e = ctx.reconstruct(&p).unwrap_err();
    assert_eq!(e.code, Error::DOMAIN_TOO_LARGE, "{e}");
    assert_eq!(e.status_name(), "domain too large");
    assert!(e.to_string().contains("status 5"));

    // The context stays usable after failures.
    assert!(ctx.reconstruct(&Params::new(SPACING)).unwrap().triangle_count() > 0);
}

fn unavailable_backend_and_bad_options() {
    if !Backend::Cuda.is_available() {
        let e = Context::with_options(ContextOptions { backend: Backend::Cuda, ..Default::default() }).unwrap_err();
        assert_eq!(e.code, Error::BACKEND_UNAVAILABLE);
        assert!(e.message.contains("cuda"), "{e}");
    }
    let e = Context::with_options(ContextOptions { num_threads: -1, ..Default::default() }).unwrap_err();
    assert_eq!(e.code, Error::INVALID_ARGUMENT);
    assert!(Backend::Serial.is_available());
    let ctx = Context::with_options(ContextOptions { backend: Backend::Serial, ..Default::default() }).unwrap();
    assert_eq!(ctx.backend().unwrap(), Backend::Serial);
    assert_eq!(ctx.stats().unwrap_err().code, Error::NO_PARTICLES);
}

fn progress_reports_stages_and_can_cancel() {
    let particles = sample();
    let mut ctx = Context::new().unwrap();
    ctx.set_particles_f32(&particles).unwrap();

    let calls = Arc::new(AtomicUsize::new(0));
    let c = Arc::clone(&calls);
    ctx.set_progress(move |stage, fraction| {
        assert!((0.0..=1.0).contains(&fraction), "{stage:?} {fraction}");
        c.fetch_add(1, Ordering::Relaxed);
        true
    })
    .unwrap();
    ctx.reconstruct(&Params::new(SPACING)).unwrap();
    assert!(calls.load(Ordering::Relaxed) > 0);

    ctx.set_progress(|stage, _| stage != Stage::Field).unwrap();
    let e = ctx.reconstruct(&Params::new(SPACING)).unwrap_err();
    assert_eq!(e.code, Error::CANCELLED, "{e}");

    ctx.clear_progress().unwrap();
    assert!(ctx.reconstruct(&Params::new(SPACING)).is_ok());
}

fn a_panic_in_the_progress_callback_does_not_cross_c() {
    let particles = sample();
    let mut ctx = Context::new().unwrap();
    ctx.set_particles_f32(&particles).unwrap();
    ctx.set_progress(|_, _| panic!("from the callback")).unwrap();
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {})); // the panic is expected: keep the output clean
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| ctx.reconstruct(&Params::new(SPACING))));
    std::panic::set_hook(hook);
    let payload = r.expect_err("the panic is resumed after the C call returned");
    assert_eq!(payload.downcast_ref::<&str>(), Some(&"from the callback"));
    ctx.clear_progress().unwrap();
    assert!(ctx.reconstruct(&Params::new(SPACING)).is_ok());
}

fn file_io_round_trip() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("nbmc-rust-io-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let sample = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/double_dam_break_4732.xyz");

    let mut ctx = Context::new().unwrap();
    assert_eq!(ctx.load_particles(&sample, None).unwrap(), 4732);
    let a = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    ctx.set_particles_f32(&sample_particles()).unwrap();
    let b = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    assert_eq!(a.triangles(), b.triangles(), "load_particles and set_particles_f32 agree");

    let ply = dir.join("mesh.ply");
    a.write(&ply, None).unwrap();
    assert!(std::fs::read(&ply).unwrap().starts_with(b"ply"));
    a.write(dir.join("mesh.bin"), Some("obj")).unwrap();

    let e = ctx.load_particles(dir.join("missing.xyz"), None).unwrap_err();
    assert_eq!(e.code, Error::IO, "{e}");
    assert!(e.message.contains("missing.xyz"), "{e}");
    let e = ctx.load_particles(&sample, Some("no-such-format")).unwrap_err();
    assert_eq!(e.code, Error::INVALID_ARGUMENT, "{e}");
    std::fs::write(dir.join("odd.xyz"), [0u8; 13]).unwrap();
    let e = ctx.load_particles(dir.join("odd.xyz"), None).unwrap_err();
    assert_eq!(e.code, Error::FORMAT, "{e}");
    // Failed loads leave no particles behind.
    assert_eq!(ctx.reconstruct(&Params::new(SPACING)).unwrap_err().code, Error::NO_PARTICLES);

    let e = a.write(dir.join("no-such-dir/mesh.ply"), None).unwrap_err();
    assert_eq!(e.code, Error::IO, "{e}");
    assert!(!e.message.is_empty());
    let e = a.write(dir.join("mesh.ply"), Some("no-such-format")).unwrap_err();
    assert_eq!(e.code, Error::INVALID_ARGUMENT, "{e}");
    let e = a.write(dir.join("nul\0name.ply"), None).unwrap_err();
    assert_eq!(e.code, Error::INVALID_ARGUMENT, "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The device-memory calls need the CUDA backend: a CPU context answers them
/// with BACKEND_UNAVAILABLE before reading the pointer, keeps no particles and
/// stays usable.
fn device_memory_needs_the_cuda_backend() {
    assert_eq!((Memory::Host.raw(), Memory::Device.raw()), (0, 1));
    assert_eq!(Memory::from_raw(1), Some(Memory::Device));
    assert_eq!(Memory::from_raw(7), None);
    for backend in [Backend::Serial, Backend::OpenMp] {
        if !backend.is_available() {
            continue;
        }
        let mut ctx = Context::with_options(ContextOptions { backend, ..Default::default() }).unwrap();
        let xyz = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        // SAFETY: a host array; a CPU context rejects the call without reading it.
        let e = unsafe { ctx.set_particles_device_f32(xyz.as_ptr(), 3, 0) }.unwrap_err();
        assert_eq!(e.code, Error::BACKEND_UNAVAILABLE, "{e}");
        assert!(e.message.contains("CUDA"), "{e}");
        let xyz64 = [0.0f64, 0.0, 0.0, 1.0, 0.0, 0.0];
        let e = unsafe { ctx.set_particles_device_f64(xyz64.as_ptr(), 2, 24) }.unwrap_err();
        assert_eq!(e.code, Error::BACKEND_UNAVAILABLE, "{e}");
        let e = ctx.set_mesh_memory(Memory::Device).unwrap_err();
        assert_eq!(e.code, Error::BACKEND_UNAVAILABLE, "{e}");
        ctx.set_mesh_memory(Memory::Host).unwrap();
        // The failed device upload left no particles behind.
        assert_eq!(ctx.reconstruct(&Params::new(SPACING)).unwrap_err().code, Error::NO_PARTICLES);
        // Still usable: a host upload reconstructs into a host mesh.
        ctx.set_particles_f32(&sample()[..500]).unwrap();
        let m = ctx.reconstruct(&Params::new(SPACING)).unwrap();
        assert_eq!(m.memory(), Memory::Host);
        assert!(m.triangle_count() > 0);
    }
}

/// A host mesh copies out exactly what its slices show; copy_to_host_into
/// checks the buffer lengths.
fn host_mesh_copy_to_host_equals_its_slices() {
    let mut ctx = Context::new().unwrap();
    ctx.set_particles_f32(&sample()).unwrap();
    let mesh = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    assert_eq!(mesh.memory(), Memory::Host);
    assert!(mesh.device_arrays().is_none());
    assert!(mesh.has_normals());
    let h = mesh.copy_to_host().unwrap();
    assert!(!h.triangles.is_empty());
    assert_eq!(h.positions, mesh.positions());
    assert_eq!(h.normals.as_deref(), mesh.normals());
    assert_eq!(h.triangles, mesh.triangles());

    // Into reused buffers, some arrays skipped.
    let mut tri = vec![[u32::MAX; 3]; mesh.triangle_count()];
    mesh.copy_to_host_into(None, None, Some(&mut tri)).unwrap();
    assert_eq!(tri, mesh.triangles());
    mesh.copy_to_host_into(None, None, None).unwrap();
    let mut short = vec![[0.0f32; 3]; mesh.vertex_count() - 1];
    let e = mesh.copy_to_host_into(Some(&mut short), None, None).unwrap_err();
    assert_eq!(e.code, Error::INVALID_ARGUMENT, "{e}");
    assert!(short.iter().all(|p| *p == [0.0; 3]), "nothing is copied on a length error");

    // Without normals: None, and a normals buffer is left untouched.
    let mut p = Params::new(SPACING);
    p.compute_normals = false;
    let bare = ctx.reconstruct(&p).unwrap();
    assert!(!bare.has_normals());
    let h = bare.copy_to_host().unwrap();
    assert!(h.normals.is_none());
    assert_eq!(h.positions, bare.positions());
    let mut nrm = vec![[7.0f32; 3]; bare.vertex_count()];
    bare.copy_to_host_into(None, Some(&mut nrm), None).unwrap();
    assert!(nrm.iter().all(|n| *n == [7.0; 3]));
}

/// With a CUDA device: a mesh left in device memory hands out no slices, its
/// raw pointers are device pointers, and copied to the host it equals the
/// host mesh. Skipped (passes) without the CUDA backend.
fn device_mesh_without_slices_when_cuda_is_available() {
    if !Backend::Cuda.is_available() {
        println!("  (skipped: the CUDA backend is not available)");
        return;
    }
    let mut ctx = Context::with_options(ContextOptions { backend: Backend::Cuda, ..Default::default() }).unwrap();
    ctx.set_particles_f32(&sample()).unwrap();
    let host = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    ctx.set_mesh_memory(Memory::Device).unwrap();
    let dev = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    drop(ctx); // a device mesh outlives its context too
    assert_eq!(dev.memory(), Memory::Device);
    assert_eq!((dev.vertex_count(), dev.triangle_count()), (host.vertex_count(), host.triangle_count()));
    assert!(dev.positions().is_empty() && dev.triangles().is_empty() && dev.normals().is_none());
    assert!(dev.has_normals());
    let d = dev.device_arrays().expect("device pointers");
    assert!(!d.positions.is_null() && !d.normals.is_null() && !d.triangles.is_null());
    assert_eq!((d.vertex_count, d.triangle_count), (dev.vertex_count(), dev.triangle_count()));
    assert_eq!(dev.copy_to_host().unwrap(), host.copy_to_host().unwrap());
}

fn names_and_version() {
    assert_eq!(nbmc::version() / 10000, nbmc::NBMC_VERSION_MAJOR);
    assert!(nbmc::version_string().starts_with("0.1."));
    assert_eq!(Stage::Upload.name(), "upload");
    assert_eq!(Stage::ALL.len(), 7);
    assert_eq!(nbmc::status_string(0), "ok");
    assert_eq!(nbmc::status_string(Error::CANCELLED), "cancelled");
}

/// `Context` is Send but not Sync, `Mesh` is both.
fn auto_traits() {
    fn send<T: Send>() {}
    fn sync<T: Sync>() {}
    send::<Context>();
    send::<Mesh>();
    sync::<Mesh>();
    sync::<Params>();
    // Not Sync: checked by the compile_fail doctest on `assert_context_not_sync`.
}

fn attributes_follow_the_particles_onto_the_mesh() {
    let particles = sample();
    let mut ctx = Context::new().unwrap();
    // Before any upload through the wrapper.
    assert_eq!(ctx.set_attribute_f32("a", &[1.0], 1).unwrap_err().code, Error::NO_PARTICLES);
    ctx.set_particles_f32(&particles).unwrap();
    let height: Vec<f32> = particles.iter().map(|p| p[1]).collect();
    let vel: Vec<f64> = particles.iter().flat_map(|p| [1.0, 2.0 * p[0] as f64, -3.0]).collect();
    ctx.set_attribute_f32("height", &height, 1).unwrap();
    ctx.set_attribute_f64("vel", &vel, 3).unwrap();
    // Wrong length, components, NaN.
    assert_eq!(ctx.set_attribute_f32("h", &height[1..], 1).unwrap_err().code, Error::INVALID_ARGUMENT);
    assert_eq!(ctx.set_attribute_f32("h", &height, 2).unwrap_err().code, Error::INVALID_ARGUMENT);
    let mut bad = height.clone();
    bad[7] = f32::NAN;
    let e = ctx.set_attribute_f32("h", &bad, 1).unwrap_err();
    assert_eq!(e.code, Error::INVALID_PARTICLES);
    assert!(e.message.contains("particle 7"), "{e}");
    let mesh = ctx.reconstruct(&Params::new(SPACING)).unwrap();
    assert_eq!(mesh.attribute_names(), vec!["height".to_string(), "vel".to_string()]);
    assert!(mesh.attribute("nope").is_none());
    let (h, c) = mesh.attribute("height").unwrap();
    assert_eq!((h.len(), c), (mesh.vertex_count(), 1));
    let (lo, hi) = particles.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| (lo.min(p[1]), hi.max(p[1])));
    for (v, p) in h.iter().zip(mesh.positions()) {
        // A kernel mean of the particles' heights within R = 4 spacings.
        assert!(*v >= lo && *v <= hi, "{v} outside [{lo}, {hi}]");
        assert!((v - p[1]).abs() < 4.0 * SPACING as f32, "{v} vs vertex height {}", p[1]);
    }
    let (v, c) = mesh.attribute("vel").unwrap();
    assert_eq!(c, 3);
    for item in v.chunks_exact(3) {
        assert!((item[0] - 1.0).abs() < 1e-6 && (item[2] + 3.0).abs() < 1e-6, "{item:?}");
    }
    // Removed, then all gone with the next upload.
    ctx.remove_attribute("height").unwrap();
    assert_eq!(ctx.reconstruct(&Params::new(SPACING)).unwrap().attribute_names(), vec!["vel".to_string()]);
    ctx.set_particles_f32(&particles).unwrap();
    assert!(ctx.reconstruct(&Params::new(SPACING)).unwrap().attribute_names().is_empty());
}

/// Params::double_positions: the sample frame shifted by 1e7 (a float
/// resolves 1.0 there) keeps its shape in the f64 positions; a float mesh has
/// none.
fn double_positions_far_from_the_origin() {
    let near: Vec<[f64; 3]> = sample().iter().map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]).collect();
    let far: Vec<[f64; 3]> = near.iter().map(|p| [p[0] + 1e7, p[1] + 1e7, p[2] + 1e7]).collect();
    let mut ctx = Context::new().unwrap();
    let mut params = Params::new(SPACING);
    assert!(!params.double_positions, "off by default");
    ctx.set_particles_f64(&near).unwrap();
    let flat = ctx.reconstruct(&params).unwrap();
    assert!(flat.positions_f64().is_none());
    params.double_positions = true;
    ctx.set_particles_f64(&far).unwrap();
    let mesh = ctx.reconstruct(&params).unwrap();
    let p64 = mesh.positions_f64().expect("double positions");
    assert_eq!(p64.len(), mesh.vertex_count());
    assert_eq!(mesh.positions().len(), mesh.vertex_count());
    // Same bounding box as the frame at the origin, to a micrometre-ish
    // (float positions there would be off by up to 0.5).
    let bounds = |it: &mut dyn Iterator<Item = [f64; 3]>| {
        let mut lo = [f64::MAX; 3];
        let mut hi = [f64::MIN; 3];
        for v in it {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        (lo, hi)
    };
    let (lo0, hi0) = bounds(&mut flat.positions().iter().map(|v| [v[0] as f64, v[1] as f64, v[2] as f64]));
    let (lo1, hi1) = bounds(&mut p64.iter().map(|v| [v[0] - 1e7, v[1] - 1e7, v[2] - 1e7]));
    for a in 0..3 {
        assert!((lo0[a] - lo1[a]).abs() < 1e-3 && (hi0[a] - hi1[a]).abs() < 1e-3, "{lo0:?} {hi0:?} vs {lo1:?} {hi1:?}");
    }
}

/// Params::decimate_fraction, smooth_weighting and Isolated::Sphere: a
/// quarter of the triangles, still closed; lone particles come back as
/// spheres of radius iso_radius (absolute).
fn decimation_and_spheres() {
    let mut particles = sample();
    particles.push([5.0, 5.0, 5.0]);
    particles.push([-5.0, 5.0, 5.0]);
    let mut ctx = Context::new().unwrap();
    ctx.set_particles_f32(&particles).unwrap();
    let mut params = Params::new(SPACING);
    assert_eq!(params.decimate_fraction, 1.0);
    assert_eq!(params.smooth_weighting, SmoothWeighting::Uniform);
    params.smooth_iterations = 3;
    params.smooth_weighting = SmoothWeighting::Feature;
    params.decimate_fraction = 0.25;
    params.isolated = Isolated::Sphere;
    let mesh = ctx.reconstruct(&params).unwrap();
    assert_closed(&mesh);
    let stats = ctx.stats().unwrap();
    assert_eq!(stats.triangle_count as usize, mesh.triangle_count());
    assert!(4 * stats.triangle_count <= stats.pre_decimation_triangle_count + 3, "{stats:?}");
    // The clean-up's counts account for every triangle it removed.
    assert!(stats.cleanup_bad_triangles_after <= stats.cleanup_bad_triangles_before, "{stats:?}");
    assert_eq!(
        stats.raw_triangle_count - stats.pre_decimation_triangle_count,
        2 * stats.cleanup_collapses + 6 * stats.cleanup_cuts + stats.cleanup_removed_component_triangles,
        "{stats:?}"
    );
    let spheres = mesh.spheres();
    assert_eq!(spheres.len() as u64, stats.dropped_particle_count);
    assert!(spheres.len() >= 2);
    let last = spheres[spheres.len() - 1];
    assert_eq!([last[0], last[1], last[2]], [-5.0, 5.0, 5.0]);
    assert!((last[3] as f64 - params.iso_radius * SPACING).abs() < 1e-6);
    params.isolated = Isolated::Keep;
    assert!(ctx.reconstruct(&params).unwrap().spheres().is_empty());
    params.decimate_fraction = 0.0;
    assert_eq!(ctx.reconstruct(&params).unwrap_err().code, Error::INVALID_PARAMETER);
}

/// Per-particle radii: equal to the spacing, the mesh without radii; two
/// sizes, a closed mesh that differs; exact codes for bad radii; an upload
/// removes them.
fn radii_follow_the_particles() {
    let particles = sample();
    let n = particles.len();
    let mut ctx = Context::with_options(ContextOptions { backend: Backend::OpenMp, ..Default::default() }).unwrap();
    assert_eq!(ctx.set_radii_f64(&[SPACING]).unwrap_err().code, Error::NO_PARTICLES);
    ctx.set_particles_f32(&particles).unwrap();
    let params = Params::new(SPACING);
    let plain = ctx.reconstruct(&params).unwrap();
    ctx.set_radii_f64(&vec![SPACING; n]).unwrap();
    let equal = ctx.reconstruct(&params).unwrap();
    assert_eq!(equal.positions(), plain.positions());
    assert_eq!(equal.triangles(), plain.triangles());
    // The left half of the frame half as large.
    let radii: Vec<f32> =
        particles.iter().map(|p| if p[0] < 0.5 { 0.5 * SPACING as f32 } else { SPACING as f32 }).collect();
    ctx.set_radii_f32(&radii).unwrap();
    let mixed = ctx.reconstruct(&params).unwrap();
    assert_closed(&mixed);
    assert_ne!(mixed.triangle_count(), plain.triangle_count());
    ctx.clear_radii().unwrap();
    assert_eq!(ctx.reconstruct(&params).unwrap().positions(), plain.positions());
    // Bad radii, a wrong count.
    assert_eq!(ctx.set_radii_f32(&radii[1..]).unwrap_err().code, Error::INVALID_ARGUMENT);
    let mut bad = radii.clone();
    bad[5] = -1.0;
    let e = ctx.set_radii_f32(&bad).unwrap_err();
    assert_eq!(e.code, Error::INVALID_PARAMETER);
    assert!(e.message.contains("particle 5"), "{e}");
    // SAFETY: a host array; a CPU context rejects the call without reading it.
    let e = unsafe { ctx.set_radii_device_f32(radii.as_ptr(), n, 0) }.unwrap_err();
    assert_eq!(e.code, Error::BACKEND_UNAVAILABLE, "{e}");
    // An upload removes them.
    ctx.set_radii_f32(&radii).unwrap();
    ctx.set_particles_f32(&particles).unwrap();
    assert_eq!(ctx.reconstruct(&params).unwrap().positions(), plain.positions());
}

// ------------------------------------------------------------------ runner

fn main() -> std::process::ExitCode {
    let tests: &[(&str, fn())] = &[
        ("reconstructs_the_sample_frame", reconstructs_the_sample_frame),
        ("f32_f64_and_strided_uploads_agree", f32_f64_and_strided_uploads_agree),
        (
            "mesh_outlives_its_context_and_is_shared_between_threads",
            mesh_outlives_its_context_and_is_shared_between_threads,
        ),
        ("params_follow_the_library_defaults", params_follow_the_library_defaults),
        ("errors_carry_exact_codes_and_messages", errors_carry_exact_codes_and_messages),
        ("unavailable_backend_and_bad_options", unavailable_backend_and_bad_options),
        ("progress_reports_stages_and_can_cancel", progress_reports_stages_and_can_cancel),
        ("a_panic_in_the_progress_callback_does_not_cross_c", a_panic_in_the_progress_callback_does_not_cross_c),
        ("file_io_round_trip", file_io_round_trip),
        ("device_memory_needs_the_cuda_backend", device_memory_needs_the_cuda_backend),
        ("host_mesh_copy_to_host_equals_its_slices", host_mesh_copy_to_host_equals_its_slices),
        ("device_mesh_without_slices_when_cuda_is_available", device_mesh_without_slices_when_cuda_is_available),
        ("names_and_version", names_and_version),
        ("auto_traits", auto_traits),
        ("attributes_follow_the_particles_onto_the_mesh", attributes_follow_the_particles_onto_the_mesh),
        ("double_positions_far_from_the_origin", double_positions_far_from_the_origin),
        ("decimation_and_spheres", decimation_and_spheres),
        ("radii_follow_the_particles", radii_follow_the_particles),
    ];
    // libtest-like arguments: options are ignored, the first free word filters.
    let filter = std::env::args().skip(1).find(|a| !a.starts_with('-')).unwrap_or_default();
    let selected: Vec<_> = tests.iter().filter(|(n, _)| n.contains(filter.as_str())).collect();
    if std::env::args().any(|a| a == "--list") {
        for (n, _) in &selected {
            println!("{n}: test");
        }
        return std::process::ExitCode::SUCCESS;
    }
    println!("\nrunning {} tests (on the main thread)", selected.len());
    let mut failed = Vec::new();
    for (name, f) in &selected {
        let ok = std::panic::catch_unwind(*f).is_ok();
        println!("test {name} ... {}", if ok { "ok" } else { "FAILED" });
        if !ok {
            failed.push(*name);
        }
    }
    println!(
        "\ntest result: {}. {} passed; {} failed\n",
        if failed.is_empty() { "ok" } else { "FAILED" },
        selected.len() - failed.len(),
        failed.len()
    );
    if failed.is_empty() {
        std::process::ExitCode::SUCCESS
    } else {
        println!("failures: {failed:?}");
        std::process::ExitCode::FAILURE
    }
}
