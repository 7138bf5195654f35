// SPDX-License-Identifier: MIT
//! Checks the hand-written declarations of this crate against the real header.
//!
//! The test reads `nbmc.h` (from the nbmc that build.rs found), writes a small
//! C program that includes it, compiles it with the system C compiler (`$CC`,
//! else `cc`) and compares what it prints with the Rust side:
//!  - every `#define NBMC_*` constant of the header exists here with that value;
//!  - every struct of the header has the same fields in the same order, and the
//!    same size, alignment, field offsets and field sizes;
//!  - every function of the header is declared in `src/lib.rs` and no other,
//!    and the C compiler accepts the Rust signatures (turned back into C
//!    prototypes) as redeclarations of the header's, so parameter and return
//!    types match; the callback typedef is compared the same way.
use nbmc_sys::*;
use std::collections::{BTreeMap, BTreeSet};
use std::mem::{align_of, size_of, MaybeUninit};
use std::path::PathBuf;
use std::process::Command;

const LIB_RS: &str = include_str!("../src/lib.rs");

fn header() -> String {
    let path = PathBuf::from(env!("NBMC_INCLUDE_DIR")).join("nbmc.h");
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

// ------------------------------------------------------------- Rust tables

/// Every constant of the Rust side, by its C name.
fn rust_constants() -> BTreeMap<&'static str, i128> {
    macro_rules! table {
        ($($c:ident),* $(,)?) => { BTreeMap::from([$((stringify!($c), $c as i128)),*]) };
    }
    table![
        NBMC_VERSION_MAJOR,
        NBMC_VERSION_MINOR,
        NBMC_VERSION_PATCH,
        NBMC_VERSION,
        NBMC_OK,
        NBMC_ERROR_INVALID_ARGUMENT,
        NBMC_ERROR_INVALID_PARTICLES,
        NBMC_ERROR_NO_PARTICLES,
        NBMC_ERROR_INVALID_PARAMETER,
        NBMC_ERROR_DOMAIN_TOO_LARGE,
        NBMC_ERROR_OUT_OF_MEMORY,
        NBMC_ERROR_BACKEND_UNAVAILABLE,
        NBMC_ERROR_IO,
        NBMC_ERROR_INTERNAL,
        NBMC_ERROR_MEMORY_BUDGET,
        NBMC_ERROR_CANCELLED,
        NBMC_ERROR_FORMAT,
        NBMC_BACKEND_AUTO,
        NBMC_BACKEND_SERIAL,
        NBMC_BACKEND_OPENMP,
        NBMC_BACKEND_CUDA,
        NBMC_METHOD_SSP07,
        NBMC_METHOD_ZB05,
        NBMC_METHOD_SPH,
        NBMC_METHOD_YT10,
        NBMC_ISOLATED_KEEP,
        NBMC_ISOLATED_DROP,
        NBMC_ISOLATED_SPHERE,
        NBMC_SMOOTH_UNIFORM,
        NBMC_SMOOTH_FEATURE,
        NBMC_FIELD_NARROW_BAND,
        NBMC_FIELD_DENSE,
        NBMC_FIELD_SCATTER,
        NBMC_CONTEXT_KOKKOS_ON_CALLING_THREAD,
        NBMC_MEMORY_HOST,
        NBMC_MEMORY_DEVICE,
        NBMC_UNIT_SPACING,
        NBMC_UNIT_ABSOLUTE,
        NBMC_STAGE_UPLOAD,
        NBMC_STAGE_NEIGHBOURHOOD,
        NBMC_STAGE_SURFACE_PARTICLES,
        NBMC_STAGE_BAND,
        NBMC_STAGE_FIELD,
        NBMC_STAGE_TRIANGULATION,
        NBMC_STAGE_OUTPUT,
        NBMC_STAGE_COUNT,
        NBMC_STAGE_SLOTS,
        NBMC_STAGE_POSTPROCESS,
        NBMC_STAGE_ATTRIBUTES,
        NBMC_SUBDOMAINS_AUTO,
    ]
}

