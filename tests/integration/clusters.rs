//! The clustered visibility mode (`gpu::visibility::clusters`) against its CPU twins
//! (`gpu::visibility::clusters::twin`) on the same inputs: k-means on the GPU's own VALs, the
//! soft-shadow visibility of every (sparse point, cluster) on the GPU's own shadow maps, and
//! the gather with that visibility per VAL.
//!
//! Tolerances: k-means compares distances that lavapipe computes with a few ulp of error
//! (`acos`, `sqrt`), so a VAL almost equidistant from two centres may go either way; we allow
//! 0.5 % of VALs to differ and centres to agree to 1e-3 of the scene diagonal. The visibility
//! taps round continuous texel positions down; a tap exactly on a texel edge may round either
//! way, so 1 % of (point, cluster) entries may differ (by one tap, 1/25) and the mean
//! difference must stay under 1e-3. The gather uses the same 1e-3 relative tolerance as the
//! other twins (`twins.rs`).

use super::{assert_close, gpu};
use glam::Vec3;
use relume::gpu::visibility::clusters::{ClusterReadback, Clusters, twin};
use relume::renderer::{Method, Renderer};
use relume::scene::Scene;

/// `cornell_bunny_small.json` with `"visibility": mode` and `settings` (more entries of
/// `settings.tuning`, e.g. `"clusters": {...}`, and `"bounces"`, which goes beside `tuning`) in
/// place of its `"visibility": "off"`.
pub(super) fn small_scene_with(mode: &str, settings: &str) -> Scene {
    let dir = super::fixture("scenes");
    let base = std::fs::read_to_string(dir.join("cornell_bunny_small.json")).unwrap();
    // `bounces` is what the user wants, beside `tuning`; the rest are research knobs in it.
    let (bounces, settings) = match ["\"bounces\": 1", "\"bounces\": 2"].iter().find(|b| settings.contains(**b)) {
        Some(b) => (format!("{b}, "), settings.replace(&format!("{b}, "), "").replace(*b, "")),
        None => (String::new(), settings.to_owned()),
    };
    let settings = settings.trim().trim_end_matches(',');
    let knobs = if settings.is_empty() { String::new() } else { format!(", {settings}") };
    let json = base
        .replace("\"visibility\": \"off\"", &format!("\"visibility\": \"{mode}\"{knobs}"))
        .replace("\"tuning\": {", &format!("{bounces}\"tuning\": {{"));
    assert_ne!(json, base);
    Scene::from_json_str(&json, &dir).unwrap()
}

fn clusters_scene(settings: &str) -> Scene {
    small_scene_with("clusters", &format!("\"clusters\": {settings}"))
}

/// What the last frame's group visibility mode (clusters or ism: both are [`Clusters`])
/// computed.
pub(super) fn readback(renderer: &Renderer, gpu: &relume::gpu::Gpu, vals: usize) -> ClusterReadback {
    let g = renderer.group_visibility().expect("a group visibility mode ran");
    let c = g.as_any().downcast_ref::<Clusters>().expect("clusters and ism are built on Clusters");
    c.read(gpu, vals, renderer.scene.flat.sparse_points.len()).unwrap()
}

fn assert_kmeans_matches(start: &[twin::Cluster], vals: &[relume::twin::Val], r: &ClusterReadback, diagonal: f32) {
    let mut clusters = start.to_vec();
    let groups = twin::kmeans(&mut clusters, vals, &r.kmeans, r.settings.iterations);
    let differ = groups.iter().zip(&r.group_of_val).filter(|(a, b)| a != b).count();
    assert!(differ * 200 <= vals.len(), "{differ} of {} VALs in another cluster", vals.len());
    // A VAL that went to the other cluster moves both centres by up to its distance from them
    // (<= 2 radii) over the cluster's count: the centres agree to 1e-3 of the diagonal plus that.
    let mut flips = vec![0u32; clusters.len()];
    for (&a, &b) in groups.iter().zip(&r.group_of_val).filter(|(a, b)| a != b) {
        for k in [a, b] {
            if let Some(f) = flips.get_mut(k as usize) {
                *f += 1;
            }
        }
    }
    for (k, (cpu, gpu)) in clusters.iter().zip(&r.clusters).enumerate() {
        let moved = flips[k] as f32 * 2.0 * cpu.radius.max(gpu.radius) / cpu.count.min(gpu.count).max(1.0);
        let tolerance = 1e-3 * diagonal + moved;
        assert!((cpu.position - gpu.position).length() <= tolerance, "cluster {k}: GPU {gpu:?} CPU {cpu:?}");
        assert!((cpu.count - gpu.count).abs() <= 0.005 * vals.len() as f32, "cluster {k}: GPU {gpu:?} CPU {cpu:?}");
    }
}

