// SPDX-License-Identifier: MIT
//! Safe Rust API over the nbmc C ABI: surface reconstruction of particle-based
//! fluids with narrow-band marching cubes.
//!
//! ```no_run
//! use nbmc::{Context, Params};
//!
//! fn frame(positions: &[[f32; 3]]) -> nbmc::Result<()> {
//!     let mut ctx = Context::new()?;
//!     ctx.set_particles_f32(positions)?;
//!     let mesh = ctx.reconstruct(&Params::new(0.05))?;
//!     println!("{} triangles", mesh.triangles().len());
//!     for [a, b, c] in mesh.triangles() {
//!         let _ = (mesh.positions()[*a as usize], b, c);
//!     }
//!     Ok(())
//! }
//! ```
//!
//! Ownership follows the C API: uploads copy the positions, a [`Mesh`] owns its
//! memory and outlives the [`Context`] that made it, and both free their C
//! objects on drop. A `Context` is [`Send`] but not [`Sync`]: it can move to
//! another thread but never be used by two at once. A `Mesh` is `Send` and
//! `Sync` (its getters are read-only).
//!
//! # GPU memory
//!
//! With the CUDA backend, particles can come straight from CUDA memory
//! ([`Context::set_particles_device_f32`], `unsafe`: the caller vouches for
//! the device pointer) and meshes can stay on the GPU
//! ([`Context::set_mesh_memory`]`(`[`Memory::Device`]`)`). A device mesh's
//! arrays are never handed out as slices (that would let safe code read
//! device memory from the host): for such a mesh [`Mesh::positions`] and
//! [`Mesh::triangles`] are empty and [`Mesh::normals`] is `None`. Use
//! [`Mesh::memory`] to tell, [`Mesh::copy_to_host`] (works for every mesh)
//! to get the data, or [`Mesh::device_arrays`] for the raw device pointers.
//! Other backends answer the device calls with
//! [`Error::BACKEND_UNAVAILABLE`].

// Unsafe operations inside an `unsafe fn` keep their own `unsafe` blocks;
// with this lint rustc 1.63 (Debian 12) does not call them unnecessary.
#![warn(unsafe_op_in_unsafe_fn)]

use nbmc_sys as sys;
use std::any::Any;
use std::ffi::{CStr, CString};
use std::fmt;
use std::marker::PhantomData;
use std::os::raw::{c_char, c_void};
use std::panic::{self, AssertUnwindSafe};
use std::path::Path;
use std::ptr::{self, NonNull};

pub use sys::{NBMC_VERSION, NBMC_VERSION_MAJOR, NBMC_VERSION_MINOR, NBMC_VERSION_PATCH};

// ------------------------------------------------------------------- errors

/// A failed nbmc call: the status code (one of the `NBMC_ERROR_*` values, see
/// the associated constants) and the library's message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Error {
    pub code: i32,
    pub message: String,
}

impl Error {
    pub const INVALID_ARGUMENT: i32 = sys::NBMC_ERROR_INVALID_ARGUMENT;
    pub const INVALID_PARTICLES: i32 = sys::NBMC_ERROR_INVALID_PARTICLES;
    pub const NO_PARTICLES: i32 = sys::NBMC_ERROR_NO_PARTICLES;
    pub const INVALID_PARAMETER: i32 = sys::NBMC_ERROR_INVALID_PARAMETER;
    pub const DOMAIN_TOO_LARGE: i32 = sys::NBMC_ERROR_DOMAIN_TOO_LARGE;
    pub const OUT_OF_MEMORY: i32 = sys::NBMC_ERROR_OUT_OF_MEMORY;
    pub const BACKEND_UNAVAILABLE: i32 = sys::NBMC_ERROR_BACKEND_UNAVAILABLE;
    pub const IO: i32 = sys::NBMC_ERROR_IO;
    pub const INTERNAL: i32 = sys::NBMC_ERROR_INTERNAL;
    pub const MEMORY_BUDGET: i32 = sys::NBMC_ERROR_MEMORY_BUDGET;
    pub const CANCELLED: i32 = sys::NBMC_ERROR_CANCELLED;
    pub const FORMAT: i32 = sys::NBMC_ERROR_FORMAT;

    fn new(code: i32, message: impl Into<String>) -> Self {
        let message = message.into();
        let message = if message.is_empty() { status_string(code).to_string() } else { message };
        Error { code, message }
    }

    /// The library's static name of the code ("invalid parameter", ...).
    pub fn status_name(&self) -> &'static str {
        status_string(self.code)
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "nbmc: {} (status {}): {}", self.status_name(), self.code, self.message)
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;

/// Copies a static or context-owned C string.
fn c_str(p: *const c_char) -> String {
    if p.is_null() {
        String::new()
    } else {
        // SAFETY: the library returns NUL-terminated strings valid at least
        // until the next call on the same context.
        unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
    }
}

fn static_str(p: *const c_char) -> &'static str {
    if p.is_null() {
        ""
    } else {
        // SAFETY: documented as static strings in nbmc.h.
        unsafe { CStr::from_ptr(p) }.to_str().unwrap_or("")
    }
}

/// A path as a NUL-terminated C string (the bytes of the OS string on Unix).
fn path_cstring(path: &Path) -> Result<CString> {
    #[cfg(unix)]
    let bytes = {
        use std::os::unix::ffi::OsStrExt;
        path.as_os_str().as_bytes().to_vec()
    };
    #[cfg(not(unix))]
    let bytes = path.to_string_lossy().into_owned().into_bytes();
    CString::new(bytes).map_err(|_| {
        Error::new(sys::NBMC_ERROR_INVALID_ARGUMENT, format!("path {} contains a NUL byte", path.display()))
    })
}

/// A format name as a C string; None (by the extension) is NULL.
fn format_cstring(format: Option<&str>) -> Result<Option<CString>> {
    format
        .map(|f| {
            CString::new(f).map_err(|_| Error::new(sys::NBMC_ERROR_INVALID_ARGUMENT, "format contains a NUL byte"))
        })
        .transpose()
}

/// The message of the last failed context-less call on this thread.
fn thread_last_error() -> String {
    c_str(unsafe { sys::nbmc_last_error() })
}

/// The English name of a status code.
pub fn status_string(code: i32) -> &'static str {
    static_str(unsafe { sys::nbmc_status_string(code) })
}

// ------------------------------------------------------------------ version

/// `NBMC_VERSION` of the library actually loaded (major*10000+minor*100+patch).
pub fn version() -> u32 {
    unsafe { sys::nbmc_version() }
}

/// "major.minor.patch" plus the compiled-in backends.
pub fn version_string() -> &'static str {
    static_str(unsafe { sys::nbmc_version_string() })
}

// -------------------------------------------------------------- enumerations

macro_rules! int_enum {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident = $c:path),* $(,)? }) => {
        $(#[$m])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $name { $($(#[$vm])* $v),* }
        impl $name {
            /// The C value.
            pub fn raw(self) -> i32 { match self { $($name::$v => $c),* } }
            /// From the C value; None for values this binding does not know.
            pub fn from_raw(v: i32) -> Option<Self> { $(if v == $c { return Some($name::$v); })* None }
        }
    };
}

