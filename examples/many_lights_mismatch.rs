//! Where `settings.direct.shadows: "per_light"` disagrees with exact shadow rays (README "Many
//! direct lights"): for every covered pixel and light with direct radiance, whether the
//! per-light maps (the twin's lookup on the GPU's own maps) and the exact shadow ray say lit or
//! shadowed; the disagreements are weighted by the light's squared radiance (what the image's
//! rel RMSE weighs) and binned by the direction's cosine to the maps' axis (|cos| near 0: at a
//! paraboloid's rim) and by the distance from the light.
//!
//! ```sh
//! cargo run --release --example many_lights_mismatch -- fixtures/scenes/sponza_lights.json 128 72
//! ```

use glam::Vec3;
use relume::gpu::Gpu;
use relume::gpu::shader::RAY_OFFSET;
use relume::renderer::{Components, Method, Renderer};
use relume::scene::{Light, Scene, SoftShadows};
use relume::twin::bvh::TraceBvh;
use relume::twin::many_lights::*;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path =
        args.get(1).ok_or_else(|| anyhow::anyhow!("usage: many_lights_mismatch <scene.json> [width] [height]"))?;
    let width: u32 = args.get(2).map_or(Ok(128), |s| s.parse())?;
    let height: u32 = args.get(3).map_or(Ok(72), |s| s.parse())?;
    anyhow::ensure!((1..=512).contains(&width) && (1..=512).contains(&height), "sides: 1..=512");
    let scene = Scene::load(std::path::Path::new(path))?;
    let gpu = Gpu::new()?;
    let mut s2 = scene.clone();
    s2.settings.direct.shadows = relume::scene::DirectShadows::PerLight;
    let mut r = Renderer::new(&gpu, &s2)?;
    r.render_components(&gpu, Method::Sparse, width, height, Components::DIRECT)?;
    let many = r.many_lights().unwrap();
    let maps = many.read_maps(&gpu)?;
    let hits = r.camera_view().unwrap().read(&gpu)?;
    let eye = r.view().eye();
    let flat = &r.scene.flat;
    let positions: Vec<Vec3> = flat.vertices.iter().map(|v| v.position.into()).collect();
    let triangles: Vec<[u32; 3]> = flat.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    let bvh = TraceBvh::build(&positions, &triangles);
    let lp: Vec<Vec3> = scene.lights.iter().map(Light::position).collect();
    let clusters = many.groups.maps(&lp);
    // Per bin: [all, maps dark where exact is lit, maps lit where exact is dark], each the sum of
    // the light's squared radiance.
    let mut bins = [[0.0f64; 3]; 5];
    let mut dist_bins = [[0.0f64; 3]; 5];
    for h in hits.iter().flatten() {
        let (p, n, m) = flat.surface_at(h.triangle, h.barycentrics);
        for (i, l) in scene.lights.iter().enumerate() {
            let rad = light_radiance(p, n, &m, eye, l).element_sum() as f64;
            if rad <= 0.0 {
                continue;
            }
            let exact_lit = !bvh.segment_blocked(p + n * RAY_OFFSET, l.position());
            let v = group_visibility(&maps, many.map_resolution(), &clusters, i, p, n, SoftShadows::Hard);
            let off = p - l.position();
            let c = (off.dot(AXIS).abs() / off.length()).min(0.999);
            let b = (c * 5.0) as usize;
            let d = ((off.length() / 2.0) as usize).min(4);
            let k = if v < 0.5 && exact_lit {
                1
            } else if v >= 0.5 && !exact_lit {
                2
            } else {
                0
            };
            let e = rad * rad;
            bins[b][0] += e;
            dist_bins[d][0] += e;
            if k > 0 {
                bins[b][k] += e;
                dist_bins[d][k] += e;
            }
        }
    }
    println!("{path}: per_light maps {}² against exact shadow rays, {width}x{height}", many.map_resolution());
    println!("shares of the squared radiance: [weight, maps dark where exact is lit, maps lit where exact is dark]");
    println!("by |cos| of the direction to the maps' axis:");
    for (b, x) in bins.iter().enumerate() {
        println!(
            "{:.1}-{:.1}: {:.3e} {:.3} {:.3}",
            b as f32 / 5.0,
            (b + 1) as f32 / 5.0,
            x[0],
            x[1] / x[0].max(1e-30),
            x[2] / x[0].max(1e-30)
        );
    }
    println!("by distance from the light:");
    for (b, x) in dist_bins.iter().enumerate() {
        println!("{}-{} m: {:.3e} {:.3} {:.3}", 2 * b, 2 * b + 2, x[0], x[1] / x[0].max(1e-30), x[2] / x[0].max(1e-30));
    }
    Ok(())
}
