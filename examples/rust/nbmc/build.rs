// SPDX-License-Identifier: MIT
//! nbmc-sys links libnbmc; this only adds its directory to the rpath of our
//! tests and examples so that they run without LD_LIBRARY_PATH.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=DEP_NBMC_LIBDIR");
    if let Ok(dir) = std::env::var("DEP_NBMC_LIBDIR") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