int_enum!(
    /// Compute backend of a context.
    Backend {
        /// CUDA when compiled in and a device exists, else OpenMP, else serial.
        Auto = sys::NBMC_BACKEND_AUTO,
        Serial = sys::NBMC_BACKEND_SERIAL,
        OpenMp = sys::NBMC_BACKEND_OPENMP,
        Cuda = sys::NBMC_BACKEND_CUDA,
    }
);

impl Backend {
    /// Whether the backend is compiled in and usable on this machine.
    pub fn is_available(self) -> bool {
        unsafe { sys::nbmc_backend_available(self.raw()) != 0 }
    }
}

int_enum!(
    /// Scalar field method.
    Method {
        /// Solenthaler, Schlaefli, Pajarola 2007 (default).
        Ssp07 = sys::NBMC_METHOD_SSP07,
        /// Zhu & Bridson 2005.
        Zb05 = sys::NBMC_METHOD_ZB05,
        /// Normalised SPH density (cubic spline of support `influence_radius`),
        /// splashsurf's level set, at `iso_threshold`.
        Sph = sys::NBMC_METHOD_SPH,
        /// Yu & Turk 2010: that density with one anisotropic kernel per
        /// particle (`aniso_*`; isotropic support `influence_radius / 2`), at
        /// `iso_threshold`.
        Yt10 = sys::NBMC_METHOD_YT10,
    }
);

int_enum!(
    /// What becomes of small clusters of particles.
    Isolated {
        /// Every particle makes surface (default).
        Keep = sys::NBMC_ISOLATED_KEEP,
        /// Clusters (particles linked when closer than the surface radius)
        /// of fewer than `min_cluster` particles make none.
        Drop = sys::NBMC_ISOLATED_DROP,
        /// As `Drop`, and their particles come back as spheres
        /// ([`Mesh::spheres`]).
        Sphere = sys::NBMC_ISOLATED_SPHERE,
    }
);

int_enum!(
    /// How the smoothing step is weighted per vertex.
    SmoothWeighting {
        /// Every vertex alike (default).
        Uniform = sys::NBMC_SMOOTH_UNIFORM,
        /// By the particles near each vertex: thin sheets, filaments and
        /// droplets are not eroded (Loeschner et al. 2023).
        Feature = sys::NBMC_SMOOTH_FEATURE,
    }
);

int_enum!(
    /// Where the scalar field is evaluated.
    FieldStrategy {
        /// Only on narrow-band vertices (the method; default).
        NarrowBand = sys::NBMC_FIELD_NARROW_BAND,
        /// Baseline: every vertex of the bounding grid.
        Dense = sys::NBMC_FIELD_DENSE,
        /// Baseline: serial scatter over a dense grid.
        Scatter = sys::NBMC_FIELD_SCATTER,
    }
);

int_enum!(
    /// How the lengths of [`Params`] are given.
    LengthUnit {
        /// Multiples of the particle spacing (default).
        Spacing = sys::NBMC_UNIT_SPACING,
        /// The units of the particle positions.
        Absolute = sys::NBMC_UNIT_ABSOLUTE,
    }
);

int_enum!(
    /// Where a mesh's arrays live (`NBMC_MEMORY_*`).
    Memory {
        /// Ordinary host memory (the default).
        Host = sys::NBMC_MEMORY_HOST,
        /// CUDA memory of the context's GPU (CUDA backend only).
        Device = sys::NBMC_MEMORY_DEVICE,
    }
);

int_enum!(
    /// Pipeline stages, as reported to progress callbacks and in [`Stats`].
    Stage {
        Upload = sys::NBMC_STAGE_UPLOAD,
        Neighbourhood = sys::NBMC_STAGE_NEIGHBOURHOOD,
        SurfaceParticles = sys::NBMC_STAGE_SURFACE_PARTICLES,
        Band = sys::NBMC_STAGE_BAND,
        Field = sys::NBMC_STAGE_FIELD,
        Triangulation = sys::NBMC_STAGE_TRIANGULATION,
        Output = sys::NBMC_STAGE_OUTPUT,
    }
);

impl Stage {
    pub const ALL: [Stage; sys::NBMC_STAGE_COUNT as usize] = [
        Stage::Upload,
        Stage::Neighbourhood,
        Stage::SurfaceParticles,
        Stage::Band,
        Stage::Field,
        Stage::Triangulation,
        Stage::Output,
    ];

    /// The library's name of the stage ("upload", "neighbourhood", ...).
    pub fn name(self) -> &'static str {
        static_str(unsafe { sys::nbmc_stage_name(self.raw()) })
    }
}

// --------------------------------------------------------------- parameters

/// Reconstruction parameters. [`Params::new`] takes the library's defaults;
/// lengths are multiples of `spacing` unless `length_unit` is `Absolute`.
#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    /// r: rest distance of the particles, absolute, > 0.
    pub spacing: f64,
    pub length_unit: LengthUnit,
    /// Marching-cubes cell edge (default 0.5 r).
    pub cell_size: f64,
    /// Kernel support R of the field (default 4 r).
    pub influence_radius: f64,
    /// Half width of the band box around surface particles (default 2 r).
    pub band_width: f64,
    /// Neighbourhood radius of the surface-particle test (default 2 r).
    pub surface_radius: f64,
    /// r-bar (SSP07) or particle radius (ZB05) (default 1 r).
    pub iso_radius: f64,
    pub method: Method,
    pub field: FieldStrategy,
    /// SSP07 eigenvalue thresholds (defaults 0.4 and 3.5).
    pub t_low: f64,
    pub t_high: f64,
    /// `Method::Sph`, `Method::Yt10`: iso level of the normalised density, a
    /// fraction of the rest density in (0, 1) (default 0.6).
    pub iso_threshold: f64,
    /// `Method::Yt10` (Yu & Turk's k_r): largest ratio of a kernel's axes,
    /// >= 1 (default 4).
    pub aniso_kr: f64,
    /// `Method::Yt10` (k_s): scale of the kernel axes, normalised so that 1
    /// gives a particle inside a uniform fluid the isotropic kernel (default 1).
    pub aniso_ks: f64,
    /// `Method::Yt10` (k_n): kernel scale of a particle with few neighbours,
    /// in (0, 1.5] (default 0.5).
    pub aniso_kn: f64,
    /// `Method::Yt10` (N_eps): more neighbours than this within the influence
    /// radius give an anisotropic kernel (default 25).
    pub aniso_neighbours: i32,
    /// `Method::Yt10` (lambda): smoothing of the kernel centres, in [0, 1]
    /// (default 0.3).
    pub aniso_lambda: f64,
    /// `Method::Ssp07`, `Zb05`, `Sph`: keep the surface within about this
    /// distance of the particles (bridges between splashes and fillets in
    /// concave corners are cut back); 0: off (default 1.5 r).
    pub max_distance: f64,
    /// Colour-field gradient threshold of the surface test (default 0.75).
    pub color_threshold: f64,
    /// Fewer neighbours than this means surface (default 25).
    pub neighbour_threshold: i32,
    /// Per-vertex normals (default true).
    pub compute_normals: bool,
    /// Small clusters of particles: kept (default) or dropped.
    pub isolated: Isolated,
    /// `Isolated::Drop`: the smallest cluster kept (default 10).
    pub min_cluster: i32,
    /// Keep the vertex positions in double precision ([`Mesh::positions_f64`]),
    /// for coordinates far from the origin; host meshes only (default false).
    pub double_positions: bool,
    /// Taubin smoothing iterations after the clean-up (default 0).
    pub smooth_iterations: i32,
    /// How the smoothing step is weighted (default uniform).
    pub smooth_weighting: SmoothWeighting,
    /// Keep this fraction of the triangles, 0 < f <= 1, by quadric-error
    /// edge collapses that keep the mesh closed and manifold (default 1: off).
    pub decimate_fraction: f64,
    /// Only reconstruct inside this box (absolute units), if set.
    pub bbox: Option<([f64; 3], [f64; 3])>,
}

