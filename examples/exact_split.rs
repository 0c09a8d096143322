//! What the exact reference itself depends on: the same scene's exact image (every VAL, a shadow
//! ray each, the CPU reference) with its VALs from a coarser spot-light RSM, or with the shadow
//! rays ignoring blockers near the receiver, each against the scene's own reference (the
//! `reference` level's VALs, every blocker).
//!
//! - `--rsm 16,32,64`: coarser VALs (fewer, each with more area and flux). How far a level's
//!   VALs alone put it from the reference, before any approximation of visibility.
//! - `--val-budget 256,1024,4096`: fewer VALs from the RSMs of the scene's `lights`
//!   (`settings.tuning.direct.val_budget`), the same question for a scene lit by many lights.
//! - `--blockers-from 0.2,1`: blockers nearer the receiver than this many metres let light
//!   through. Where the image changes is where occluders that close decide the light: what a
//!   shadow map seen from far away (texels of centimetres to decimetres) cannot resolve.
//!
//! For each variant: VALs, seconds, rel RMSE against the reference, the same without the worst
//! 1 % of pixels, the worst 1 %'s share of the squared error, the mean ratio. `--images DIR`
//! writes `reference.exr` and one EXR per variant.
//!
//!   cargo run --release --example exact_split -- <scene.json> [--rsm R,..] [--val-budget N,..] [--blockers-from M,..] [--images DIR]
use relume::bench::compare::{ExactOptions, ReferenceDevice, exact_reference, rel_rmse_without_worst};
use relume::image::{LinearImage, relative_rmse};
use relume::renderer::Renderer;
use relume::scene::{Quality, Scene};
use std::path::{Path, PathBuf};

fn list<T: std::str::FromStr>(args: &[String], flag: &str) -> Vec<T> {
    args.iter()
        .position(|a| a == flag)
        .and_then(|i| args.get(i + 1))
        .map(|v| v.split(',').map(|x| x.parse().unwrap_or_else(|_| panic!("{flag}: bad value {x}"))).collect())
        .unwrap_or_default()
}

/// The share of the squared error (summed over RGB) in the worst 1 % of covered pixels, and the
/// mean ratio as `relume compare` reports it (summed luminance over the reference's).
fn worst_share_and_ratio(test: &LinearImage, reference: &LinearImage) -> (f64, f64) {
    let mut errors: Vec<f64> = (0..reference.pixels.len())
        .filter(|&i| reference.covered(i))
        .map(|i| f64::from((test.rgb(i) - reference.rgb(i)).length_squared()))
        .collect();
    errors.sort_by(|a, b| b.total_cmp(a));
    let total: f64 = errors.iter().sum();
    let worst: f64 = errors[..errors.len().div_ceil(100)].iter().sum();
    let (sum, reference_sum) = (test.luminance_sum_and_peak().0, reference.luminance_sum_and_peak().0);
    (worst / total.max(f64::MIN_POSITIVE), sum / reference_sum)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect(
        "usage: exact_split <scene.json> [--rsm R,..] [--val-budget N,..] [--blockers-from M,..] [--images DIR]",
    );
    let rsms: Vec<u32> = list(&args, "--rsm");
    let budgets: Vec<u32> = list(&args, "--val-budget");
    let blockers: Vec<f32> = list(&args, "--blockers-from");
    let images: Option<PathBuf> = list::<String>(&args, "--images").first().map(PathBuf::from);
    let text = std::fs::read_to_string(path).unwrap();
    let base = Path::new(path).parent().unwrap();
    let gpu = relume::gpu::Gpu::new().unwrap();
    if let Some(dir) = &images {
        std::fs::create_dir_all(dir).unwrap();
    }
    // A change of the scene file's `settings.tuning` (none: the reference).
    let run = |tuning: Option<(&str, u32)>, blockers_from: f32| {
        let mut file: serde_json::Value = serde_json::from_str(&text).unwrap();
        match tuning {
            Some(("val_budget", n)) => file["settings"]["tuning"]["direct"]["val_budget"] = n.into(),
            Some((key, n)) => file["settings"]["tuning"][key] = n.into(),
            None => {}
        }
        let scene = Scene::from_json_str_at(&file.to_string(), base, Some(Quality::Reference)).unwrap();
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        let options = ExactOptions { blockers_from, ..ExactOptions::every_val(ReferenceDevice::Cpu) };
        let start = std::time::Instant::now();
        let exact = exact_reference(&gpu, &mut renderer, 256, 256, &options).unwrap();
        let seconds = start.elapsed().as_secs_f64();
        (exact.indirect().clone(), seconds, renderer.read_vals(&gpu).unwrap().len())
    };
    let (reference, seconds, vals) = run(None, 0.0);
    println!("{path} at 256x256: reference {vals} VALs, {seconds:.1} s");
    if let Some(dir) = &images {
        reference.write_exr(&dir.join("reference.exr")).unwrap();
    }
    let variants = rsms.iter().map(|&r| (format!("rsm {r}"), Some(("rsm_resolution", r)), 0.0));
    let variants = variants.chain(budgets.iter().map(|&n| (format!("val budget {n}"), Some(("val_budget", n)), 0.0)));
    let variants = variants.chain(blockers.iter().map(|&m| (format!("blockers from {m} m"), None, m)));
    for (name, tuning, blockers_from) in variants {
        let (image, seconds, vals) = run(tuning, blockers_from);
        let error = relative_rmse(&image, &reference);
        let without = rel_rmse_without_worst(&image, &reference, 0.01);
        let (share, ratio) = worst_share_and_ratio(&image, &reference);
        println!(
            "{name}: {vals} VALs, {seconds:.1} s, rel RMSE {error:.4}, without worst 1 % {without:.4}, \
             worst 1 %'s share of the squared error {share:.3}, mean ratio {ratio:.3}"
        );
        if let Some(dir) = &images {
            image.write_exr(&dir.join(format!("{}.exr", name.replace(' ', "_")))).unwrap();
        }
    }
}
