// SPDX-License-Identifier: MIT
//! Reconstructs one frame and writes it as a binary PLY.
//!
//!   cargo run --example reconstruct -- [PARTICLES.xyz SPACING OUT.ply]
//!
//! Without arguments it uses the repository's sample frame
//! (examples/data/double_dam_break_4732.xyz, spacing 0.05) and writes to the
//! system's temporary directory.
use nbmc::{Context, Mesh, Params};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Raw particle file: little-endian float32 x, y, z triples, no header.
fn read_xyz(path: &Path) -> Result<Vec<[f32; 3]>, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    if bytes.is_empty() || bytes.len() % 12 != 0 {
        return Err(format!("{}: {} bytes is not a positive multiple of 12", path.display(), bytes.len()));
    }
    let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    Ok(bytes.chunks_exact(12).map(|p| [f(&p[0..4]), f(&p[4..8]), f(&p[8..12])]).collect())
}

fn write_ply(path: &Path, mesh: &Mesh) -> std::io::Result<()> {
    let mut w = BufWriter::new(std::fs::File::create(path)?);
    let normals = mesh.normals();
    writeln!(w, "ply\nformat binary_little_endian 1.0\ncomment written by the nbmc Rust example")?;
    writeln!(w, "element vertex {}\nproperty float x\nproperty float y\nproperty float z", mesh.vertex_count())?;
    if normals.is_some() {
        writeln!(w, "property float nx\nproperty float ny\nproperty float nz")?;
    }
    writeln!(w, "element face {}\nproperty list uchar uint vertex_indices\nend_header", mesh.triangle_count())?;
    // Borrowed slices straight from the C mesh: no copy.
    for (i, p) in mesh.positions().iter().enumerate() {
        for v in p {
            w.write_all(&v.to_le_bytes())?;
        }
        if let Some(n) = normals {
            for v in &n[i] {
                w.write_all(&v.to_le_bytes())?;
            }
        }
    }
    for t in mesh.triangles() {
        w.write_all(&[3u8])?;
        for i in t {
            w.write_all(&i.to_le_bytes())?;
        }
    }
    w.flush()
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (input, spacing, output) = match args.as_slice() {
        [] => (
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/double_dam_break_4732.xyz"),
            0.05,
            std::env::temp_dir().join("nbmc_rust_example.ply"),
        ),
        [i, s, o] => (PathBuf::from(i), s.parse::<f64>().map_err(|e| format!("SPACING '{s}': {e}"))?, PathBuf::from(o)),
        _ => return Err("usage: reconstruct [PARTICLES.xyz SPACING OUT.ply]".into()),
    };

    println!("nbmc {}", nbmc::version_string());
    let particles = read_xyz(&input)?;
    println!("read {} particles from {}", particles.len(), input.display());

    let mut ctx = Context::new()?;
    println!("backend: {:?}", ctx.backend()?);
    ctx.set_particles_f32(&particles)?;
    ctx.set_progress(|stage, fraction| {
        if fraction >= 1.0 {
            eprintln!("  {:<18} done", stage.name());
        }
        true // keep going
    })?;
    let mesh = ctx.reconstruct(&Params::new(spacing))?;
    let stats = ctx.stats()?;
    drop(ctx); // the mesh outlives its context

    println!(
        "{} surface particles, {} vertices, {} triangles in {:.3} s",
        stats.surface_particle_count,
        mesh.vertex_count(),
        mesh.triangle_count(),
        stats.total_seconds
    );
    if mesh.triangle_count() == 0 {
        return Err("the mesh is empty (is SPACING right for these particles?)".into());
    }
    write_ply(&output, &mesh).map_err(|e| format!("cannot write {}: {e}", output.display()))?;
    println!("wrote {}", output.display());
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