impl Params {
    /// The library's defaults for a particle spacing `spacing`.
    pub fn new(spacing: f64) -> Self {
        let mut p = sys::nbmc_params::default();
        unsafe { sys::nbmc_params_init(&mut p) };
        Params {
            spacing,
            length_unit: LengthUnit::from_raw(p.length_unit).unwrap_or(LengthUnit::Spacing),
            cell_size: p.cell_size,
            influence_radius: p.influence_radius,
            band_width: p.band_width,
            surface_radius: p.surface_radius,
            iso_radius: p.iso_radius,
            method: Method::from_raw(p.method).unwrap_or(Method::Ssp07),
            field: FieldStrategy::from_raw(p.field).unwrap_or(FieldStrategy::NarrowBand),
            t_low: p.t_low,
            t_high: p.t_high,
            iso_threshold: p.iso_threshold,
            aniso_kr: p.aniso_kr,
            aniso_ks: p.aniso_ks,
            aniso_kn: p.aniso_kn,
            aniso_neighbours: p.aniso_neighbours,
            aniso_lambda: p.aniso_lambda,
            max_distance: p.max_distance,
            color_threshold: p.color_threshold,
            neighbour_threshold: p.neighbour_threshold,
            compute_normals: p.compute_normals != 0,
            isolated: Isolated::from_raw(p.isolated).unwrap_or(Isolated::Keep),
            min_cluster: p.min_cluster,
            double_positions: p.double_positions != 0,
            smooth_iterations: p.smooth_iterations,
            smooth_weighting: SmoothWeighting::from_raw(p.smooth_weighting).unwrap_or(SmoothWeighting::Uniform),
            decimate_fraction: p.decimate_fraction,
            bbox: None,
        }
    }

    /// The C struct (struct_size and reserved fields filled by the library).
    pub fn to_raw(&self) -> sys::nbmc_params {
        let mut p = sys::nbmc_params::default();
        unsafe { sys::nbmc_params_init(&mut p) };
        p.spacing = self.spacing;
        p.length_unit = self.length_unit.raw();
        p.cell_size = self.cell_size;
        p.influence_radius = self.influence_radius;
        p.band_width = self.band_width;
        p.surface_radius = self.surface_radius;
        p.iso_radius = self.iso_radius;
        p.method = self.method.raw();
        p.field = self.field.raw();
        p.t_low = self.t_low;
        p.t_high = self.t_high;
        p.iso_threshold = self.iso_threshold;
        p.aniso_kr = self.aniso_kr;
        p.aniso_ks = self.aniso_ks;
        p.aniso_kn = self.aniso_kn;
        p.aniso_neighbours = self.aniso_neighbours;
        p.aniso_lambda = self.aniso_lambda;
        p.max_distance = self.max_distance;
        p.color_threshold = self.color_threshold;
        p.neighbour_threshold = self.neighbour_threshold;
        p.compute_normals = i32::from(self.compute_normals);
        p.isolated = self.isolated.raw();
        p.min_cluster = self.min_cluster;
        p.double_positions = i32::from(self.double_positions);
        p.smooth_iterations = self.smooth_iterations;
        p.smooth_weighting = self.smooth_weighting.raw();
        p.decimate_fraction = self.decimate_fraction;
        if let Some((lo, hi)) = self.bbox {
            p.use_bbox = 1;
            p.bbox_min = lo;
            p.bbox_max = hi;
        }
        p
    }
}

// -------------------------------------------------------------------- stats

/// Figures of the last successful reconstruction of a context.
#[derive(Clone, Debug, PartialEq)]
pub struct Stats {
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
    /// Seconds per stage, indexed by [`Stage::raw`].
    pub stage_seconds: [f64; sys::NBMC_STAGE_COUNT as usize],
    pub total_seconds: f64,
    pub grid_origin: [f64; 3],
    /// Absolute marching-cubes cell size.
    pub cell_size: f64,
    /// Particles left out as isolated, and the clusters they formed.
    pub dropped_particle_count: u64,
    pub dropped_cluster_count: u64,
    /// Triangles before the decimation (`triangle_count` without it).
    pub pre_decimation_triangle_count: u64,
    /// Triangles of the marching-cubes mesh, before the clean-up.
    pub raw_triangle_count: u64,
    /// The clean-up's counts (all 0 without it; summed over its two runs
    /// with smoothing): bad (degenerate + sliver) triangles of the
    /// marching-cubes mesh and left after the last run, vertices moved, edges
    /// flipped and collapsed, pinched tubes cut, triangles removed with whole
    /// bad components. `raw_triangle_count - pre_decimation_triangle_count ==
    /// 2 * cleanup_collapses + 6 * cleanup_cuts + cleanup_removed_component_triangles`.
    pub cleanup_bad_triangles_before: u64,
    pub cleanup_bad_triangles_after: u64,
    pub cleanup_moves: u64,
    pub cleanup_flips: u64,
    pub cleanup_collapses: u64,
    pub cleanup_cuts: u64,
    pub cleanup_removed_component_triangles: u64,
}

impl Stats {
    pub fn seconds(&self, stage: Stage) -> f64 {
        self.stage_seconds[stage.raw() as usize]
    }
}

// ------------------------------------------------------------------ context

type ProgressFn = dyn FnMut(Stage, f64) -> bool + Send;

/// State shared with the C trampoline.
struct Progress {
    callback: Box<ProgressFn>,
    panic: Option<Box<dyn Any + Send>>,
}

/// Owns a `Progress` through a raw pointer (from `Box::into_raw`), so that the
/// pointer registered with C is never invalidated by moves of a `Box`.
struct ProgressSlot(NonNull<Progress>);

impl ProgressSlot {
    fn new(p: Progress) -> Self {
        ProgressSlot(NonNull::from(Box::leak(Box::new(p))))
    }

    fn take_panic(&mut self) -> Option<Box<dyn Any + Send>> {
        // SAFETY: no C call is running (we hold &mut), so nothing else uses it.
        unsafe { (*self.0.as_ptr()).panic.take() }
    }
}

impl Drop for ProgressSlot {
    fn drop(&mut self) {
        // SAFETY: created by Box::leak in ProgressSlot::new, freed only here.
        drop(unsafe { Box::from_raw(self.0.as_ptr()) });
    }
}