struct Layout {
    name: &'static str,
    size: usize,
    align: usize,
    fields: Vec<(&'static str, usize, usize)>, // name, offset, size
}

fn field_size<T>(_: *const T) -> usize {
    size_of::<T>()
}

fn field_offset<S, T>(base: *const S, field: *const T) -> usize {
    field as usize - base as usize
}

macro_rules! layout {
    ($t:ident { $($f:ident),* $(,)? }) => {{
        let u = MaybeUninit::<$t>::uninit();
        let p = u.as_ptr();
        Layout {
            name: stringify!($t),
            size: size_of::<$t>(),
            align: align_of::<$t>(),
            // SAFETY: addr_of! on a field of an uninitialised value reads nothing.
            // (Offsets by address difference, not offset_of!: that needs Rust
            // 1.77 and the crates build with Debian 12's 1.63.)
            fields: vec![$((stringify!($f), field_offset(p, unsafe { std::ptr::addr_of!((*p).$f) }),
                            field_size(unsafe { std::ptr::addr_of!((*p).$f) }))),*],
        }
    }};
}

/// Every struct of the Rust side, fields in declaration order.
fn rust_layouts() -> Vec<Layout> {
    vec![
        layout!(nbmc_context_desc { struct_size, backend, num_threads, device_id, flags, reserved0 }),
        layout!(nbmc_params {
            struct_size,
            length_unit,
            spacing,
            cell_size,
            influence_radius,
            band_width,
            surface_radius,
            iso_radius,
            method,
            field,
            t_low,
            t_high,
            color_threshold,
            neighbour_threshold,
            compute_normals,
            use_bbox,
            reserved0,
            bbox_min,
            bbox_max,
            cleanup,
            smooth_iterations,
            iso_threshold,
            isolated,
            min_cluster,
            double_positions,
            decimate_fraction,
            smooth_weighting,
            reserved1,
            aniso_kr,
            aniso_ks,
            aniso_kn,
            aniso_lambda,
            aniso_neighbours,
            reserved2,
            max_distance
        }),
        layout!(nbmc_stats {
            struct_size,
            reserved0,
            particle_count,
            surface_particle_count,
            occupied_cell_count,
            band_vertex_count,
            band_block_count,
            grid_vertex_count,
            triangulated_cell_count,
            vertex_count,
            triangle_count,
            grid_dims,
            peak_memory_bytes,
            neighbour_evaluations,
            stage_seconds,
            total_seconds,
            grid_origin,
            cell_size,
            raw_triangle_count,
            smoothing_volume_change,
            dropped_particle_count,
            dropped_cluster_count,
            pre_decimation_triangle_count,
            cleanup_bad_triangles_before,
            cleanup_bad_triangles_after,
            cleanup_moves,
            cleanup_flips,
            cleanup_collapses,
            cleanup_cuts,
            cleanup_removed_component_triangles
        }),
        layout!(nbmc_mesh_check_result {
            struct_size,
            closed,
            manifold,
            oriented,
            vertex_count,
            triangle_count,
            edge_count,
            boundary_edge_count,
            nonmanifold_edge_count,
            misoriented_edge_count,
            nonmanifold_vertex_count,
            unreferenced_vertex_count,
            degenerate_triangle_count,
            sliver_triangle_count,
            component_count,
            euler_characteristic,
            volume,
            area,
            min_angle_degrees
        }),
        layout!(nbmc_subdomain_stats {
            struct_size,
            parts,
            count,
            automatic,
            reserved,
            ghost_width,
            ghost_particles,
            reruns,
            exchanged_cells,
            shared_vertices,
            budget_bytes,
            stitch_seconds
        }),
        layout!(nbmc_subdomain_entry {
            struct_size,
            coord,
            cell_lo,
            cell_hi,
            particles,
            ghost_particles,
            vertex_count,
            triangle_count,
            runs,
            rank,
            seconds
        }),
    ]
}

// --------------------------------------------------------- header parsing

fn strip_c_comments(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    loop {
        let block = rest.find("/*");
        let line = rest.find("//");
        let (start, is_block) = match (block, line) {
            (Some(b), Some(l)) if l < b => (l, false),
            (Some(b), _) => (b, true),
            (None, Some(l)) => (l, false),
            (None, None) => {
                out.push_str(rest);
                return out;
            }
        };
        out.push_str(&rest[..start]);
        rest = &rest[start..];
        let end = if is_block { rest.find("*/").map(|e| e + 2) } else { rest.find('\n') };
        match end {
            Some(e) => {
                out.push(' ');
                rest = &rest[e..];
            }
            None => return out,
        }
    }
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

fn last_ident(s: &str) -> &str {
    let s = s.trim_end();
    let start = s.rfind(|c: char| !is_ident(c)).map_or(0, |i| i + 1);
    &s[start..]
}

/// Object-like `#define NBMC_*` names (not the guard and not the export macro).
fn header_constants(h: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for line in strip_c_comments(h).lines() {
        let l = line.trim_start();
        let l = match l.strip_prefix('#') {
            Some(v) => v,
            None => continue,
        };
        let l = match l.trim_start().strip_prefix("define") {
            Some(v) => v,
            None => continue,
        };
        let l = l.trim_start();
        let name: String = l.chars().take_while(|&c| is_ident(c)).collect();
        let function_like = l[name.len()..].starts_with('(');
        if name.starts_with("NBMC_") && name != "NBMC_H" && name != "NBMC_API" && !function_like {
            out.insert(name);
        }
    }
    out
}

/// Names of the functions declared with NBMC_API.
fn header_functions(h: &str) -> BTreeSet<String> {
    let text = strip_c_comments(h);
    let mut out = BTreeSet::new();
    for line in text.lines() {
        if line.trim_start().starts_with('#') {
            continue; // the definition of NBMC_API itself
        }
        let mut rest = line;
        while let Some(i) = rest.find("NBMC_API") {
            rest = &rest[i + "NBMC_API".len()..];
            if let Some(paren) = rest.find('(') {
                out.insert(last_ident(&rest[..paren]).to_string());
            }
        }
    }
    out
}

/// `typedef struct NAME { fields } NAME;` -> field names in order.
fn header_structs(h: &str) -> BTreeMap<String, Vec<String>> {
    let text = strip_c_comments(h);
    let mut out = BTreeMap::new();
    let mut rest = text.as_str();
    while let Some(i) = rest.find("typedef struct") {
        rest = &rest[i + "typedef struct".len()..];
        let (brace, semi) = match (rest.find('{'), rest.find(';')) {
            (Some(a), Some(b)) => (a, b),
            _ => break,
        };
        if brace > semi {
            continue; // opaque: typedef struct X X;
        }
        let name = rest[..brace].trim().to_string();
        let close = rest.find('}').expect("unterminated struct");
        let fields = rest[brace + 1..close]
            .split(';')
            .map(|d| d.split('[').next().unwrap())
            .filter(|d| !d.trim().is_empty())
            .map(|d| last_ident(d).to_string())
            .collect();
        out.insert(name, fields);
        rest = &rest[close..];
    }
    out
}

// ------------------------------------------------------------ lib.rs parsing

/// One `pub fn` of an `extern "C"` block: name, C parameter types, C return type.
struct RustFn {
    name: String,
    params: Vec<String>,
    ret: String,
}

fn rust_type_to_c(t: &str) -> String {
    let t = t.trim();
    if let Some(rest) = t.strip_prefix("*const ") {
        return format!("{} const*", rust_type_to_c(rest));
    }
    if let Some(rest) = t.strip_prefix("*mut ") {
        return format!("{}*", rust_type_to_c(rest));
    }
    match t {
        "i8" => "int8_t",
        "u8" => "uint8_t",
        "i16" => "int16_t",
        "u16" => "uint16_t",
        "i32" => "int32_t",
        "u32" => "uint32_t",
        "i64" => "int64_t",
        "u64" => "uint64_t",
        "f32" => "float",
        "f64" => "double",
        "usize" => "size_t",
        "isize" => "ptrdiff_t",
        "c_char" => "char",
        "c_void" => "void",
        "c_int" => "int",
        "()" => "void",
        other if other.starts_with("nbmc_") => other,
        other => panic!("the layout test does not know the Rust type `{other}`: extend rust_type_to_c"),
    }
    .to_string()
}

fn split_params(s: &str) -> Vec<String> {
    s.split(',')
        .map(str::trim)
        .filter(|p| !p.is_empty())
        .map(|p| rust_type_to_c(p.split_once(':').expect("parameter without a type").1))
        .collect()
}

fn rust_functions() -> Vec<RustFn> {
    // nbmc.h's functions: everything before the `mpi` module (nbmc_mpi.h,
    // which needs mpi.h to compile, is checked by linking with feature `mpi`).
    let lib_rs = LIB_RS.split("pub mod mpi {").next().unwrap_or(LIB_RS);
    let src: String = lib_rs.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n");
    let mut out = Vec::new();
    let mut rest = src.as_str();
    while let Some(i) = rest.find("extern \"C\" {") {
        rest = &rest[i + "extern \"C\" {".len()..];
        let end = rest.find("\n}").expect("unterminated extern block");
        for decl in rest[..end].split(';') {
            let decl = decl.split_whitespace().collect::<Vec<_>>().join(" ");
            let d = match decl.strip_prefix("pub fn ") {
                Some(v) => v,
                None => continue,
            };
            let open = d.find('(').unwrap();
            let close = d.rfind(')').unwrap();
            let ret = d[close + 1..].trim().strip_prefix("->").map_or("()", str::trim);
            out.push(RustFn {
                name: d[..open].trim().to_string(),
                params: split_params(&d[open + 1..close]),
                ret: rust_type_to_c(ret),
            });
        }
        rest = &rest[end..];
    }
    out
}

/// `pub type nbmc_x = Option<unsafe extern "C" fn(a: A, b: B) -> R>;`
fn rust_callbacks() -> Vec<RustFn> {
    let mut out = Vec::new();
    let src = LIB_RS.split_whitespace().collect::<Vec<_>>().join(" ");
    for decl in src.split(';') {
        let i = match decl.find("pub type ") {
            Some(v) => v,
            None => continue,
        };
        let d = &decl[i + "pub type ".len()..];
        let (name, ty) = match d.split_once('=') {
            Some(v) => v,
            None => continue,
        };
        let f = match ty.trim().strip_prefix("Option<unsafe extern \"C\" fn(") {
            Some(v) => v,
            None => continue,
        };
        let close = f.rfind(')').unwrap();
        let ret = f[close + 1..].trim().trim_end_matches('>').trim();
        let ret = ret.strip_prefix("->").map_or("()", str::trim);
        out.push(RustFn { name: name.trim().to_string(), params: split_params(&f[..close]), ret: rust_type_to_c(ret) });
    }
    out
}

// -------------------------------------------------------------- the C side

fn c_program(constants: &BTreeSet<String>, layouts: &[Layout], fns: &[RustFn], cbs: &[RustFn]) -> String {
    let mut c = String::from(
        "#include <nbmc.h>\n#include <stddef.h>\n#include <stdio.h>\n\n\
         #define ALIGNOF(T) offsetof(struct { char c; T t; }, t)\n\n\
         /* The Rust declarations, turned back into C: a mismatch is a compile error. */\n",
    );
    let plist = |p: &[String]| if p.is_empty() { "void".to_string() } else { p.join(", ") };
    for f in fns {
        c += &format!("{} {}({});\n", f.ret, f.name, plist(&f.params));
    }
    for f in cbs {
        c += &format!(
            "typedef {ret} (*rust_{n})({p});\n\
             typedef char check_{n}[__builtin_types_compatible_p({n}, rust_{n}) ? 1 : -1];\n",
            ret = f.ret,
            n = f.name,
            p = plist(&f.params)
        );
    }
    c += "\nint main(void) {\n";
    for k in constants {
        c += &format!("  printf(\"const {k} %lld\\n\", (long long)({k}));\n");
    }
    for l in layouts {
        let s = l.name;
        c += &format!("  printf(\"size {s} %zu\\n\", sizeof({s}));\n");
        c += &format!("  printf(\"align {s} %zu\\n\", (size_t)ALIGNOF({s}));\n");
        for (f, _, _) in &l.fields {
            c += &format!("  printf(\"offset {s}.{f} %zu\\n\", offsetof({s}, {f}));\n");
            c += &format!("  printf(\"fsize {s}.{f} %zu\\n\", sizeof(((const {s}*)0)->{f}));\n");
        }
    }
    c += "  return 0;\n}\n";
    c
}

fn run_c(source: &str) -> BTreeMap<String, i128> {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("nbmc-sys-layout-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let src = dir.join("layout.c");
    let exe = dir.join("layout");
    std::fs::write(&src, source).unwrap();
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".to_string());
    let out = Command::new(&cc)
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wno-unused-local-typedefs"])
        .arg("-I")
        .arg(env!("NBMC_INCLUDE_DIR"))
        .arg("-o")
        .arg(&exe)
        .arg(&src)
        .output()
        .unwrap_or_else(|e| panic!("cannot run the C compiler `{cc}`: {e}"));
    assert!(
        out.status.success(),
        "the C check program does not compile against nbmc.h: a Rust declaration differs from the header.\n\
         program: {}\n{}",
        src.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Command::new(&exe).output().expect("cannot run the C check program");
    assert!(run.status.success());
    let text = String::from_utf8(run.stdout).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    text.lines()
        .map(|l| {
            let (k, v) = l.rsplit_once(' ').unwrap();
            (k.to_string(), v.parse().unwrap())
        })
        .collect()
}

// ------------------------------------------------------------------ the test

#[test]
fn rust_declarations_match_the_header() {
    let h = header();
    let mut errors = Vec::new();

    // Constants: the same names on both sides.
    let c_consts = header_constants(&h);
    let rust = rust_constants();
    for k in &c_consts {
        if !rust.contains_key(k.as_str()) {
            errors.push(format!("constant {k} is in nbmc.h but not in nbmc-sys (or its test table)"));
        }
    }
    for k in rust.keys() {
        if !c_consts.contains(*k) {
            errors.push(format!("constant {k} is in nbmc-sys but not in nbmc.h"));
        }
    }

    // Structs: the same field names in the same order.
    let c_structs = header_structs(&h);
    let layouts = rust_layouts();
    for (name, fields) in &c_structs {
        match layouts.iter().find(|l| l.name == name) {
            None => errors.push(format!("struct {name} is in nbmc.h but not checked here / not in nbmc-sys")),
            Some(l) => {
                let ours: Vec<&str> = l.fields.iter().map(|f| f.0).collect();
                if ours != *fields {
                    errors.push(format!("struct {name}: fields differ\n  C:    {fields:?}\n  Rust: {ours:?}"));
                }
            }
        }
    }
    for l in &layouts {
        if !c_structs.contains_key(l.name) {
            errors.push(format!("struct {} is in nbmc-sys but not in nbmc.h", l.name));
        }
    }

    // Functions: the same set of names.
    let c_fns = header_functions(&h);
    let fns = rust_functions();
    let r_fns: BTreeSet<String> = fns.iter().map(|f| f.name.clone()).collect();
    for f in c_fns.difference(&r_fns) {
        errors.push(format!("function {f} is declared in nbmc.h but not in nbmc-sys"));
    }
    for f in r_fns.difference(&c_fns) {
        errors.push(format!("function {f} is declared in nbmc-sys but not in nbmc.h"));
    }
    assert!(c_fns.len() >= 20 && !c_consts.is_empty() && c_structs.len() >= 3, "header parsing went wrong");
    assert!(errors.is_empty(), "nbmc-sys is out of date with nbmc.h:\n{}", errors.join("\n"));

    // Values, sizes and offsets from the C compiler (signatures are checked
    // while it compiles the program).
    let c_consts_in_rust: BTreeSet<String> =
        c_consts.iter().filter(|k| rust.contains_key(k.as_str())).cloned().collect();
    let cvals = run_c(&c_program(&c_consts_in_rust, &layouts, &fns, &rust_callbacks()));
    for (k, v) in &rust {
        let c = cvals[&format!("const {k}")];
        if c != *v {
            errors.push(format!("constant {k}: C {c}, Rust {v}"));
        }
    }
    for l in &layouts {
        let s = l.name;
        let check = |what: String, rust: usize, errors: &mut Vec<String>| {
            let c = cvals[&what];
            if c != rust as i128 {
                errors.push(format!("{what}: C {c}, Rust {rust}"));
            }
        };
        check(format!("size {s}"), l.size, &mut errors);
        check(format!("align {s}"), l.align, &mut errors);
        for (f, off, sz) in &l.fields {
            check(format!("offset {s}.{f}"), *off, &mut errors);
            check(format!("fsize {s}.{f}"), *sz, &mut errors);
        }
    }
    assert!(errors.is_empty(), "nbmc-sys differs from nbmc.h:\n{}", errors.join("\n"));
}

/// The library that is linked is the one whose header was checked.
#[test]
fn linked_library_matches_the_declared_version() {
    let v = unsafe { nbmc_version() };
    assert_eq!(v / 10000, NBMC_VERSION_MAJOR, "major version of the loaded library");
    assert!(v >= NBMC_VERSION, "the loaded library ({v}) is older than the declarations ({NBMC_VERSION})");
    let s = unsafe { std::ffi::CStr::from_ptr(nbmc_version_string()) }.to_str().unwrap();
    assert!(s.starts_with(&format!("{NBMC_VERSION_MAJOR}.{NBMC_VERSION_MINOR}.")), "{s}");
}

/// Defaults filled by the library carry the right struct_size.
#[test]
fn init_functions_fill_struct_size() {
    unsafe {
        let mut d = nbmc_context_desc::default();
        nbmc_context_desc_init(&mut d);
        assert_eq!(d.struct_size as usize, size_of::<nbmc_context_desc>());
        let mut p = nbmc_params::default();
        nbmc_params_init(&mut p);
        assert_eq!(p.struct_size as usize, size_of::<nbmc_params>());
        assert_eq!(p.method, NBMC_METHOD_SSP07);
        let mut s = nbmc_stats::default();
        nbmc_stats_init(&mut s);
        assert_eq!(s.struct_size as usize, size_of::<nbmc_stats>());
        for code in 0..=NBMC_ERROR_FORMAT {
            assert!(!nbmc_status_string(code).is_null());
        }
    }
}
