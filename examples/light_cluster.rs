//! LightCluster (paper 003) against one shadow map per light and exact shadow rays, swept over
//! `d_init` (the paper's Fig. 6 and Table 1), as a benchmark that prints its figures: the
//! scene's `lights` are rendered direct-only at a small size
//!
//! - with `settings.direct.shadows: "per_light"` (two paraboloid maps per light, one texel
//!   each: the shadow-map baseline whose time LightCluster is measured against);
//! - with `"light_cluster"` at each `d_init` given (PCSS per group);
//!
//! and compared with the CPU reference, one shadow ray per pixel and light through the scene's
//! BVH (`twin::many_lights::exact_image`; deterministic, so its noise is 0), and with the
//! `per_light` image (the paper's own reference: a shadow map per light). "too lit" is the share
//! of the squared error against exact where the image is brighter than exact. Times are the GPU
//! stages `lights_shadow_maps` + `lights_direct`, the median of `runs` frames each, all in this
//! one run; the clustering (CPU, once per frame in the paper) is timed separately.
//!
//! ```sh
//! cargo run --release --example light_cluster -- fixtures/scenes/sponza_lights.json 128 72 1,2,3,4,6,8,12
//! ```

use relume::gpu::Gpu;
use relume::gpu::lights::many::{SHADE_STAGE, SHADOW_MAPS_STAGE, groups_of};
use relume::image::{LinearImage, relative_rmse};
use relume::renderer::{Components, Method, Renderer};
use relume::scene::{DirectSettings, DirectShadows, Scene};
use relume::twin::many_lights::exact_image;
use std::time::Instant;

/// Frames timed per configuration (the median is printed).
const RUNS: usize = 3;
const MAX_SIDE: u32 = 512;

/// The share of the squared error (against `reference`) where `test` is brighter: light that
/// leaks through the maps or a group's too-wide penumbra, as opposed to shadow where there is none.
fn too_lit(test: &LinearImage, reference: &LinearImage) -> f64 {
    let (mut bright, mut all) = (0.0f64, 0.0f64);
    for i in 0..reference.pixels.len() {
        if reference.covered(i) {
            let d = test.rgb(i) - reference.rgb(i);
            let e = d.length_squared() as f64;
            all += e;
            if d.element_sum() > 0.0 {
                bright += e;
            }
        }
    }
    if all > 0.0 { bright / all } else { 0.0 }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: light_cluster <scene.json> [width] [height] [d_init,d_init,...] [png_dir]";
    let path = args.get(1).ok_or_else(|| anyhow::anyhow!(usage))?;
    let width: u32 = args.get(2).map_or(Ok(128), |s| s.parse())?;
    let height: u32 = args.get(3).map_or(Ok(72), |s| s.parse())?;
    let d_inits: Vec<f32> = match args.get(4) {
        Some(list) => list.split(',').map(str::parse).collect::<Result<_, _>>()?,
        None => vec![0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0],
    };
    let png_dir = args.get(5).map(std::path::PathBuf::from);
    anyhow::ensure!((1..=MAX_SIDE).contains(&width) && (1..=MAX_SIDE).contains(&height), "sides: 1..={MAX_SIDE}");
    let scene = Scene::load(std::path::Path::new(path))?;
    anyhow::ensure!(!scene.lights.is_empty(), "{path}: the scene has no `lights`");
    anyhow::ensure!(scene.light.is_none(), "{path}: measure `lights` alone (the scene has a `light` too)");
    let gpu = Gpu::new()?;
    let mut renderer = Renderer::new(&gpu, &scene)?;
    let base = scene.settings.direct;

    let frame = |renderer: &mut Renderer, settings: &DirectSettings| -> anyhow::Result<(LinearImage, f64)> {
        renderer.set_direct_settings(&gpu, settings)?;
        let mut times = Vec::new();
        let mut image = None;
        for _ in 0..RUNS {
            let r = renderer.render_components(&gpu, Method::Sparse, width, height, Components::DIRECT)?;
            times.push(r.timings.total_of(&[SHADOW_MAPS_STAGE, SHADE_STAGE]));
            image = Some(r.direct);
        }
        times.sort_by(f64::total_cmp);
        Ok((image.expect("RUNS > 0"), times[RUNS / 2]))
    };

    let per_light = DirectSettings { shadows: DirectShadows::PerLight, ..base };
    let (per_light_image, per_light_ms) = frame(&mut renderer, &per_light)?;
    let hits = renderer.camera_view().expect("a frame was rendered").read(&gpu)?;
    let eye = renderer.view().eye();
    let start = Instant::now();
    let exact = exact_image(&renderer.scene.flat, &hits, (width, height), eye, &scene.lights);
    let exact_s = start.elapsed().as_secs_f64();
    let exposure = exact.auto_exposure();
    let save = |name: &str, image: &LinearImage| -> anyhow::Result<()> {
        if let Some(dir) = &png_dir {
            std::fs::create_dir_all(dir)?;
            image.write_png(&dir.join(format!("{name}.png")), exposure)?;
        }
        Ok(())
    };
    save("exact", &exact)?;
    save("per_light", &per_light_image)?;

    println!(
        "{path}: {} lights, {width}x{height}, maps {}² (two per group), {} on {}",
        scene.lights.len(),
        base.shadow_map_resolution,
        if gpu.timestamps { "GPU timestamps" } else { "wall time per stage" },
        gpu.adapter_name()
    );
    println!("reference: one CPU shadow ray per pixel and light (noise 0), {exact_s:.2} s");
    println!(
        "{:<18} {:>6} {:>14} {:>8} {:>16} {:>10} {:>8} {:>13}",
        "shadows", "groups", "rRMSE vs exact", "too lit", "rRMSE vs per_lt", "time ms", "ratio", "clustering ms"
    );
    let row = |name: &str, groups: usize, image: &LinearImage, ms: f64, clustering: &str| {
        println!(
            "{name:<18} {groups:>6} {:>14.4} {:>8.3} {:>16.4} {ms:>10.1} {:>8.3} {clustering:>13}",
            relative_rmse(image, &exact),
            too_lit(image, &exact),
            relative_rmse(image, &per_light_image),
            ms / per_light_ms,
        );
    };
    row("per_light", scene.lights.len(), &per_light_image, per_light_ms, "-");
    for d_init in d_inits {
        let settings = DirectSettings { shadows: DirectShadows::LightCluster, d_init, ..base };
        settings.validate("d_init")?;
        let start = Instant::now();
        let groups = groups_of(&scene.lights, &settings, scene.camera.position);
        let clustering_ms = start.elapsed().as_secs_f64() * 1e3;
        let (image, ms) = frame(&mut renderer, &settings)?;
        save(&format!("light_cluster_{d_init}"), &image)?;
        row(&format!("light_cluster {d_init}"), groups.len(), &image, ms, &format!("{clustering_ms:.3}"));
    }
    Ok(())
}
