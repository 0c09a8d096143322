//! How `settings.direct.val_budget` is split among a scene's `lights` (README "Many direct
//! lights"): per light its emitted flux, share of the budget, RSM resolution, texels and the
//! VALs it made this frame (its texels that see a surface with flux, counted by the twin on the
//! GPU's own atlas), against the frame's VAL count; and the stage times of one sparse frame.
//!
//! ```sh
//! cargo run --release --example light_rsms -- fixtures/scenes/sponza_lights.json 128 72
//! ```

use relume::gpu::Gpu;
use relume::renderer::{Method, Renderer};
use relume::scene::Scene;
use relume::twin::light_rsms::{emitted_flux, view_texel_val};
use relume::twin::rsm::rsm_texel_ndc;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).ok_or_else(|| anyhow::anyhow!("usage: light_rsms <scene.json> [width] [height]"))?;
    let width: u32 = args.get(2).map_or(Ok(128), |s| s.parse())?;
    let height: u32 = args.get(3).map_or(Ok(72), |s| s.parse())?;
    anyhow::ensure!((1..=1024).contains(&width) && (1..=1024).contains(&height), "sides: 1..=1024");
    let scene = Scene::load(std::path::Path::new(path))?;
    anyhow::ensure!(!scene.lights.is_empty(), "{path}: the scene has no `lights`");
    let gpu = Gpu::new()?;
    let mut renderer = Renderer::new(&gpu, &scene)?;
    let frame = renderer.render(&gpu, Method::Sparse, width, height)?;
    let rsms = renderer.light_rsms().ok_or_else(|| anyhow::anyhow!("no light emits anything"))?;
    let atlas = rsms.read_atlas(&gpu)?;
    let flat = &renderer.scene.flat;
    let mut vals = vec![0u32; scene.lights.len()];
    for placed in &rsms.views {
        let r = placed.view.resolution;
        for iy in 0..r {
            for ix in 0..r {
                let texel = ((placed.origin[1] + iy) * rsms.atlas_size[0] + placed.origin[0] + ix) as usize;
                if let Some(hit) = atlas[texel] {
                    let (y, n, m) = flat.surface_at(hit.triangle, hit.barycentrics);
                    if view_texel_val(rsm_texel_ndc(ix, iy, r), &placed.view, y, n, m.diffuse).flux.max_element() > 0.0
                    {
                        vals[placed.light as usize] += 1;
                    }
                }
            }
        }
    }
    let budget = scene.settings.direct.val_budget;
    let flux: Vec<f32> = scene.lights.iter().map(emitted_flux).collect();
    let total_flux: f32 = flux.iter().sum();
    println!("| light | kind | flux Y (W) | share of {budget} | R | texels | VALs |");
    println!("|---|---|---|---|---|---|---|");
    for (i, light) in scene.lights.iter().enumerate() {
        let (kind, views) = match light {
            relume::scene::Light::Point(_) => ("point", 6),
            relume::scene::Light::Spot(_) => ("spot", 1),
        };
        let r = rsms.resolutions[i];
        println!(
            "| {i} | {kind} | {:.3} | {:.1} | {r} | {} | {} |",
            flux[i],
            budget as f32 * flux[i] / total_flux,
            views * r * r,
            vals[i]
        );
    }
    let counted: u32 = vals.iter().sum();
    println!(
        "\ntexels {} (budget {budget}), VALs counted by the twin {counted}, frame's VALs {}, atlas {} x {}",
        rsms.texels, frame.val_count, rsms.atlas_size[0], rsms.atlas_size[1]
    );
    println!("\n| stage | ms |\n|---|---|");
    for (name, ms) in &frame.timings.stages {
        println!("| {name} | {ms:.1} |");
    }
    Ok(())
}
