//! Measures the shadow-ray backends on one scene with the same segments and intersection code.
//!
//! `cargo run --release -p radcast-solver --example ray_backends -- scenes/cornell-box.obj 2000000`

use solver::visibility::{Occluders, RayBackend};
use solver::{Mesh, PatchTarget, Scene};
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "scenes/cornell-box.obj".into());
    let segments: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(2_000_000);
    let scene = Scene::load_obj(path.as_ref())?;
    let mesh = Mesh::build(&scene, PatchTarget::Count(2000));
    let patches = &mesh.patches;
    // Segments between centroids of pseudo-random patch pairs (a fixed LCG keeps runs identical).
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = || {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        (state >> 33) as usize % patches.len()
    };
    let pairs: Vec<(usize, usize)> = (0..segments).map(|_| (next(), next())).collect();
    println!("{path}: {} faces, {segments} segments, 1 thread, median of 5\n", scene.faces.len());
    println!("| backend | build ms | Msegments/s | clear |");
    println!("|---|---:|---:|---:|");
    for backend in [RayBackend::CwBvh, RayBackend::Bvh2, RayBackend::Linear] {
        let start = Instant::now();
        let occluders = Occluders::with_backend(&scene, backend);
        let build_ms = start.elapsed().as_secs_f64() * 1e3;
        let mut rates = Vec::new();
        let mut clear = 0;
        for _ in 0..5 {
            let start = Instant::now();
            clear = pairs
                .iter()
                .filter(|&&(i, j)| {
                    let (p, q) = (&patches[i], &patches[j]);
                    occluders.segment_is_clear(p.centroid, q.centroid, [p.face, q.face])
                })
                .count();
            rates.push(segments as f64 / start.elapsed().as_secs_f64() / 1e6);
        }
        rates.sort_by(f64::total_cmp);
        println!("| {backend:?} | {build_ms:.2} | {:.2} | {clear} |", rates[2]);
    }
    Ok(())
}
