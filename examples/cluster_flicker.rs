//! Temporal stability of the clusters visibility mode, as a benchmark that prints its
//! figures: the spot light moves sideways by 1 % of the scene's bounding radius per frame, and
//! every frame's indirect image is rendered three ways at a small size:
//!
//! - **coherent**: the clusters mode on one renderer for the whole sequence, so each frame's
//!   k-means starts from the last frame's centres (what relume does);
//! - **reseeded**: a new renderer each frame, so k-means starts from its seeds every frame;
//! - **exact**: the CPU exact reference with every VAL (noise 0).
//!
//! It prints, for each, the mean frame-to-frame change of the image `Σ|I_t − I_{t−1}| /
//! Σ|I_{t−1}|` (pixels covered in both), and for the two cluster variants the change of their
//! error against exact (`Σ|e_t − e_{t−1}| / Σ|X_{t−1}|`, `e = I − X`: flicker that is the
//! method's, not the light's) and their mean rel RMSE against exact. The target: the
//! coherent image changes at most 1.5× as much as exact's.
//!
//! ```sh
//! cargo run --release --example cluster_flicker -- fixtures/scenes/cornell_bunny_small.json 30 48
//! ```

use glam::Vec3;
use relume::bench::compare::{ExactOptions, ReferenceDevice, exact_reference};
use relume::bench::temporal::image_change;
use relume::gpu::Gpu;
use relume::image::{LinearImage, relative_rmse};
use relume::renderer::{Method, Renderer};
use relume::scene::{Occlusion, Scene};

/// Frames and image side at most (the exact reference costs pixels x VALs shadow rays a frame).
const MAX_FRAMES: u32 = 120;
const MAX_SIDE: u32 = 128;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).ok_or_else(|| anyhow::anyhow!("usage: cluster_flicker <scene.json> [frames] [side]"))?;
    let frames: u32 = args.get(2).map_or(Ok(30), |s| s.parse())?;
    let side: u32 = args.get(3).map_or(Ok(48), |s| s.parse())?;
    anyhow::ensure!((2..=MAX_FRAMES).contains(&frames), "frames: must be in 2..={MAX_FRAMES}, got {frames}");
    anyhow::ensure!((1..=MAX_SIDE).contains(&side), "side: must be in 1..={MAX_SIDE}, got {side}");
    let mut scene = Scene::load(std::path::Path::new(path))?;
    scene.settings.visibility.mode = Occlusion::Clusters;
    let light = scene.light.ok_or_else(|| anyhow::anyhow!("{path}: the scene has no spot light to move"))?;
    let gpu = Gpu::new()?;
    let mut coherent = Renderer::new(&gpu, &scene)?;
    let mut exact_renderer = Renderer::new(&gpu, &scene)?;
    let (_, radius) = coherent.scene.flat.bounding_sphere();
    let step = 0.01 * radius;
    let side_dir = light.direction.cross(Vec3::Y).try_normalize().unwrap_or(Vec3::X);
    let options = ExactOptions::every_val(ReferenceDevice::Cpu);
    let (mut kept, mut reseeded, mut exact) = (Vec::new(), Vec::new(), Vec::new());
    for t in 0..frames {
        let mut l = light;
        l.position += side_dir * step * t as f32;
        coherent.set_spot_light(&l);
        kept.push(coherent.render(&gpu, Method::Sparse, side, side)?.indirect);
        let mut fresh = Renderer::new(&gpu, &scene)?;
        fresh.set_spot_light(&l);
        reseeded.push(fresh.render(&gpu, Method::Sparse, side, side)?.indirect);
        exact_renderer.set_spot_light(&l);
        exact.push(exact_reference(&gpu, &mut exact_renderer, side, side, &options)?.indirect().clone());
        eprint!("\rframe {}/{frames}", t + 1);
    }
    eprintln!();
    let mean_change = |images: &[LinearImage]| {
        images.windows(2).map(|w| image_change(&w[0], &w[1])).sum::<f64>() / (images.len() - 1) as f64
    };
    // Σ|e_t − e_{t−1}| / Σ|X_{t−1}| over pixels covered in all four images, e = I − X.
    let error_change = |images: &[LinearImage]| {
        let mut sum = 0.0;
        for t in 1..images.len() {
            let (i0, i1, x0, x1) = (&images[t - 1], &images[t], &exact[t - 1], &exact[t]);
            let (mut num, mut den) = (0.0f64, 0.0f64);
            for p in 0..x0.pixels.len() {
                if i0.covered(p) && i1.covered(p) && x0.covered(p) && x1.covered(p) {
                    let (e0, e1) = (i0.rgb(p) - x0.rgb(p), i1.rgb(p) - x1.rgb(p));
                    num += (e1 - e0).abs().element_sum() as f64;
                    den += x0.rgb(p).abs().element_sum() as f64;
                }
            }
            sum += if den > 0.0 { num / den } else { 0.0 };
        }
        sum / (images.len() - 1) as f64
    };
    let mean_rmse = |images: &[LinearImage]| {
        images.iter().zip(&exact).map(|(i, x)| relative_rmse(i, x)).sum::<f64>() / images.len() as f64
    };
    let exact_change = mean_change(&exact);
    println!(
        "{path}: {frames} frames at {side}x{side}, the spot light {step:.4} m sideways a frame, clusters {:?}",
        scene.settings.visibility.clusters
    );
    println!("exact (every VAL):       image change {exact_change:.4}");
    for (name, images) in [("coherent (relume)", &kept), ("reseeded each frame", &reseeded)] {
        let change = mean_change(images);
        println!(
            "{name:<24} image change {change:.4} ({:.2}x exact's), error change {:.4}, rel RMSE vs exact {:.4}",
            change / exact_change.max(f64::MIN_POSITIVE),
            error_change(images),
            mean_rmse(images)
        );
    }
    Ok(())
}
