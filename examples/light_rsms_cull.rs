//! The cull of the lights' RSM views (docs/measurements/many-lights.md "VALs from every light's RSM"), side by side in
//! one run: indirect-only sparse frames with the cull off and on, alternated (off, on, off, on,
//! ...) so the shared machine's load falls on both alike; per setting the median wall time of
//! `lights_rsm_raster` and of the gather, the triangles drawn over all views and the views
//! drawn; and whether both gave the same VALs (sorted, compared bit for bit). Then the same
//! for the direct light's shadow maps (`ManyLights::draws`): direct-only frames with their cull
//! off, the hemisphere cull on, and with it the groups whose lights are all out of the camera's
//! view skipped (`ManyLights::groups_in_view`), alternated, the median `lights_shadow_maps`
//! time, the triangles drawn, and whether the direct images are the same bit for bit.
//!
//! ```sh
//! cargo run --release --example light_rsms_cull -- fixtures/scenes/sponza_lights.json 128 72 3
//! ```

use relume::gpu::Gpu;
use relume::gpu::lights::light_rsms::RASTER_STAGE;
use relume::renderer::{Components, Method, Renderer};
use relume::scene::Scene;
use relume::twin::Val;

fn stage_ms(frame: &relume::renderer::Rendered, name: &str) -> f64 {
    frame.timings.stages.iter().find(|(n, _)| n == name).map_or(0.0, |(_, ms)| *ms)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The VALs as sortable bit patterns (the GPU appends them in any order).
fn sorted_bits(vals: &[Val]) -> Vec<[u32; 10]> {
    let mut bits: Vec<[u32; 10]> = vals
        .iter()
        .map(|v| {
            let f = [v.position, v.normal, v.flux].map(|x| x.to_array().map(f32::to_bits));
            [f[0][0], f[0][1], f[0][2], f[1][0], f[1][1], f[1][2], v.area.to_bits(), f[2][0], f[2][1], f[2][2]]
        })
        .collect();
    bits.sort_unstable();
    bits
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: light_rsms_cull <scene.json> [width] [height] [frames per setting]";
    let path = args.get(1).ok_or_else(|| anyhow::anyhow!(usage))?;
    let width: u32 = args.get(2).map_or(Ok(128), |s| s.parse())?;
    let height: u32 = args.get(3).map_or(Ok(72), |s| s.parse())?;
    let frames: usize = args.get(4).map_or(Ok(3), |s| s.parse())?;
    anyhow::ensure!((1..=1024).contains(&width) && (1..=1024).contains(&height), "sides: 1..=1024");
    anyhow::ensure!((1..=20).contains(&frames), "frames per setting: 1..=20");
    let scene = Scene::load(std::path::Path::new(path))?;
    anyhow::ensure!(!scene.lights.is_empty(), "{path}: the scene has no `lights`");
    let gpu = Gpu::new()?;
    let mut renderer = Renderer::new(&gpu, &scene)?;
    // Warm-up frame (pipelines, first uploads), not counted.
    renderer.render_components(&gpu, Method::Sparse, width, height, Components::INDIRECT)?;
    let mut raster = [Vec::new(), Vec::new()];
    let mut gather = [Vec::new(), Vec::new()];
    let mut vals: [Vec<[u32; 10]>; 2] = [Vec::new(), Vec::new()];
    let mut drawn = [(0u64, 0usize); 2];
    let mut cull_ms = [Vec::new(), Vec::new()];
    for _ in 0..frames {
        for (s, culling) in [false, true].into_iter().enumerate() {
            let rsms = renderer.light_rsms_mut().ok_or_else(|| anyhow::anyhow!("no light emits anything"))?;
            rsms.set_culling(culling);
            let frame = renderer.render_components(&gpu, Method::Sparse, width, height, Components::INDIRECT)?;
            raster[s].push(stage_ms(&frame, RASTER_STAGE));
            gather[s].push(stage_ms(&frame, relume::renderer::stage::GATHER));
            vals[s] = sorted_bits(&renderer.read_vals(&gpu)?);
            let rsms = renderer.light_rsms().expect("checked above");
            let start = std::time::Instant::now();
            let draws = rsms.draws(&renderer.scene, &rsms.raw_views(&renderer.scene));
            cull_ms[s].push(start.elapsed().as_secs_f64() * 1e3);
            let triangles: u64 = draws.iter().flatten().map(|r| (r.end - r.start) as u64).sum();
            drawn[s] = (triangles, draws.iter().filter(|d| !d.is_empty()).count());
        }
    }
    let views = renderer.light_rsms().expect("checked above").views.len();
    println!("{path}, {width}x{height}, {frames} frames per setting, alternated; {views} views");
    println!(
        "\n| cull | triangles drawn (all views) | views drawn | CPU cull ms | `{RASTER_STAGE}` ms (median) | gather ms (median) |"
    );
    println!("|---|---|---|---|---|---|");
    for (s, name) in ["off", "on"].iter().enumerate() {
        println!(
            "| {name} | {} | {} | {:.1} | {:.0} | {:.0} |",
            drawn[s].0,
            drawn[s].1,
            median(cull_ms[s].clone()),
            median(raster[s].clone()),
            median(gather[s].clone())
        );
    }
    // What the chunk size buys: triangles the cull keeps at other sizes (1: each triangle alone).
    let rsms = renderer.light_rsms().expect("checked above");
    let raw = rsms.raw_views(&renderer.scene);
    print!("\ntriangles kept by chunk size:");
    for chunk in [1, 4, relume::gpu::raster::cull::CHUNK_TRIANGLES, 64, 256] {
        let chunks = relume::gpu::raster::cull::TriangleChunks::with_chunk(&renderer.scene.flat, chunk);
        let kept: u64 = rsms
            .views
            .iter()
            .zip(&raw)
            .flat_map(|(p, r)| {
                let sphere = p.view.range.map(|range| (p.view.frame.position, range));
                chunks.visible(glam::Mat4::from_cols_array_2d(&r.world_to_clip), sphere)
            })
            .map(|r| (r.end - r.start) as u64)
            .sum();
        print!(" {chunk}: {kept} ({:.3});", kept as f64 / drawn[0].0 as f64);
    }
    println!();
    let ratio = median(raster[1].clone()) / median(raster[0].clone());
    println!("\nraster on / off: {ratio:.3}; triangles on / off: {:.3}", drawn[1].0 as f64 / drawn[0].0 as f64);
    println!("VALs: {} off, {} on, identical bit for bit: {}", vals[0].len(), vals[1].len(), vals[0] == vals[1]);

    // The maps' cull off, the hemisphere cull alone, and with it the lights out of view
    // (`ManyLights::groups_in_view`).
    let states = [(false, false, "off"), (true, false, "hemisphere"), (true, true, "hemisphere + lights out of view")];
    let mut maps_ms = vec![Vec::new(); states.len()];
    let mut images = vec![Vec::new(); states.len()];
    let mut map_draws = vec![0u64; states.len()];
    for _ in 0..frames {
        for (s, &(culling, light_culling, _)) in states.iter().enumerate() {
            let many = renderer.many_lights_mut().ok_or_else(|| anyhow::anyhow!("no many-light direct"))?;
            many.set_culling(culling);
            many.set_light_culling(light_culling);
            let frame = renderer.render_components(&gpu, Method::Sparse, width, height, Components::DIRECT)?;
            maps_ms[s].push(stage_ms(&frame, relume::gpu::lights::many::SHADOW_MAPS_STAGE));
            images[s] = frame.direct.pixels.clone();
            let many = renderer.many_lights().expect("checked above");
            let seen = many.groups_in_view(renderer.camera_to_clip(width, height));
            map_draws[s] = many
                .draws(&renderer.scene)
                .iter()
                .enumerate()
                .filter(|(k, _)| !light_culling || seen[k / 2])
                .flat_map(|(_, r)| r)
                .map(|r| (r.end - r.start) as u64)
                .sum();
        }
    }
    let many = renderer.many_lights().expect("checked above");
    let groups = many.groups.len();
    let in_view = many.groups_in_view(renderer.camera_to_clip(width, height)).iter().filter(|s| **s).count();
    println!("\n{in_view} of {groups} groups have a light in view");
    println!("\n| maps' cull | triangles drawn ({} maps) | `lights_shadow_maps` ms (median) |", 2 * groups);
    println!("|---|---|---|");
    for (s, (_, _, name)) in states.iter().enumerate() {
        println!("| {name} | {} | {:.0} |", map_draws[s], median(maps_ms[s].clone()));
    }
    let peak = images[0].iter().map(|p| p[0].max(p[1]).max(p[2])).fold(0.0f32, f32::max);
    for s in 1..states.len() {
        let differ: Vec<f32> = images[0]
            .iter()
            .zip(&images[s])
            .filter(|(a, b)| a != b)
            .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max) / peak)
            .collect();
        println!(
            "{}: direct pixels that differ from off: {} of {}, largest difference {:.2e} of the peak",
            states[s].2,
            differ.len(),
            images[0].len(),
            differ.iter().copied().fold(0.0f32, f32::max)
        );
        println!(
            "{}: maps / off: {:.3}; triangles / off: {:.3}; direct image identical bit for bit: {}",
            states[s].2,
            median(maps_ms[s].clone()) / median(maps_ms[0].clone()),
            map_draws[s] as f64 / map_draws[0] as f64,
            images[0] == images[s]
        );
    }
    Ok(())
}