unsafe extern "C" fn progress_trampoline(user: *mut c_void, stage: i32, fraction: f64) -> i32 {
    // SAFETY: user is the ProgressSlot pointer registered by
    // Context::set_progress, alive while registered; the callback runs on the
    // thread that called reconstruct, which holds &mut Context.
    let state = unsafe { &mut *(user as *mut Progress) };
    if state.panic.is_some() {
        return 1;
    }
    let stage = match Stage::from_raw(stage) {
        Some(v) => v,
        None => return 0,
    };
    match panic::catch_unwind(AssertUnwindSafe(|| (state.callback)(stage, fraction))) {
        Ok(true) => 0,
        Ok(false) => 1,
        Err(payload) => {
            // A panic must not unwind through C: cancel, re-raise afterwards.
            state.panic = Some(payload);
            1
        }
    }
}

/// Options of [`Context::with_options`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ContextOptions {
    pub backend: Backend,
    /// Host threads for OpenMP; 0 = all cores.
    pub num_threads: i32,
    /// CUDA device.
    pub device_id: i32,
}

impl Default for ContextOptions {
    fn default() -> Self {
        let mut d = sys::nbmc_context_desc::default();
        unsafe { sys::nbmc_context_desc_init(&mut d) };
        ContextOptions {
            backend: Backend::from_raw(d.backend).unwrap_or(Backend::Auto),
            num_threads: d.num_threads,
            device_id: d.device_id,
        }
    }
}

/// A reconstruction context: holds the uploaded particles and reusable
/// buffers. Destroyed on drop; meshes it made stay valid.
pub struct Context {
    raw: NonNull<sys::nbmc_context>,
    progress: Option<ProgressSlot>,
    // Particles of the last upload through this wrapper (None: unknown, after
    // a failed upload or `as_raw`); attribute slices are checked against it.
    particle_count: Option<usize>,
    // Send but not Sync: the C context has no internal locking.
    _not_sync: PhantomData<std::cell::Cell<()>>,
}

// SAFETY: nbmc.h: a context may move between threads; it must not be used by
// two threads at once, which `!Sync` and `&mut self` rule out.
unsafe impl Send for Context {}

/// `Context` is not `Sync`:
/// ```compile_fail
/// fn sync<T: Sync>() {}
/// sync::<nbmc::Context>();
/// ```
#[doc(hidden)]
pub fn assert_context_not_sync() {}

impl Context {
    /// A context with the default options (automatic backend, all cores).
    /// Initialises the Kokkos runtime on first use unless the process already did.
    pub fn new() -> Result<Self> {
        Self::with_options(ContextOptions::default())
    }

    pub fn with_options(options: ContextOptions) -> Result<Self> {
        let mut d = sys::nbmc_context_desc::default();
        unsafe { sys::nbmc_context_desc_init(&mut d) };
        d.backend = options.backend.raw();
        d.num_threads = options.num_threads;
        d.device_id = options.device_id;
        let mut raw = ptr::null_mut();
        let status = unsafe { sys::nbmc_context_create(&d, &mut raw) };
        if status != sys::NBMC_OK {
            // The create error is kept per thread; we are still on this thread.
            return Err(Error::new(status, c_str(unsafe { sys::nbmc_context_last_error(ptr::null()) })));
        }
        let raw = NonNull::new(raw).ok_or_else(|| Error::new(sys::NBMC_ERROR_INTERNAL, "context is NULL"))?;
        Ok(Context { raw, progress: None, particle_count: None, _not_sync: PhantomData })
    }

    // The status of an upload of count particles; remembers the count.
    fn uploaded(&mut self, status: i32, count: usize) -> Result<()> {
        self.particle_count = if status == sys::NBMC_OK { Some(count) } else { None };
        self.check(status)
    }

    fn attribute_name(name: &str) -> Result<CString> {
        CString::new(name).map_err(|_| Error::new(sys::NBMC_ERROR_INVALID_ARGUMENT, "name contains a NUL byte"))
    }

    fn check_attribute(&self, len: usize, components: u32) -> Result<()> {
        let n = self.particle_count.ok_or_else(|| {
            Error::new(sys::NBMC_ERROR_NO_PARTICLES, "no particles uploaded through this Context (upload them first)")
        })?;
        if components != 1 && components != 3 {
            return Err(Error::new(
                sys::NBMC_ERROR_INVALID_ARGUMENT,
                format!("components must be 1 (scalar) or 3 (vector), got {components}"),
            ));
        }
        if Some(len) != n.checked_mul(components as usize) {
            return Err(Error::new(
                sys::NBMC_ERROR_INVALID_ARGUMENT,
                format!("{len} values for {n} particles of {components} component(s)"),
            ));
        }
        Ok(())
    }

    /// Sets (copies) the per-particle attribute `name` (velocity, density,
    /// ...): `components` (1 or 3) values per particle of the last upload,
    /// particle after particle; the next reconstruction interpolates it onto
    /// the mesh's vertices ([`Mesh::attribute`]). Every particle upload
    /// removes all attributes: set them after the particles. Setting a name
    /// again replaces it. NaN or infinite values give
    /// [`Error::INVALID_PARTICLES`]; a slice of the wrong length
    /// [`Error::INVALID_ARGUMENT`].
    pub fn set_attribute_f32(&mut self, name: &str, values: &[f32], components: u32) -> Result<()> {
        self.check_attribute(values.len(), components)?;
        let n = Self::attribute_name(name)?;
        let s = unsafe {
            sys::nbmc_context_set_attribute_f32(self.raw.as_ptr(), n.as_ptr(), values.as_ptr(), components, 0)
        };
        self.check(s)
    }

    /// Double-precision version of [`Context::set_attribute_f32`].
    pub fn set_attribute_f64(&mut self, name: &str, values: &[f64], components: u32) -> Result<()> {
        self.check_attribute(values.len(), components)?;
        let n = Self::attribute_name(name)?;
        let s = unsafe {
            sys::nbmc_context_set_attribute_f64(self.raw.as_ptr(), n.as_ptr(), values.as_ptr(), components, 0)
        };
        self.check(s)
    }

    /// Removes the attribute `name` (Ok also when there is none).
    pub fn remove_attribute(&mut self, name: &str) -> Result<()> {
        let n = Self::attribute_name(name)?;
        let s = unsafe { sys::nbmc_context_set_attribute_f64(self.raw.as_ptr(), n.as_ptr(), ptr::null(), 1, 0) };
        self.check(s)
    }

    /// Sets the attribute `name` from CUDA device memory: item i's
    /// `components` f32 values at byte offset `i * byte_stride` from `data`
    /// (0 = packed; otherwise a multiple of 4), one item per particle of the
    /// last upload. CUDA backend only, else [`Error::BACKEND_UNAVAILABLE`].
    ///
    /// # Safety
    /// `data` must be CUDA device (or managed) memory of the context's GPU in
    /// which those items are allocated and unchanged for the duration of the
    /// call (see [`Context::set_particles_device_f32`]).
    pub unsafe fn set_attribute_device_f32(
        &mut self,
        name: &str,
        data: *const f32,
        components: u32,
        byte_stride: usize,
    ) -> Result<()> {
        let n = Self::attribute_name(name)?;
        let s = unsafe {
            sys::nbmc_context_set_attribute_device_f32(
                self.raw.as_ptr(),
                n.as_ptr(),
                data,
                components,
                byte_stride as u64,
            )
        };
        self.check(s)
    }

