//! Shadow-ray throughput of the CPU exact reference's traversal, before and after, in one run:
//! obvhs's compressed 8-wide BVH with an exit at the first blocker (`TraceBvh::segment_blocked`,
//! what `twin::exact_cpu` uses) against obvhs's binary BVH with its any-hit traversal (what it
//! used before), on the same shadow rays: every pixel-VAL pair with a non-zero unoccluded term
//! of a real frame, as the reference casts them. Both decide every ray with the same triangle
//! test; a ray they decide differently is an error.
//!
//! ```sh
//! cargo run --example exact_rays -- fixtures/scenes/cornell_bunny.json 16
//! ```

use glam::{Vec3, Vec3A};
use rayon::prelude::*;
use relume::gpu::Gpu;
use relume::gpu::shader::RAY_OFFSET;
use relume::renderer::{Components, Method, Renderer};
use relume::scene::Scene;
use relume::twin::bvh::{TraceBvh, ray_triangle};
use relume::twin::exact_cpu::Receiver;
use relume::twin::val_radiance;
use std::time::Instant;

/// Image side at most: the rays are stored (24 bytes each), ~10 k per pixel on cornell_bunny.
const MAX_SIDE: u32 = 32;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).ok_or_else(|| anyhow::anyhow!("usage: exact_rays <scene.json> [side]"))?;
    let side: u32 = args.get(2).map_or(Ok(16), |s| s.parse())?;
    anyhow::ensure!((1..=MAX_SIDE).contains(&side), "side: must be in 1..={MAX_SIDE}, got {side}");
    let scene = Scene::load(std::path::Path::new(path))?;
    let gpu = Gpu::new()?;
    let mut renderer = Renderer::new(&gpu, &scene)?;
    renderer.render_components(&gpu, Method::Sparse, side, side, Components::DIRECT)?;
    let vals = renderer.read_vals(&gpu)?;
    let hits = renderer.camera_view().ok_or_else(|| anyhow::anyhow!("no camera view"))?.read(&gpu)?;
    let flat = &renderer.scene.flat;
    let eye = renderer.view().eye();
    let rays: Vec<(Vec3, Vec3)> = hits
        .iter()
        .flatten()
        .flat_map(|h| {
            let (p, n, s) = flat.surface_at(h.triangle, h.barycentrics);
            let r = Receiver::new(p, n, s, eye);
            vals.iter()
                .filter(move |v| val_radiance(r.position, r.normal, &r.surface, r.view, v, true) != Vec3::ZERO)
                .map(move |v| (r.position + r.normal * RAY_OFFSET, v.position + v.normal * RAY_OFFSET))
        })
        .collect();
    let positions: Vec<Vec3> = flat.vertices.iter().map(|v| v.position.into()).collect();
    let triangles: Vec<[u32; 3]> = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();

    // Before: obvhs's BVH2 (medium_build, leaves collapsed) and its any-hit traversal.
    let start = Instant::now();
    let tris: Vec<obvhs::triangle::Triangle> = triangles
        .iter()
        .map(|t| {
            let [v0, v1, v2] = t.map(|i| Vec3A::from(positions[i as usize]));
            obvhs::triangle::Triangle { v0, v1, v2 }
        })
        .collect();
    let bvh2 = obvhs::bvh2::builder::build_bvh2_from_tris(
        &tris,
        obvhs::BvhBuildParams::medium_build(),
        &mut Default::default(),
    );
    let corners: Vec<[Vec3; 3]> =
        bvh2.primitive_indices.iter().map(|&i| triangles[i as usize].map(|v| positions[v as usize])).collect();
    let bvh2_build_ms = start.elapsed().as_secs_f64() * 1e3;
    let bvh2_blocked = |o: Vec3, t: Vec3| {
        let d = t - o;
        let ray = obvhs::ray::Ray::new(o.into(), d.into(), 0.0, 1.0);
        !bvh2.ray_traverse_miss(ray, |_, k| {
            let [a, b, c] = corners[k];
            match ray_triangle(o, d, a, b, c) {
                Some(t) if t > 0.0 && t < 1.0 => t,
                _ => f32::INFINITY,
            }
        })
    };
    // After: the CWBVH.
    let start = Instant::now();
    let wide = TraceBvh::build(&positions, &triangles);
    let cwbvh_build_ms = start.elapsed().as_secs_f64() * 1e3;

    let time = |f: &(dyn Fn(Vec3, Vec3) -> bool + Sync)| {
        let start = Instant::now();
        let blocked: Vec<bool> = rays.par_iter().map(|&(o, t)| f(o, t)).collect();
        (blocked, start.elapsed().as_secs_f64())
    };
    let (before, before_s) = time(&bvh2_blocked);
    let (after, after_s) = time(&|o, t| wide.segment_blocked(o, t));
    let differ = before.iter().zip(&after).filter(|(a, b)| a != b).count();
    let n = rays.len() as f64;
    println!(
        "{path} at {side}x{side}: {} VALs, {} triangles, {} shadow rays ({:.1} % blocked), {} rayon threads",
        vals.len(),
        triangles.len(),
        rays.len(),
        100.0 * after.iter().filter(|b| **b).count() as f64 / n,
        rayon::current_num_threads()
    );
    println!("before (obvhs BVH2, any-hit):    {:8.3} M rays/s (build {bvh2_build_ms:.0} ms)", n / before_s * 1e-6);
    println!("after  (obvhs CWBVH, first hit): {:8.3} M rays/s (build {cwbvh_build_ms:.0} ms)", n / after_s * 1e-6);
    println!("speed-up {:.2}x; rays decided differently: {differ}", before_s / after_s);
    anyhow::ensure!(differ == 0, "{differ} rays decided differently");
    Ok(())
}