#[test]
fn clusters_match_cpu_twins() {
    let scene = clusters_scene(r#"{"count": 12, "shadow_map_resolution": 64, "iterations": 3, "soft": "pcss"}"#);
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
    let stages: Vec<&str> = frame.timings.stages.iter().map(|(n, _)| n.as_str()).collect();
    let at = stages.iter().position(|s| *s == "clustering").expect("a clustering stage");
    let want = ["clustering", "cluster_shadow_maps", "cluster_visibility", "gather"];
    assert_eq!(&stages[at..at + 4], &want[..], "{stages:?}");
    let vals = renderer.read_vals(&gpu).unwrap();
    let r = readback(&renderer, &gpu, vals.len());
    let diagonal = 1.0 / r.kmeans.position_scale;
    assert_kmeans_matches(&vec![twin::Cluster::default(); 12], &vals, &r, diagonal);

    assert_lookup_and_gather_match(&renderer, &gpu, &vals, &r, r.settings.shadow_map_resolution);
}

/// The visibility of every (sparse point, group) recomputed by the twin on the GPU's own maps
/// (1 % of entries may differ by a tap, the mean difference under 1e-3), some of it shadowed,
/// and the gather as every VAL's irradiance times its group's visibility (1e-3 relative).
pub(super) fn assert_lookup_and_gather_match(
    renderer: &Renderer,
    gpu: &relume::gpu::Gpu,
    vals: &[relume::twin::Val],
    r: &ClusterReadback,
    resolution: u32,
) {
    let slope_bias_texels = r.ism.map_or(0.0, |p| p.slope_bias_texels);
    let flat = &renderer.scene.flat;
    let m = r.clusters.len();
    let (mut differ, mut sum_diff, mut shadowed) = (0, 0.0, 0);
    for (i, p) in flat.sparse_points.iter().enumerate() {
        for (k, c) in r.clusters.iter().enumerate() {
            let tile = twin::DepthTile { resolution, depths: &r.maps[k], slope_bias_texels };
            let receiver =
                twin::ShadowReceiver { offset: Vec3::from(p.position) - c.position, normal: p.normal.into() };
            let cpu = twin::cluster_visibility(&tile, c, &receiver, r.settings.soft);
            let gpu = r.visibility[i * m + k];
            let d = (cpu - gpu).abs();
            sum_diff += d;
            differ += usize::from(d > 1e-3);
            shadowed += usize::from(gpu < 0.5);
        }
    }
    let n = flat.sparse_points.len() * m;
    assert!(differ * 100 <= n, "{differ} of {n} visibilities differ");
    assert!(sum_diff / (n as f32) < 1e-3, "mean difference {}", sum_diff / n as f32);
    assert!(shadowed > 0, "the bunny must shadow some sparse points from some group");

    let mid = renderer.read_sparse_intermediates(gpu).unwrap();
    let expected: Vec<Vec3> = flat
        .sparse_points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let (x, n) = (Vec3::from(p.position), Vec3::from(p.normal));
            vals.iter()
                .zip(&r.group_of_val)
                .map(|(v, g)| relume::twin::val_irradiance(x, n, v) * r.visibility[i * m + *g as usize])
                .sum()
        })
        .collect();
    let scale = expected.iter().map(|e| e.max_element()).fold(0.0, f32::max);
    for (i, e) in expected.iter().enumerate() {
        assert_close(mid.gathered_diffuse[i].irradiance.into(), *e, 1e-3, scale, 1e-9, &format!("E at {i}"));
    }
}

/// Each frame's k-means starts from the last frame's centres: the second frame's clusters are
/// the twin's k-means started from the first frame's (GPU) clusters, with the light moved.
#[test]
fn clusters_start_from_last_frames_centres() {
    let scene = clusters_scene(r#"{"count": 8, "shadow_map_resolution": 32, "iterations": 2}"#);
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
    let first = readback(&renderer, &gpu, 0).clusters;
    let mut light = renderer.spot().unwrap();
    light.position += Vec3::new(-0.05, 0.0, 0.02);
    renderer.set_spot_light(&light);
    renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
    let vals = renderer.read_vals(&gpu).unwrap();
    let r = readback(&renderer, &gpu, vals.len());
    assert_ne!(first, r.clusters, "the light moved");
    assert_kmeans_matches(&first, &vals, &r, 1.0 / r.kmeans.position_scale);
}
