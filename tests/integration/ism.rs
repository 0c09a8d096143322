//! The imperfect shadow maps mode (`gpu::visibility::ism`) against its CPU twins
//! (`gpu::visibility::ism::twin`, and the clusters' lookup twin) on the same inputs: the flux
//! draw and the update on the GPU's own VALs, every map splatted and pull-pushed around the
//! GPU's own group centres, the visibility of every (sparse point, group) on the GPU's own
//! maps, and the gather with it.
//!
//! Tolerances: the groups compare distances lavapipe computes with a few ulp of error (`acos`,
//! `sqrt`), so as in `clusters.rs` 0.5 % of VALs may join another group. A point's texel is
//! `floor` of a projected position: a point within an ulp of a texel edge may land in the
//! neighbour, and its distance (a `length`) may differ in the last bits, which pull-push then
//! spreads over up to 4x4 texels; so 2 % of texels may differ by more than 1e-4 relative. The
//! lookup and the gather use the clusters' tolerances (1 % of entries, mean under 1e-3; 1e-3
//! relative).

use super::clusters::{readback, small_scene_with};
use super::gpu;
use glam::Vec3;
use relume::gpu::visibility::clusters::ClusterReadback;
use relume::gpu::visibility::ism::twin as ism_twin;
use relume::renderer::{Method, Renderer};
use relume::scene::Scene;

fn ism_scene(settings: &str) -> Scene {
    small_scene_with("ism", &format!("\"ism\": {settings}"))
}

/// One 16x16 sparse frame of `scene` with imperfect maps: its stages are `grouping` (how the
/// groups are made), the splat, pull-push and lookup, then the gather; the VALs and the readback.
fn render_group_mode(
    scene: &Scene,
    grouping: &str,
) -> (relume::gpu::Gpu, Renderer, Vec<relume::twin::Val>, ClusterReadback) {
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
    let stages: Vec<&str> = frame.timings.stages.iter().map(|(n, _)| n.as_str()).collect();
    let at = stages.iter().position(|s| *s == grouping).expect("the grouping stage");
    let want = [grouping, "ism_splat", "ism_pull_push", "ism_visibility", "gather"];
    assert_eq!(&stages[at..at + 5], &want[..], "{stages:?}");
    let vals = renderer.read_vals(&gpu).unwrap();
    let r = readback(&renderer, &gpu, vals.len());
    (gpu, renderer, vals, r)
}