    /// Double-precision version of [`Context::set_attribute_device_f32`].
    ///
    /// # Safety
    /// As for [`Context::set_attribute_device_f32`], with f64 values aligned
    /// to 8 bytes.
    pub unsafe fn set_attribute_device_f64(
        &mut self,
        name: &str,
        data: *const f64,
        components: u32,
        byte_stride: usize,
    ) -> Result<()> {
        let n = Self::attribute_name(name)?;
        let s = unsafe {
            sys::nbmc_context_set_attribute_device_f64(
                self.raw.as_ptr(),
                n.as_ptr(),
                data,
                components,
                byte_stride as u64,
            )
        };
        self.check(s)
    }

    /// Sets (copies) per-particle radii, one per particle of the last upload
    /// (absolute, in the unit of the positions): a radius is the particle's
    /// `r`, the spacing it would have in a uniform frame. The [`Params`] then
    /// describe a particle of radius `Params::spacing`, and each particle
    /// scales the influence radius, band width, surface radius and iso radius
    /// by its own radius over it; the cell size stays the frame's (see
    /// docs/api.md, "Per-particle radii"). They stay for the following
    /// reconstructions until [`Context::clear_radii`] or the next particle
    /// upload. A slice of the wrong length gives [`Error::INVALID_ARGUMENT`];
    /// a NaN, infinite, zero or negative radius
    /// [`Error::INVALID_PARAMETER`] (the message names the particle).
    pub fn set_radii_f32(&mut self, radii: &[f32]) -> Result<()> {
        let s = unsafe { sys::nbmc_context_set_radii_f32(self.raw.as_ptr(), radii.as_ptr(), radii.len() as u64, 0) };
        self.check(s)
    }

    /// Double-precision version of [`Context::set_radii_f32`].
    pub fn set_radii_f64(&mut self, radii: &[f64]) -> Result<()> {
        let s = unsafe { sys::nbmc_context_set_radii_f64(self.raw.as_ptr(), radii.as_ptr(), radii.len() as u64, 0) };
        self.check(s)
    }

    /// Removes the per-particle radii (Ok also when there are none).
    pub fn clear_radii(&mut self) -> Result<()> {
        let s = unsafe { sys::nbmc_context_set_radii_f64(self.raw.as_ptr(), ptr::null(), 0, 0) };
        self.check(s)
    }

    /// Sets the per-particle radii from CUDA device memory: `count` f32
    /// values (the particle count), value i at byte offset `i * byte_stride`
    /// from `radii` (0 = packed; otherwise a multiple of 4). CUDA backend
    /// only, else [`Error::BACKEND_UNAVAILABLE`].
    ///
    /// # Safety
    /// `radii` must be CUDA device (or managed) memory of the context's GPU
    /// in which those values are allocated and unchanged for the duration of
    /// the call (see [`Context::set_particles_device_f32`]).
    pub unsafe fn set_radii_device_f32(&mut self, radii: *const f32, count: usize, byte_stride: usize) -> Result<()> {
        let s = unsafe {
            sys::nbmc_context_set_radii_device_f32(self.raw.as_ptr(), radii, count as u64, byte_stride as u64)
        };
        self.check(s)
    }

    /// Double-precision version of [`Context::set_radii_device_f32`].
    ///
    /// # Safety
    /// As for [`Context::set_radii_device_f32`], with f64 values aligned to 8
    /// bytes.
    pub unsafe fn set_radii_device_f64(&mut self, radii: *const f64, count: usize, byte_stride: usize) -> Result<()> {
        let s = unsafe {
            sys::nbmc_context_set_radii_device_f64(self.raw.as_ptr(), radii, count as u64, byte_stride as u64)
        };
        self.check(s)
    }

    fn check(&self, status: i32) -> Result<()> {
        if status == sys::NBMC_OK {
            Ok(())
        } else {
            Err(Error::new(status, c_str(unsafe { sys::nbmc_context_last_error(self.raw.as_ptr()) })))
        }
    }

    /// The raw handle, for calls this crate does not wrap. It stays owned by
    /// the context. The wrapper forgets the particle count (the caller may
    /// upload through the handle): upload again through the wrapper before
    /// [`Context::set_attribute_f32`].
    pub fn as_raw(&mut self) -> *mut sys::nbmc_context {
        self.particle_count = None;
        self.raw.as_ptr()
    }

    /// The backend actually in use (Auto resolved).
    pub fn backend(&self) -> Result<Backend> {
        let mut b = -1;
        let status = unsafe { sys::nbmc_context_backend(self.raw.as_ptr(), &mut b) };
        if status != sys::NBMC_OK {
            return Err(Error::new(status, "nbmc_context_backend failed"));
        }
        Backend::from_raw(b).ok_or_else(|| Error::new(sys::NBMC_ERROR_INTERNAL, format!("unknown backend {b}")))
    }

    /// Uploads (copies) positions, replacing earlier ones. NaN or infinite
    /// values give [`Error::INVALID_PARTICLES`], an empty slice
    /// [`Error::NO_PARTICLES`].
    pub fn set_particles_f32(&mut self, xyz: &[[f32; 3]]) -> Result<()> {
        // SAFETY: xyz.len() packed triples are readable.
        unsafe { self.set_particles_f32_raw(xyz.as_ptr().cast(), xyz.len(), 0) }
    }

    /// Uploads (copies) double-precision positions.
    pub fn set_particles_f64(&mut self, xyz: &[[f64; 3]]) -> Result<()> {
        unsafe { self.set_particles_f64_raw(xyz.as_ptr().cast(), xyz.len(), 0) }
    }

    /// Uploads `count` positions from interleaved data: particle i's x, y, z
    /// are `data[i * stride .. i * stride + 3]` (stride in elements, >= 3),
    /// e.g. `[x, y, z, vx, vy, vz, ...]` with stride 6.
    pub fn set_particles_strided_f32(&mut self, data: &[f32], count: usize, stride: usize) -> Result<()> {
        check_strided(data.len(), count, stride)?;
        unsafe { self.set_particles_f32_raw(data.as_ptr(), count, stride * 4) }
    }

    /// Double-precision version of [`Context::set_particles_strided_f32`].
    pub fn set_particles_strided_f64(&mut self, data: &[f64], count: usize, stride: usize) -> Result<()> {
        check_strided(data.len(), count, stride)?;
        unsafe { self.set_particles_f64_raw(data.as_ptr(), count, stride * 8) }
    }

    /// Raw upload: particle i's x, y, z are three f32 at byte offset
    /// `i * byte_stride` from `xyz` (0 = packed).
    ///
    /// # Safety
    /// Those `count` triples must be readable for the duration of the call.
    pub unsafe fn set_particles_f32_raw(&mut self, xyz: *const f32, count: usize, byte_stride: usize) -> Result<()> {
        let s =
            unsafe { sys::nbmc_context_set_particles_f32(self.raw.as_ptr(), xyz, count as u64, byte_stride as u64) };
        self.uploaded(s, count)
    }

