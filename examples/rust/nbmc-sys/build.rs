// SPDX-License-Identifier: MIT
//! Finds an installed nbmc and links it. In order:
//!  1. `NBMC_DIR`: an install prefix (holding include/nbmc.h and lib/libnbmc.so);
//!  2. `pkg-config nbmc` (honours `PKG_CONFIG_PATH`; `PKG_CONFIG` names the tool);
//!  3. the in-tree install `build/install` of the nbmc repository.
//!
//! The library directory is also put into the rpath of this crate's tests and
//! passed on to dependent crates as `DEP_NBMC_LIBDIR` (links = "nbmc"), so
//! `cargo test` runs without LD_LIBRARY_PATH.
use std::env;
use std::path::{Path, PathBuf};
use std::process::Command;

struct Found {
    how: String,
    include: PathBuf,
    lib: PathBuf,
}

fn lib_dir_in(prefix: &Path) -> Option<PathBuf> {
    ["lib", "lib64", "lib/x86_64-linux-gnu", "lib/aarch64-linux-gnu"]
        .iter()
        .map(|d| prefix.join(d))
        .find(|d| d.join("libnbmc.so").exists() || d.join("libnbmc.dylib").exists())
}

fn from_prefix(prefix: &Path, how: &str) -> Option<Found> {
    let include = prefix.join("include");
    if !include.join("nbmc.h").exists() {
        return None;
    }
    Some(Found { how: how.to_string(), include, lib: lib_dir_in(prefix)? })
}

fn pkg_config_var(tool: &str, var: &str) -> Option<PathBuf> {
    let out = Command::new(tool).args(["--variable", var, "nbmc"]).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let s = String::from_utf8(out.stdout).ok()?;
    let s = s.trim();
    if s.is_empty() {
        None
    } else {
        Some(PathBuf::from(s))
    }
}

fn from_pkg_config() -> Option<Found> {
    let tool = env::var("PKG_CONFIG").unwrap_or_else(|_| "pkg-config".to_string());
    let lib = pkg_config_var(&tool, "libdir")?;
    let include = pkg_config_var(&tool, "includedir")?;
    if !include.join("nbmc.h").exists() {
        return None;
    }
    Some(Found { how: format!("{tool} nbmc"), include, lib })
}

fn main() {
    for v in ["NBMC_DIR", "PKG_CONFIG", "PKG_CONFIG_PATH"] {
        println!("cargo:rerun-if-env-changed={v}");
    }
    println!("cargo:rerun-if-changed=build.rs");

    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR").unwrap());
    // examples/rust/nbmc-sys -> repository root
    let root = manifest.ancestors().nth(3).unwrap_or(&manifest).to_path_buf();
    let in_tree = root.join("build/install");

    let found = match env::var_os("NBMC_DIR") {
        Some(dir) => {
            let prefix = PathBuf::from(dir);
            from_prefix(&prefix, "NBMC_DIR").unwrap_or_else(|| {
                panic!(
                    "NBMC_DIR={} holds no include/nbmc.h and lib/libnbmc.so (it must be an nbmc install prefix)",
                    prefix.display()
                )
            })
        }
        None => from_pkg_config().or_else(|| from_prefix(&in_tree, "in-tree build/install")).unwrap_or_else(|| {
            panic!(
                "cannot find nbmc: set NBMC_DIR to its install prefix, put <prefix>/lib/pkgconfig on \
                     PKG_CONFIG_PATH, or run scripts/setup.sh to create {}",
                in_tree.display()
            )
        }),
    };

    let lib = found.lib.canonicalize().unwrap_or(found.lib.clone());
    let include = found.include.canonicalize().unwrap_or(found.include.clone());
    println!("cargo:rustc-link-search=native={}", lib.display());
    println!("cargo:rustc-link-lib=dylib=nbmc");
    if std::env::var_os("CARGO_FEATURE_MPI").is_some() {
        println!("cargo:rustc-link-lib=dylib=nbmc_mpi");
    }
    // rpath for this crate's own tests; dependants read DEP_NBMC_LIBDIR.
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib.display());
    println!("cargo:libdir={}", lib.display());
    println!("cargo:include={}", include.display());
    // For tests/layout.rs, which compiles a C program against the real header.
    println!("cargo:rustc-env=NBMC_INCLUDE_DIR={}", include.display());
    println!("cargo:rustc-env=NBMC_LIB_DIR={}", lib.display());
    println!("cargo:rerun-if-changed={}", include.join("nbmc.h").display());
    if env::var_os("NBMC_SYS_VERBOSE").is_some() {
        println!("cargo:warning=nbmc found via {}: {}", found.how, lib.display());
    }
}