#[test]
fn ism_matches_cpu_twins() {
    let count = 24;
    let scene = ism_scene(&format!(r#"{{"count": {count}, "resolution": 32, "points": 400, "soft": "pcss"}}"#));
    let (gpu, renderer, vals, r) = render_group_mode(&scene, "ism_sampling");
    let params = r.ism.expect("the ism mode's lengths");

    // The groups: flux seeds, one assignment and update.
    let (clusters, groups) = ism_twin::groups(&vals, count, &r.kmeans);
    let differ = groups.iter().zip(&r.group_of_val).filter(|(a, b)| a != b).count();
    assert!(differ * 200 <= vals.len(), "{differ} of {} VALs in another group", vals.len());
    let diagonal = 1.0 / r.kmeans.position_scale;
    let lit = clusters.iter().filter(|c| c.count > 0.0).count();
    assert!(lit > count as usize / 2, "most draws are distinct lit VALs: {lit} of {count}");
    if differ == 0 {
        for (k, (cpu, gpu)) in clusters.iter().zip(&r.clusters).enumerate() {
            assert!((cpu.position - gpu.position).length() <= 1e-3 * diagonal, "group {k}: GPU {gpu:?} CPU {cpu:?}");
            assert_eq!(cpu.count, gpu.count, "group {k}");
        }
    }

    assert_maps_match(&renderer, &r, 0.25);

    // Visibility on the GPU's own maps, and the gather with it.
    super::clusters::assert_lookup_and_gather_match(&renderer, &gpu, &vals, &r, params.resolution);
}

/// Every map, splatted and pull-pushed by the twin around the GPU's own centres, against the
/// GPU's (2 % of texels may differ, see the module's note), and more than `drawn_share` of the
/// texels hold depths.
fn assert_maps_match(renderer: &Renderer, r: &ClusterReadback, drawn_share: f32) {
    let params = r.ism.expect("imperfect maps");
    let flat = &renderer.scene.flat;
    let positions: Vec<Vec3> = flat.vertices.iter().map(|v| Vec3::from(v.position)).collect();
    let cdf = ism_twin::triangle_cdf(&positions, &flat.indices, &flat.triangle_sparse_density);
    let (mut texels, mut texels_differ, mut drawn) = (0, 0, 0);
    for (k, c) in r.clusters.iter().enumerate() {
        let mut map = ism_twin::splat_in(c, &r.frames[k], k as u32, &params, &cdf, &positions, &flat.indices);
        ism_twin::pull_push(&mut map, params.resolution, &params);
        for (a, b) in map.iter().zip(&r.maps[k]) {
            texels += 1;
            drawn += usize::from(b.is_finite());
            let same = (a.is_infinite() && b.is_infinite()) || (a - b).abs() <= 1e-4 * a.abs().max(1.0);
            texels_differ += usize::from(!same);
        }
    }
    assert!(texels_differ * 50 <= texels, "{texels_differ} of {texels} texels differ");
    assert!(drawn as f32 > drawn_share * texels as f32, "the maps hold depths: {drawn} of {texels} texels");
}

/// The clusters mode with `shadow_maps: "ism"`: k-means groups, imperfect maps, the same
/// lookup; maps, lookup and gather against the twins.
#[test]
fn clusters_with_imperfect_maps_match_cpu_twins() {
    let scene = small_scene_with(
        "clusters",
        r#""clusters": {"count": 12, "shadow_map_resolution": 32, "shadow_maps": "ism", "soft": "pcss"}, "ism": {"points": 500}"#,
    );
    let (gpu, renderer, vals, r) = render_group_mode(&scene, "clustering");
    assert_eq!((r.clusters.len(), r.ism.map(|p| (p.resolution, p.points))), (12, Some((32, 500))));
    assert_maps_match(&renderer, &r, 0.25);
    super::clusters::assert_lookup_and_gather_match(&renderer, &gpu, &vals, &r, 32);
}

/// Without pull-push the stages are the splat alone; a scene without lit VALs (a dark spot
/// light) gives empty groups and full visibility, with no NaN.
#[test]
fn ism_without_pull_push_and_without_light() {
    let scene = ism_scene(r#"{"count": 8, "resolution": 16, "pull_push_levels": 0}"#);
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
    let stages: Vec<&str> = frame.timings.stages.iter().map(|(n, _)| n.as_str()).collect();
    assert!(stages.contains(&"ism_splat") && !stages.contains(&"ism_pull_push"), "{stages:?}");
    let mut dark = scene.clone();
    let light = dark.light.as_mut().expect("the fixture has a spot light");
    light.intensity = Vec3::ZERO;
    let mut renderer = Renderer::new(&gpu, &dark).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
    let r = readback(&renderer, &gpu, 0);
    assert!(r.visibility.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)), "{:?}", &r.visibility[..8]);
    assert!(frame.indirect.pixels.iter().all(|p| p.iter().all(|c| c.is_finite())));
}

/// `brute_force_ism` (the brute force with per-pixel ISM visibility) against its twins on the
/// GPU's own VALs, groups and maps: its stages (the `ism` mode's, named `brute_force_ism_*`,
/// then the lookup at the pixels and the brute force), the groups, the maps, then the table
/// and the image ([`assert_pixels_match`]).
#[test]
fn brute_force_ism_matches_cpu_twins() {
    let count = 24;
    let scene = ism_scene(&format!(r#"{{"count": {count}, "resolution": 32, "points": 400}}"#));
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let (w, h) = (16, 12);
    let frame = renderer.render(&gpu, Method::BruteForceIsm, w, h).unwrap();
    let stages: Vec<&str> = frame.timings.stages.iter().map(|(n, _)| n.as_str()).collect();
    let at = stages.iter().position(|s| *s == "brute_force_ism_sampling").expect("its groups");
    let want = [
        "brute_force_ism_sampling",
        "brute_force_ism_splat",
        "brute_force_ism_pull_push",
        "brute_force_ism_visibility",
        "brute_force",
    ];
    assert_eq!(&stages[at..at + 5], &want[..], "{stages:?}");
    assert!(!stages.contains(&"gather"), "{stages:?}");
    let vals = renderer.read_vals(&gpu).unwrap();
    let groups = renderer.brute_force_groups().expect("brute_force_ism's groups");
    let pixels = (w * h) as usize;
    let r = groups.read(&gpu, vals.len(), pixels).unwrap();
    let m = r.clusters.len();
    assert_eq!(m, count as usize);
    let (clusters, cpu_groups) = ism_twin::groups(&vals, count, &r.kmeans);
    let differ = cpu_groups.iter().zip(&r.group_of_val).filter(|(a, b)| a != b).count();
    assert!(differ * 200 <= vals.len(), "{differ} of {} VALs in another group", vals.len());
    assert!(clusters.iter().filter(|c| c.count > 0.0).count() > m / 2);
    assert_maps_match(&renderer, &r, 0.25);

    let params = r.ism.expect("imperfect maps");
    assert_pixels_match(&mut renderer, &gpu, &frame, &vals, &r, params.resolution, "brute_force_ism");
}

/// A grouped brute force's visibility and image against their twins on the GPU's own VALs,
/// groups and maps (`r`, of `resolution`): every (pixel, group) lookup by the clusters' lookup
/// twin, some shadowed. With a table (`brute_force_ism`) its entries against the twin's (the
/// sparse points' tolerances: 1 % may differ by a tap, mean difference under 1e-3; uncovered
/// pixels 1) and every covered pixel against `twin::shade_brute_force_grouped` with the GPU's
/// table (1e-3 of the brightest pixel, the brute-force twin test's tolerance). Without one
/// (`brute_force_clusters`, looked up in the pass) the pixels against the twin with the twin's
/// lookups: a lookup a tap apart moves its pixel, so 2 % of the pixels may differ and the mean
/// difference stays under 1e-3 of the brightest. Darker than the plain brute force.
pub(super) fn assert_pixels_match(
    renderer: &mut Renderer,
    gpu: &relume::gpu::Gpu,
    frame: &relume::renderer::Rendered,
    vals: &[relume::twin::Val],
    r: &relume::gpu::visibility::clusters::ClusterReadback,
    resolution: u32,
    label: &str,
) {
    use relume::gpu::visibility::clusters::twin as ctwin;
    let (w, h) = (frame.indirect.width, frame.indirect.height);
    let m = r.clusters.len();
    let pixels = (w * h) as usize;
    let slope_bias_texels = r.ism.map_or(0.0, |p| p.slope_bias_texels);
    let hits = renderer.camera_view().unwrap().read(gpu).unwrap();
    let flat = &renderer.scene.flat;
    let twin_rows: Vec<Vec<f32>> = hits
        .iter()
        .map(|hit| match hit {
            None => vec![1.0; m],
            Some(hit) => {
                let (p, n, _) = flat.surface_at(hit.triangle, hit.barycentrics);
                (r.clusters.iter().enumerate())
                    .map(|(k, c)| {
                        let tile = ctwin::DepthTile { resolution, depths: &r.maps[k], slope_bias_texels };
                        let receiver = ctwin::ShadowReceiver { offset: p - c.position, normal: n };
                        ctwin::cluster_visibility_in(&tile, c, &r.frames[k], &receiver, r.settings.soft)
                    })
                    .collect()
            }
        })
        .collect();
    let shadowed = twin_rows.iter().flatten().filter(|v| **v < 0.5).count();
    assert!(shadowed > 0, "{label}: the bunny and the box shadow some pixels from some group");
    let table = !r.visibility.is_empty();
    if table {
        let (mut differ, mut sum_diff) = (0, 0.0);
        for (i, row) in twin_rows.iter().enumerate() {
            for (k, v) in row.iter().enumerate() {
                let d = (v - r.visibility[i * m + k]).abs();
                sum_diff += d;
                differ += usize::from(d > 1e-3);
            }
        }
        let n = pixels * m;
        assert!(differ * 100 <= n, "{label}: {differ} of {n} visibilities differ");
        assert!(sum_diff / (n as f32) < 1e-3, "{label}: mean difference {}", sum_diff / n as f32);
    }

    let eye = renderer.view().eye();
    let glossy = renderer.glossy();
    let expected: Vec<Option<Vec3>> = hits
        .iter()
        .enumerate()
        .map(|(i, hit)| {
            hit.map(|h| {
                let (p, n, surface) = flat.surface_at(h.triangle, h.barycentrics);
                let row = if table { &r.visibility[i * m..(i + 1) * m] } else { &twin_rows[i][..] };
                relume::twin::shade_brute_force_grouped(p, n, &surface, eye, vals, &r.group_of_val, row, glossy)
            })
        })
        .collect();
    let scale = expected.iter().flatten().map(|e| e.max_element()).fold(0.0, f32::max);
    assert!(scale > 0.0);
    let (mut covered, mut differ, mut sum_diff) = (0, 0, 0.0);
    for (i, e) in expected.iter().enumerate() {
        assert_eq!(e.is_some(), frame.indirect.covered(i));
        let Some(e) = e else { continue };
        if table {
            super::assert_close(frame.indirect.rgb(i), *e, 1e-3, scale, 1e-9, &format!("{label} pixel {i}"));
        }
        let d = (frame.indirect.rgb(i) - *e).abs().max_element() / scale;
        covered += 1;
        differ += usize::from(d > 1e-3);
        sum_diff += d;
    }
    println!("{label}: {differ} of {covered} pixels differ from the twin's by over 1e-3 of the brightest");
    assert!(differ * 50 <= covered, "{label}: {differ} of {covered} pixels differ");
    assert!(sum_diff / (covered as f32) < 1e-3, "{label}: mean difference {}", sum_diff / covered as f32);
    let plain = renderer.render(gpu, Method::BruteForce, w, h).unwrap();
    let (a, b) = (frame.indirect.luminance_sum_and_peak().0, plain.indirect.luminance_sum_and_peak().0);
    assert!(a < 0.99 * b, "{label}: the maps take light from some pixels: {a} vs {b}");
}

/// VALs 2.5 m from a 0.3 m object: every lit group's imperfect map holds the object's points (no
/// far plane cuts them off), maps, lookup and gather match their twins, and the light it leaves
/// is the exact reference's within the clusters' tolerance (`clusters::FAR_DARKENING_TOLERANCE`).
#[test]
fn ism_shadows_a_small_object_lit_from_far() {
    let settings = serde_json::json!({ "count": 32, "resolution": 32, "points": 2000, "soft": "pcss" });
    let (gpu, renderer, vals, r) = super::clusters::far_lit_bunny("ism", settings, 2.5);
    super::clusters::assert_maps_hold_the_object(&r);
    assert_maps_match(&renderer, &r, 0.2);
    super::clusters::assert_lookup_and_gather_match(&renderer, &gpu, &vals, &r, 32);
    super::clusters::assert_far_darkening("ism", &renderer, &gpu, &vals);
}