    /// Raw upload of f64 positions; see [`Context::set_particles_f32_raw`].
    ///
    /// # Safety
    /// Those `count` triples must be readable for the duration of the call.
    pub unsafe fn set_particles_f64_raw(&mut self, xyz: *const f64, count: usize, byte_stride: usize) -> Result<()> {
        let s =
            unsafe { sys::nbmc_context_set_particles_f64(self.raw.as_ptr(), xyz, count as u64, byte_stride as u64) };
        self.uploaded(s, count)
    }

    /// Uploads (copies) `count` f32 positions from CUDA device memory: particle
    /// i's x, y, z are three f32 at byte offset `i * byte_stride` from `xyz`
    /// (0 = packed; otherwise a multiple of 4). The copy and the validation
    /// run on the GPU; the call returns when the copy is done, so the caller
    /// may then change its array. Replaces earlier particles.
    ///
    /// Errors: [`Error::BACKEND_UNAVAILABLE`] unless the context uses the
    /// CUDA backend (nothing is read then); [`Error::INVALID_ARGUMENT`] for a
    /// host pointer, memory of another GPU, NULL or a bad stride;
    /// [`Error::INVALID_PARTICLES`] / [`Error::NO_PARTICLES`] as for host
    /// uploads. On failure the context keeps no particles.
    ///
    /// # Safety
    /// `xyz` must be CUDA device (or managed) memory of the context's GPU
    /// (cudaMalloc'd, e.g. from cust or cudarc), aligned to 4 bytes, in which
    /// those `count` strided triples are allocated and stay allocated and
    /// unchanged for the duration of the call (no kernel of the caller may
    /// write them meanwhile). nbmc recognises host pointers, but it cannot
    /// check the extent of a device allocation.
    pub unsafe fn set_particles_device_f32(&mut self, xyz: *const f32, count: usize, byte_stride: usize) -> Result<()> {
        let s = unsafe {
            sys::nbmc_context_set_particles_device_f32(self.raw.as_ptr(), xyz, count as u64, byte_stride as u64)
        };
        self.uploaded(s, count)
    }

    /// Double-precision version of [`Context::set_particles_device_f32`]
    /// (stride a multiple of 8).
    ///
    /// # Safety
    /// As for [`Context::set_particles_device_f32`], with f64 values aligned
    /// to 8 bytes.
    pub unsafe fn set_particles_device_f64(&mut self, xyz: *const f64, count: usize, byte_stride: usize) -> Result<()> {
        let s = unsafe {
            sys::nbmc_context_set_particles_device_f64(self.raw.as_ptr(), xyz, count as u64, byte_stride as u64)
        };
        self.uploaded(s, count)
    }

    /// Where the meshes of later reconstructions on this context are put:
    /// [`Memory::Host`] (the default) or [`Memory::Device`], which leaves them
    /// in the GPU's memory (see [`Mesh::memory`]); `Device` needs the CUDA
    /// backend, else [`Error::BACKEND_UNAVAILABLE`].
    pub fn set_mesh_memory(&mut self, memory: Memory) -> Result<()> {
        let s = unsafe { sys::nbmc_context_set_mesh_memory(self.raw.as_ptr(), memory.raw()) };
        self.check(s)
    }

    /// Reads the particle positions of a file with nbmc's readers and uploads
    /// them (same validation as the set_particles functions). `format` is a
    /// format name ("xyz", "ply", "vtk", "bgeo", "h5part", ...; see
    /// docs/api.md) or None to go by the extension. Returns the particle count.
    pub fn load_particles(&mut self, path: impl AsRef<Path>, format: Option<&str>) -> Result<u64> {
        let p = path_cstring(path.as_ref())?;
        let f = format_cstring(format)?;
        let mut count = 0u64;
        let s = unsafe {
            sys::nbmc_context_load_particles(
                self.raw.as_ptr(),
                p.as_ptr(),
                f.as_ref().map_or(ptr::null(), |f| f.as_ptr()),
                &mut count,
            )
        };
        self.uploaded(s, count as usize)?;
        Ok(count)
    }

    /// Caps what nbmc may allocate for this context's reconstructions (host
    /// and device together, bytes; 0 = no cap). Over the cap a reconstruction
    /// fails with `NBMC_ERROR_MEMORY_BUDGET` and the estimate in the message.
    pub fn set_memory_budget(&mut self, bytes: u64) -> Result<()> {
        // SAFETY: the handle is valid for the lifetime of self.
        let status = unsafe { sys::nbmc_context_set_memory_budget(self.raw.as_ptr(), bytes) };
        self.check(status)
    }

    /// Calls `f(stage, fraction)` during reconstructions; returning false
    /// cancels (the reconstruction then fails with [`Error::CANCELLED`]). A
    /// panic in `f` cancels the reconstruction and is resumed after it.
    pub fn set_progress<F>(&mut self, f: F) -> Result<()>
    where
        F: FnMut(Stage, f64) -> bool + Send + 'static,
    {
        let slot = ProgressSlot::new(Progress { callback: Box::new(f), panic: None });
        let user = slot.0.as_ptr().cast::<c_void>();
        let s = unsafe { sys::nbmc_context_set_progress(self.raw.as_ptr(), Some(progress_trampoline), user) };
        self.check(s)?;
        self.progress = Some(slot); // the previous one is unregistered now
        Ok(())
    }

    /// Removes the progress callback.
    pub fn clear_progress(&mut self) -> Result<()> {
        let s = unsafe { sys::nbmc_context_set_progress(self.raw.as_ptr(), None, ptr::null_mut()) };
        self.check(s)?;
        self.progress = None;
        Ok(())
    }

    /// Reconstructs the surface of the uploaded particles (blocking).
    pub fn reconstruct(&mut self, params: &Params) -> Result<Mesh> {
        let p = params.to_raw();
        let mut mesh = ptr::null_mut();
        let status = unsafe { sys::nbmc_context_reconstruct(self.raw.as_ptr(), &p, &mut mesh) };
        if let Some(payload) = self.progress.as_mut().and_then(ProgressSlot::take_panic) {
            unsafe { sys::nbmc_mesh_destroy(mesh) };
            panic::resume_unwind(payload);
        }
        self.check(status)?;
        let raw = NonNull::new(mesh).ok_or_else(|| Error::new(sys::NBMC_ERROR_INTERNAL, "mesh is NULL"))?;
        Ok(Mesh { raw })
    }

