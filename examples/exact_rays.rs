//! Shadow-ray throughput of the CPU exact reference's traversal, before and after, in one run,
//! on the same shadow rays: every pixel-VAL pair with a non-zero unoccluded term of a real frame,
//! as the reference casts them (per receiver, in the reference's VAL order).
//!
//! - before: obvhs's CWBVH from its `medium_build` preset, one ray at a time, VALs in the RSM's
//!   order (what `twin::exact_cpu` did before the packets);
//! - single: [`TraceBvh`] (`very_slow_build`), [`TraceBvh::shadow_rays`] one ray at a time with
//!   the last blocker tested first, VALs along the Morton curve;
//! - packets: the same with [`ShadowTraversal::Packets`].
//!
//! Every path decides each ray with the same triangle test; a ray decided differently from
//! `before` is reported (and makes the run fail).
//!
//! ```sh
//! cargo run --release --example exact_rays -- fixtures/scenes/cornell_bunny.json 32
//! ```

use glam::Vec3;
use rayon::prelude::*;
use relume::gpu::Gpu;
use relume::gpu::shader::RAY_OFFSET;
use relume::renderer::{Components, Method, Renderer};
use relume::scene::Scene;
use relume::twin::bvh::{ShadowTraversal, TraceBvh};
use relume::twin::exact_cpu::{Receiver, sort_along_curve};
use relume::twin::val_radiance;
use std::time::Instant;

/// One receiver's shadow rays: the ray origin and the targets.
type Rays = (Vec3, Vec<Vec3>);

/// Image side at most: the rays are stored (24 bytes each), ~10 k per pixel on cornell_bunny.
const MAX_SIDE: u32 = 48;

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
    let mut curve = vals.clone();
    sort_along_curve(&mut curve);
    let hits = renderer.camera_view().ok_or_else(|| anyhow::anyhow!("no camera view"))?.read(&gpu)?;
    let flat = &renderer.scene.flat;
    let eye = renderer.view().eye();
    // One receiver's shadow rays: its ray origin and the targets of the VALs it sees unoccluded.
    let receivers: Vec<Receiver> = hits
        .iter()
        .flatten()
        .map(|h| {
            let (p, n, s) = flat.surface_at(h.triangle, h.barycentrics);
            Receiver::new(p, n, s, eye)
        })
        .collect();
    let rays_of = |r: &Receiver, vals: &[relume::twin::Val]| -> Rays {
        let targets = vals
            .iter()
            .filter(|v| val_radiance(r.position, r.normal, &r.surface, r.view, v, true) != Vec3::ZERO)
            .map(|v| v.position + v.normal * RAY_OFFSET)
            .collect();
        (r.position + r.normal * RAY_OFFSET, targets)
    };
    let in_rsm_order: Vec<Rays> = receivers.iter().map(|r| rays_of(r, &vals)).collect();
    let along_curve: Vec<Rays> = receivers.iter().map(|r| rays_of(r, &curve)).collect();
    let positions: Vec<Vec3> = flat.vertices.iter().map(|v| v.position.into()).collect();
    let triangles: Vec<[u32; 3]> = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();

    // Before: obvhs's CWBVH (medium_build), one ray at a time.
    let start = Instant::now();
    let medium = TraceBvh::build_with(&positions, &triangles, obvhs::BvhBuildParams::medium_build());
    let medium_build_ms = start.elapsed().as_secs_f64() * 1e3;
    let before_blocked = |o: Vec3, t: Vec3| medium.segment_blocked(o, t);
    let start = Instant::now();
    let wide = &TraceBvh::build(&positions, &triangles);
    let build_ms = start.elapsed().as_secs_f64() * 1e3;

    // Per receiver, how many of its rays are blocked: the rays' order differs between the two
    // VAL orders, the count per receiver does not.
    let time = |f: &(dyn Fn(&Rays) -> Vec<bool> + Sync), rays: &[Rays]| {
        let start = Instant::now();
        let blocked: Vec<Vec<bool>> = rays.par_iter().map(f).collect();
        (blocked, start.elapsed().as_secs_f64())
    };
    let (before, before_s) = time(&|(o, ts)| ts.iter().map(|t| before_blocked(*o, *t)).collect(), &in_rsm_order);
    let traced = |traversal| {
        move |(o, ts): &Rays| {
            let mut blocked = Vec::new();
            wide.shadow_rays(*o, ts, traversal, &mut blocked);
            blocked
        }
    };
    let (single, single_s) = time(&traced(ShadowTraversal::Single), &along_curve);
    let (packets, packets_s) = time(&traced(ShadowTraversal::Packets), &along_curve);
    // Ray by ray against `before` on the curve order (same rays, same order).
    let (curve_before, _) = time(&|(o, ts)| ts.iter().map(|t| before_blocked(*o, *t)).collect(), &along_curve);
    let differ = |a: &[Vec<bool>], b: &[Vec<bool>]| {
        a.iter().zip(b).map(|(x, y)| x.iter().zip(y).filter(|(p, q)| p != q).count()).sum::<usize>()
    };
    let count = |v: &[Vec<bool>]| v.iter().map(|r| r.iter().filter(|b| **b).count()).collect::<Vec<_>>();
    anyhow::ensure!(count(&before) == count(&curve_before), "the VAL order changed which rays are blocked");
    let (single_differ, packets_differ) = (differ(&curve_before, &single), differ(&curve_before, &packets));
    let n = in_rsm_order.iter().map(|(_, t)| t.len()).sum::<usize>() as f64;
    let blocked = count(&before).iter().sum::<usize>() as f64;
    println!(
        "{path} at {side}x{side}: {} VALs, {} triangles, {} shadow rays ({:.1} % blocked), {} rayon threads",
        vals.len(),
        triangles.len(),
        n,
        100.0 * blocked / n,
        rayon::current_num_threads()
    );
    let rate = |s: f64| n / s * 1e-6;
    println!(
        "before  (CWBVH medium_build, one ray, RSM order): {:8.3} M rays/s (build {medium_build_ms:.0} ms)",
        rate(before_s)
    );
    println!(
        "single  (very_slow_build, last blocker, curve):    {:8.3} M rays/s (build {build_ms:.0} ms), {:.2}x, {single_differ} rays decided differently",
        rate(single_s),
        before_s / single_s
    );
    println!(
        "packets (very_slow_build, packets, curve):        {:8.3} M rays/s, {:.2}x, {packets_differ} rays decided differently",
        rate(packets_s),
        before_s / packets_s
    );
    anyhow::ensure!(single_differ == 0 && packets_differ == 0, "rays decided differently");
    Ok(())
}
