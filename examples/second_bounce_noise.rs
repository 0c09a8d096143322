//! The second bounce's own noise (`settings.bounces: 2`): the brute force of a scene rendered
//! with its bounce points placed from `seeds` different seeds (`settings.seed`; the brute force
//! does not use the sparse points the seed also places), each an independent draw of the
//! second bounce, against one bounce. Prints the second bounce's share of the indirect light
//! and the relative RMSE between draws, divided by √2: the noise one draw adds to the image
//! (relative to the two-bounce image), which is also the noise in the two-bounce references.
//!
//! `cargo run --release --example second_bounce_noise -- fixtures/scenes/<scene> [side] [seeds]`

use relume::gpu::Gpu;
use relume::image::{LinearImage, relative_rmse};
use relume::renderer::{Components, Method, Renderer};
use relume::scene::Scene;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).ok_or_else(|| anyhow::anyhow!("usage: second_bounce_noise <scene.json> [side] [seeds]"))?;
    let side: u32 = args.get(2).map_or(Ok(64), |s| s.parse())?;
    let seeds: u64 = args.get(3).map_or(Ok(4), |s| s.parse())?;
    anyhow::ensure!(seeds >= 2, "seeds: at least 2");
    let gpu = Gpu::new()?;
    let base = Scene::load(std::path::Path::new(path))?;
    let render = |bounces: u32, seed: u64| -> anyhow::Result<(LinearImage, f64)> {
        let mut scene = base.clone();
        scene.settings.bounces = bounces;
        scene.settings.seed = seed;
        let mut renderer = Renderer::new(&gpu, &scene)?;
        let frame = renderer.render_components(&gpu, Method::BruteForce, side, side, Components::INDIRECT)?;
        let bounce_ms = frame.timings.total_of(&renderer.bounce_stages());
        Ok((frame.indirect, bounce_ms))
    };
    let (one, _) = render(1, base.settings.seed)?;
    let one_sum = one.luminance_sum_and_peak().0;
    let mut images = Vec::new();
    for seed in 1..=seeds {
        let (image, ms) = render(2, seed)?;
        let share = 1.0 - one_sum / image.luminance_sum_and_peak().0;
        println!("seed {seed}: second bounce {:.1} % of the indirect light; its stages {ms:.0} ms", 100.0 * share);
        images.push(image);
    }
    let mut pairs = Vec::new();
    for i in 0..images.len() {
        for j in i + 1..images.len() {
            pairs.push(relative_rmse(&images[i], &images[j]) / std::f64::consts::SQRT_2);
        }
    }
    let mean = pairs.iter().sum::<f64>() / pairs.len() as f64;
    let (lo, hi) = pairs.iter().fold((f64::MAX, 0.0f64), |(lo, hi), &p| (lo.min(p), hi.max(p)));
    println!(
        "{side}x{side}: one draw's noise, rel RMSE between draws / sqrt 2: mean {mean:.4} ({lo:.4}..{hi:.4}) over {} pairs",
        pairs.len()
    );
    Ok(())
}