    /// Figures of the last successful reconstruction.
    pub fn stats(&self) -> Result<Stats> {
        let mut s = sys::nbmc_stats::default();
        unsafe { sys::nbmc_stats_init(&mut s) };
        let status = unsafe { sys::nbmc_context_stats(self.raw.as_ptr(), &mut s) };
        if status != sys::NBMC_OK {
            return Err(Error::new(status, "no successful reconstruction on this context yet"));
        }
        let mut stage_seconds = [0.0; sys::NBMC_STAGE_COUNT as usize];
        stage_seconds.copy_from_slice(&s.stage_seconds[..sys::NBMC_STAGE_COUNT as usize]);
        Ok(Stats {
            particle_count: s.particle_count,
            surface_particle_count: s.surface_particle_count,
            occupied_cell_count: s.occupied_cell_count,
            band_vertex_count: s.band_vertex_count,
            band_block_count: s.band_block_count,
            grid_vertex_count: s.grid_vertex_count,
            triangulated_cell_count: s.triangulated_cell_count,
            vertex_count: s.vertex_count,
            triangle_count: s.triangle_count,
            grid_dims: s.grid_dims,
            peak_memory_bytes: s.peak_memory_bytes,
            neighbour_evaluations: s.neighbour_evaluations,
            stage_seconds,
            total_seconds: s.total_seconds,
            grid_origin: s.grid_origin,
            cell_size: s.cell_size,
            dropped_particle_count: s.dropped_particle_count,
            dropped_cluster_count: s.dropped_cluster_count,
            pre_decimation_triangle_count: s.pre_decimation_triangle_count,
            raw_triangle_count: s.raw_triangle_count,
            cleanup_bad_triangles_before: s.cleanup_bad_triangles_before,
            cleanup_bad_triangles_after: s.cleanup_bad_triangles_after,
            cleanup_moves: s.cleanup_moves,
            cleanup_flips: s.cleanup_flips,
            cleanup_collapses: s.cleanup_collapses,
            cleanup_cuts: s.cleanup_cuts,
            cleanup_removed_component_triangles: s.cleanup_removed_component_triangles,
        })
    }
}

fn check_strided(len: usize, count: usize, stride: usize) -> Result<()> {
    if stride < 3 {
        return Err(Error::new(sys::NBMC_ERROR_INVALID_ARGUMENT, format!("stride {stride} is smaller than 3")));
    }
    let need = if count == 0 {
        0
    } else {
        (count - 1).checked_mul(stride).and_then(|n| n.checked_add(3)).unwrap_or(usize::MAX)
    };
    if need > len {
        return Err(Error::new(
            sys::NBMC_ERROR_INVALID_ARGUMENT,
            format!("{count} particles with stride {stride} need {need} values, the slice has {len}"),
        ));
    }
    Ok(())
}

impl Drop for Context {
    fn drop(&mut self) {
        unsafe { sys::nbmc_context_destroy(self.raw.as_ptr()) };
    }
}

impl fmt::Debug for Context {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Context").field("raw", &self.raw).finish_non_exhaustive()
    }
}

// --------------------------------------------------------------------- mesh

/// A triangle mesh. Owns its memory (independent of the context); the slices
/// borrow it without copying. A mesh in device memory ([`Memory::Device`])
/// hands out no slices: see [`Mesh::copy_to_host`] and [`Mesh::device_arrays`].
pub struct Mesh {
    raw: NonNull<sys::nbmc_mesh>,
}

/// A mesh's arrays copied to the host by [`Mesh::copy_to_host`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HostMesh {
    pub positions: Vec<[f32; 3]>,
    /// None when the reconstruction computed no normals.
    pub normals: Option<Vec<[f32; 3]>>,
    pub triangles: Vec<[u32; 3]>,
}

/// Raw pointers to the arrays of a device mesh (same layout as the slices:
/// 3 values per vertex or triangle), valid while the [`Mesh`] lives; freed
/// when it is dropped. CUDA device pointers: never dereference them on the
/// host. Null for an empty mesh; `normals` is null when none were computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DeviceArrays {
    pub positions: *const f32,
    pub normals: *const f32,
    pub triangles: *const u32,
    pub vertex_count: usize,
    pub triangle_count: usize,
}

// SAFETY: a mesh is immutable after creation; nbmc.h allows concurrent getters
// and destroying it from any thread.
unsafe impl Send for Mesh {}
unsafe impl Sync for Mesh {}

impl Mesh {
    pub fn vertex_count(&self) -> usize {
        unsafe { sys::nbmc_mesh_vertex_count(self.raw.as_ptr()) as usize }
    }

    pub fn triangle_count(&self) -> usize {
        unsafe { sys::nbmc_mesh_triangle_count(self.raw.as_ptr()) as usize }
    }

    /// Where the mesh's arrays live ([`Context::set_mesh_memory`]). A value
    /// this binding does not know counts as [`Memory::Device`] (not host
    /// memory: no slices are handed out).
    pub fn memory(&self) -> Memory {
        let m = unsafe { sys::nbmc_mesh_memory(self.raw.as_ptr()) };
        Memory::from_raw(m).unwrap_or(Memory::Device)
    }

    fn on_host(&self) -> bool {
        self.memory() == Memory::Host
    }

    /// Whether the reconstruction computed normals (host or device mesh).
    pub fn has_normals(&self) -> bool {
        !unsafe { sys::nbmc_mesh_normals(self.raw.as_ptr()) }.is_null()
    }

    /// Vertex positions. Empty for a mesh in device memory (see
    /// [`Mesh::memory`]; use [`Mesh::copy_to_host`] there). For a mesh made
    /// with [`Params::double_positions`], its doubles rounded to f32 (see
    /// [`Mesh::positions_f64`]).
    pub fn positions(&self) -> &[[f32; 3]] {
        if !self.on_host() {
            return &[];
        }
        // SAFETY: host memory: 3 * vertex_count floats, alive until
        // nbmc_mesh_destroy (drop).
        unsafe { slice3(sys::nbmc_mesh_positions(self.raw.as_ptr()), self.vertex_count()) }
    }

    /// Double-precision vertex positions of a mesh made with
    /// [`Params::double_positions`]; None for a float mesh (its
    /// [`Mesh::positions`] are all it has) and for an empty one.
    pub fn positions_f64(&self) -> Option<&[[f64; 3]]> {
        let p = unsafe { sys::nbmc_mesh_positions_f64(self.raw.as_ptr()) };
        if p.is_null() {
            None
        } else {
            // SAFETY: host memory: 3 * vertex_count doubles, alive until
            // nbmc_mesh_destroy (drop).
            Some(unsafe { slice3(p, self.vertex_count()) })
        }
    }

    /// Unit normals pointing out of the fluid; None when not computed, and
    /// for a mesh in device memory ([`Mesh::has_normals`] tells the two apart).
    pub fn normals(&self) -> Option<&[[f32; 3]]> {
        if !self.on_host() {
            return None;
        }
        let p = unsafe { sys::nbmc_mesh_normals(self.raw.as_ptr()) };
        if p.is_null() {
            None
        } else {
            Some(unsafe { slice3(p, self.vertex_count()) })
        }
    }

    /// Vertex indices, counter-clockwise seen from outside the fluid. Empty
    /// for a mesh in device memory.
    pub fn triangles(&self) -> &[[u32; 3]] {
        if !self.on_host() {
            return &[];
        }
        unsafe { slice3(sys::nbmc_mesh_triangles(self.raw.as_ptr()), self.triangle_count()) }
    }

    /// The arrays copied to the host, wherever they live (for a host mesh,
    /// the same values as the slices).
    pub fn copy_to_host(&self) -> Result<HostMesh> {
        let (nv, nt) = (self.vertex_count(), self.triangle_count());
        let mut h = HostMesh {
            positions: vec![[0.0; 3]; nv],
            normals: self.has_normals().then(|| vec![[0.0; 3]; nv]),
            triangles: vec![[0; 3]; nt],
        };
        self.copy_to_host_into(
            Some(h.positions.as_mut_slice()),
            h.normals.as_deref_mut(),
            Some(h.triangles.as_mut_slice()),
        )?;
        Ok(h)
    }

    /// Copies the arrays into buffers the caller owns (e.g. reused from frame
    /// to frame); None skips an array. Each given buffer must have exactly
    /// [`Mesh::vertex_count`] (positions, normals) or
    /// [`Mesh::triangle_count`] (triangles) elements, else
    /// [`Error::INVALID_ARGUMENT`] and nothing is copied. `normals` is left
    /// untouched when the mesh has none.
    pub fn copy_to_host_into(
        &self,
        positions: Option<&mut [[f32; 3]]>,
        normals: Option<&mut [[f32; 3]]>,
        triangles: Option<&mut [[u32; 3]]>,
    ) -> Result<()> {
        let (nv, nt) = (self.vertex_count(), self.triangle_count());
        let check_len = |what: &str, len: usize, want: usize| {
            if len == want {
                Ok(())
            } else {
                Err(Error::new(
                    sys::NBMC_ERROR_INVALID_ARGUMENT,
                    format!("copy_to_host_into: {what} has {len} elements, the mesh {want}"),
                ))
            }
        };
        if let Some(p) = &positions {
            check_len("positions", p.len(), nv)?;
        }
        if let Some(n) = &normals {
            check_len("normals", n.len(), nv)?;
        }
        if let Some(t) = &triangles {
            check_len("triangles", t.len(), nt)?;
        }
        // Empty buffers go as NULL (nothing to copy).
        fn out<T>(b: Option<&mut [[T; 3]]>) -> *mut T {
            match b {
                Some(b) if !b.is_empty() => b.as_mut_ptr().cast(),
                _ => ptr::null_mut(),
            }
        }
        // SAFETY: every non-null pointer has room for the mesh's 3 * count values.
        let s = unsafe { sys::nbmc_mesh_copy_to_host(self.raw.as_ptr(), out(positions), out(normals), out(triangles)) };
        if s == sys::NBMC_OK {
            Ok(())
        } else {
            Err(Error::new(s, format!("nbmc_mesh_copy_to_host failed ({})", status_string(s))))
        }
    }

    /// The raw CUDA device pointers of a mesh in device memory; None for a
    /// host mesh (use the slices). They are valid while `self` lives.
    pub fn device_arrays(&self) -> Option<DeviceArrays> {
        if self.on_host() {
            return None;
        }
        let m = self.raw.as_ptr();
        // Reading the pointer values is safe; dereferencing them on the host is not.
        Some(unsafe {
            DeviceArrays {
                positions: sys::nbmc_mesh_positions(m),
                normals: sys::nbmc_mesh_normals(m),
                triangles: sys::nbmc_mesh_triangles(m),
                vertex_count: self.vertex_count(),
                triangle_count: self.triangle_count(),
            }
        })
    }

    /// Writes the mesh with nbmc's writers ("ply", "obj", "vtk", "vtu",
    /// "glb"; None: by the extension); a device mesh is copied to the host
    /// first. The file is written under a temporary name and renamed into
    /// place, so a failure leaves no partial file.
    pub fn write(&self, path: impl AsRef<Path>, format: Option<&str>) -> Result<()> {
        let p = path_cstring(path.as_ref())?;
        let f = format_cstring(format)?;
        let s = unsafe {
            sys::nbmc_mesh_write(self.raw.as_ptr(), p.as_ptr(), f.as_ref().map_or(ptr::null(), |f| f.as_ptr()))
        };
        if s == sys::NBMC_OK {
            Ok(())
        } else {
            // Thread-local message; this thread made the call just now.
            Err(Error::new(s, thread_last_error()))
        }
    }

    /// Names of the attributes interpolated onto the mesh, in the order they
    /// were first set on the context.
    pub fn attribute_names(&self) -> Vec<String> {
        let n = unsafe { sys::nbmc_mesh_attribute_count(self.raw.as_ptr()) };
        (0..n).map(|i| c_str(unsafe { sys::nbmc_mesh_attribute_name(self.raw.as_ptr(), i) })).collect()
    }

    /// The values of attribute `name`, `components` (1 or 3) per vertex, and
    /// that count; None when the mesh has no such attribute. Host memory for
    /// every mesh (also one in device memory).
    pub fn attribute(&self, name: &str) -> Option<(&[f32], usize)> {
        let n = CString::new(name).ok()?;
        let mut comps = 0u32;
        let p = unsafe { sys::nbmc_mesh_attribute(self.raw.as_ptr(), n.as_ptr(), &mut comps) };
        if comps == 0 {
            return None;
        }
        let len = self.vertex_count() * comps as usize;
        if p.is_null() || len == 0 {
            return Some((&[], comps as usize));
        }
        // SAFETY: host memory of components * vertex_count floats, alive
        // until nbmc_mesh_destroy (drop).
        Some((unsafe { std::slice::from_raw_parts(p, len) }, comps as usize))
    }

    /// `Isolated::Sphere`: the dropped particles as spheres, `[x, y, z,
    /// radius]` each, in the particles' order (host memory); empty otherwise.
    pub fn spheres(&self) -> &[[f32; 4]] {
        let n = unsafe { sys::nbmc_mesh_sphere_count(self.raw.as_ptr()) } as usize;
        let p = unsafe { sys::nbmc_mesh_spheres(self.raw.as_ptr()) };
        if p.is_null() || n == 0 {
            return &[];
        }
        // SAFETY: host memory of 4 * n floats, alive until nbmc_mesh_destroy
        // (drop); [f32; 4] has the layout of 4 floats.
        unsafe { std::slice::from_raw_parts(p as *const [f32; 4], n) }
    }

    /// The raw handle; it stays owned by the mesh.
    pub fn as_raw(&self) -> *const sys::nbmc_mesh {
        self.raw.as_ptr()
    }
}

/// # Safety
/// `p` must be NULL (then `n` is taken as 0) or point to `3 * n` valid values.
unsafe fn slice3<'a, T>(p: *const T, n: usize) -> &'a [[T; 3]] {
    if p.is_null() || n == 0 {
        &[]
    } else {
        // [T; 3] has the size and alignment of three packed T.
        unsafe { std::slice::from_raw_parts(p.cast::<[T; 3]>(), n) }
    }
}

impl Drop for Mesh {
    fn drop(&mut self) {
        unsafe { sys::nbmc_mesh_destroy(self.raw.as_ptr()) };
    }
}

impl fmt::Debug for Mesh {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Mesh")
            .field("vertices", &self.vertex_count())
            .field("triangles", &self.triangle_count())
            .field("memory", &self.memory())
            .finish()
    }
}

// ------------------------------------------------------------------- Kokkos

/// Finalises the Kokkos runtime that nbmc initialised (no-op if the host
/// program initialised Kokkos itself). Call after dropping every context;
/// fails with [`Error::INVALID_ARGUMENT`] while contexts are alive. No context
/// can be created in this process afterwards.
pub fn kokkos_finalize() -> Result<()> {
    let s = unsafe { sys::nbmc_kokkos_finalize() };
    if s == sys::NBMC_OK {
        Ok(())
    } else {
        Err(Error::new(s, "nbmc_kokkos_finalize: contexts are still alive"))
    }
}
