//! The second bounce (`settings.bounces: 2`, `gpu::lights::bounce`): the GPU's candidates and
//! drawn VALs against the CPU twin (`twin::bounce`) on the GPU's own inputs, and a closed white
//! furnace in which the second bounce adds what the albedo predicts.

use super::clusters::small_scene_with;
use super::gpu;
use glam::Vec3;
use relume::renderer::{Method, Renderer, stage};
use relume::scene::Scene;
use relume::twin::Val;
use relume::twin::bounce::{self as twin, BounceSurface};

fn surfaces(renderer: &Renderer) -> Vec<BounceSurface> {
    let b = renderer.second_bounce().expect("a second bounce");
    b.points.iter().map(|p| BounceSurface::at(&renderer.scene.flat, p)).collect()
}

fn luminance_sum(vals: &[Val]) -> f32 {
    vals.iter().map(|v| relume::twin::luminance(v.flux)).sum()
}

/// `cornell_bunny_small.json` with a second bounce of 48 VALs from 700 points: the GPU's
/// candidates against `twin::candidate_vals` on the GPU's own first-bounce VALs, and its drawn
/// VALs against `twin::draw_vals` on the GPU's own candidates.
///
/// Tolerances: a candidate's flux is a sum over ~800 VALs of the disc form factor, which
/// lavapipe evaluates with a few ulp of error (`inverseSqrt`), so 1e-4 of the largest
/// candidate's flux. The draw is the same f32 sums in the same order on both sides, but a
/// goal within an ulp of a running sum may pick the neighbouring candidate: at most 1 draw in
/// 48 may differ; the others land on the same point with flux equal to 1e-4.
#[test]
fn second_bounce_matches_cpu_twin() {
    let scene = small_scene_with("off", r#""bounces": 2, "second_bounce": {"points": 700, "vals": 48}"#);
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
    let stages: Vec<&str> = frame.timings.stages.iter().map(|(n, _)| n.as_str()).collect();
    let at = stages.iter().position(|s| *s == stage::BOUNCE2_POINTS).expect("the bounce stages");
    assert_eq!(&stages[at..at + 2], &[stage::BOUNCE2_POINTS, stage::BOUNCE2_VALS], "{stages:?}");
    assert!(at > stages.iter().position(|s| *s == stage::RSM_VALS).unwrap(), "after the first bounce: {stages:?}");
    assert!(at < stages.iter().position(|s| *s == stage::GATHER).unwrap(), "before the gather: {stages:?}");

    let all = renderer.read_vals(&gpu).unwrap();
    let bounce = renderer.second_bounce().unwrap();
    assert_eq!(bounce.points.len(), 700);
    let first = &all[..all.len() - 48];
    let drawn = &all[all.len() - 48..];

    let gpu_candidates = bounce.read_candidates(&gpu).unwrap();
    let cpu_candidates = twin::candidate_vals(&surfaces(&renderer), first, None);
    let largest = cpu_candidates.iter().map(|c| c.flux.max_element()).fold(0.0, f32::max);
    assert!(largest > 0.0, "the first bounce lights some points");
    let lit = cpu_candidates.iter().filter(|c| c.flux.max_element() > 0.0).count();
    assert!(lit > 100, "{lit} of 700 points lit");
    for (k, (g, c)) in gpu_candidates.iter().zip(&cpu_candidates).enumerate() {
        assert!((g.position - c.position).length() < 1e-5, "point {k}: {g:?} vs {c:?}");
        assert!((g.flux - c.flux).abs().max_element() <= 1e-4 * largest, "point {k}: GPU {g:?} CPU {c:?}");
    }

    let cpu_drawn = twin::draw_vals(&gpu_candidates, 48, bounce.drawn_area);
    let mut differ = 0;
    for (g, c) in drawn.iter().zip(&cpu_drawn) {
        if (g.position - c.position).length() > 1e-6 {
            differ += 1;
            continue;
        }
        assert!((g.flux - c.flux).abs().max_element() <= 1e-4 * c.flux.max_element(), "GPU {g:?} CPU {c:?}");
        assert_eq!(g.area, c.area);
    }
    assert!(differ <= 1, "{differ} of 48 draws picked another point");
    // Unbiased by construction: the drawn flux adds up to the candidates' (exactly for grey
    // flux; this scene's red and green walls make it coloured, so within 10 %).
    let (drawn_sum, candidate_sum) = (luminance_sum(drawn), luminance_sum(&gpu_candidates));
    assert!((drawn_sum / candidate_sum - 1.0).abs() < 0.1, "drawn {drawn_sum} vs candidates {candidate_sum}");

    // One bounce: no stage, and no second-bounce VALs.
    let one = small_scene_with("off", r#""bounces": 1"#);
    let mut renderer = Renderer::new(&gpu, &one).unwrap();
    assert!(renderer.second_bounce().is_none());
    let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
    assert!(frame.timings.stages.iter().all(|(n, _)| !n.starts_with("bounce2")), "{:?}", frame.timings.stages);
    assert_eq!(renderer.read_vals(&gpu).unwrap().len(), first.len());
}

/// A closed 2 m box seen from inside (faces inward), every wall of albedo `rho`, a spot light
/// under the ceiling aimed at the floor.
fn furnace(rho: f32) -> Scene {
    let mut obj = String::new();
    for i in 0..8 {
        let c = |bit: i32| if i & bit == 0 { -1.0 } else { 1.0 };
        obj += &format!("v {} {} {}\n", c(1), c(2) + 1.0, c(4));
    }
    // Corner index = 1 + x + 2y + 4z; each face wound to face the inside.
    obj += "f 2 4 3 1\nf 7 8 6 5\nf 5 6 2 1\nf 4 8 7 3\nf 3 7 5 1\nf 6 8 4 2\n";
    let json = serde_json::json!({
        "meshes": [{ "obj": "room.obj", "obj_text": obj, "sparse_points": 3000,
                     "material": { "diffuse": [rho, rho, rho] } }],
        "light": { "position": [0.1, 1.9, 0.05], "direction": [0, -1, 0], "inner_angle_deg": 30,
                   "outer_angle_deg": 40, "intensity": [5, 5, 5] },
        "camera": { "position": [0, 1, 0.9], "target": [0, 1, 0], "fov_y_deg": 90, "width": 32, "height": 32 },
        "settings": { "bounces": 2,
                      "tuning": { "rsm_resolution": 48, "visibility": "off",
                                  "second_bounce": { "points": 4096, "vals": 512 } } }
    });
    Scene::from_json_str(&json.to_string(), std::path::Path::new(".")).expect("furnace scene")
}

/// In a closed box every watt a bounce's VALs emit lands on the walls, which reflect `rho` of
/// it: the second bounce's VALs carry `rho` times the first's flux, and the mean irradiance
/// the second bounce adds at the sparse points (blue noise, area-proportional on the one mesh:
/// their mean is the walls' area mean) is `rho` times the first's.
///
/// Tolerance: the ratios may fall short of `rho` by up to 4 % and pass it by up to 2 %. Short,
/// because the disc form factor `cos cos a / (pi d² + a)` delivers less than a point's
/// `cos cos / (pi d²)` to receivers within a few disc radii, which a closed room's adjacent
/// walls have near its edges (measured: the first bounce's RSM discs deliver 97.7 % of their
/// flux here, and the second bounce's, each a point's patch of 24 m² / 4,096, 97.5 %; the test
/// checks that shrunk to points they deliver all of it, within 2 %); and because 4,096 points
/// estimate the reflected flux and 3,000 sparse points each mean irradiance (stratified by
/// area: about 1 % each). Nothing in the chain can add energy, so above `rho` only that
/// estimation noise is allowed. Measured: 0.977 rho for both ratios at rho 0.5 and 1.
#[test]
fn white_furnace_second_bounce_adds_albedo_times_first() {
    let gpu = gpu();
    for rho in [0.5f32, 1.0] {
        let scene = furnace(rho);
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        renderer.render(&gpu, Method::Sparse, 32, 32).unwrap();
        let vals = renderer.read_vals(&gpu).unwrap();
        let (first, second) = vals.split_at(vals.len() - 512);
        let e2 = renderer.read_gathered_irradiance(&gpu).unwrap();
        let points = surfaces(&renderer);

        let one = {
            let mut s = scene.clone();
            s.settings.bounces = 1;
            s
        };
        let mut renderer = Renderer::new(&gpu, &one).unwrap();
        renderer.render(&gpu, Method::Sparse, 32, 32).unwrap();
        assert_eq!(renderer.read_vals(&gpu).unwrap().len(), first.len(), "the same first bounce");
        let e1 = renderer.read_gathered_irradiance(&gpu).unwrap();

        let flux_ratio = luminance_sum(second) / luminance_sum(first);
        let mean = |e: &[Vec3]| e.iter().map(|e| f64::from(relume::twin::luminance(*e))).sum::<f64>() / e.len() as f64;
        let (m1, m2) = (mean(&e1), mean(&e2));
        let added_ratio = ((m2 - m1) / m1) as f32;
        eprintln!("rho {rho}: second/first flux {flux_ratio:.4}, added/first mean irradiance {added_ratio:.4}");
        for (what, ratio) in [("flux", flux_ratio), ("mean irradiance", added_ratio)] {
            assert!(
                ratio > 0.96 * rho && ratio < 1.02 * rho,
                "rho {rho}: second bounce's {what} is {ratio} of the first's"
            );
        }
        // What falls short is the disc form factor's: with the discs shrunk to points, the
        // bounce points receive every watt either bounce emits, within the points' estimation
        // noise (2 %).
        for (name, vals) in [("first", first), ("second", second)] {
            let points_only: Vec<Val> = vals.iter().map(|v| Val { area: 0.0, ..*v }).collect();
            let received: f32 =
                twin::candidate_vals(&points, &points_only, None).iter().map(|c| relume::twin::luminance(c.flux)).sum();
            let fraction = received / rho / luminance_sum(vals);
            eprintln!("rho {rho}: the {name} bounce's flux received as from points: {fraction:.4}");
            assert!((fraction - 1.0).abs() < 0.02, "rho {rho}: {name} bounce: {fraction} of the flux received");
        }
    }
}

/// The stages of a frame, by name.
fn stage_names(frame: &relume::renderer::Rendered) -> Vec<&str> {
    frame.timings.stages.iter().map(|(n, _)| n.as_str()).collect()
}

/// With the sparse method's `ism` or `clusters` mode the bounce points see the first bounce
/// through that mode's maps: the first bounce's groups and maps (stages of their own, before
/// `bounce2_points`), their lookup at every (bounce point, group) against the clusters' lookup
/// twin on the GPU's own maps, and the candidates against `twin::grouped_candidate_vals` on
/// the GPU's own VALs, groups and table. The brute force keeps them unoccluded.
///
/// Tolerances: the lookup's, as in `clusters.rs` (a tap on a texel edge may round either way:
/// 1 % of entries may differ, the mean difference under 1e-3); the ISM groups' assignment, as
/// in `ism.rs` (0.5 % of VALs); the candidates' as in `second_bounce_matches_cpu_twin` (1e-4 of
/// the largest: the same sums over ~800 VALs, each now times its group's entry).
#[test]
fn second_bounce_through_group_visibility_matches_cpu_twin() {
    use relume::gpu::visibility::clusters::twin as ctwin;
    use relume::gpu::visibility::ism::twin as ism_twin;
    let gpu = gpu();
    let cases: [(&str, &str, &[&str]); 2] = [
        (
            "ism",
            r#""ism": {"count": 24, "resolution": 32, "points": 400}"#,
            &["bounce2_ism_sampling", "bounce2_ism_splat", "bounce2_ism_pull_push"],
        ),
        (
            "clusters",
            r#""clusters": {"count": 12, "shadow_map_resolution": 64, "soft": "pcss"}"#,
            &["bounce2_clustering", "bounce2_cluster_shadow_maps"],
        ),
    ];
    for (mode, settings, grouping) in cases {
        let bounce_settings = r#""bounces": 2, "second_bounce": {"points": 700, "vals": 48}"#;
        let scene = small_scene_with(mode, &format!("{settings}, {bounce_settings}"));
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
        let stages = stage_names(&frame);
        let at = stages.iter().position(|s| *s == grouping[0]).unwrap_or_else(|| panic!("{mode}: {stages:?}"));
        let mut want = grouping.to_vec();
        want.extend([stage::BOUNCE2_VISIBILITY, stage::BOUNCE2_POINTS, stage::BOUNCE2_VALS]);
        assert_eq!(&stages[at..at + want.len()], &want[..], "{mode}");
        assert!(at > stages.iter().position(|s| *s == stage::RSM_VALS).unwrap(), "{mode}: {stages:?}");
        // The sparse method's own instance, over every VAL, comes after the draw.
        let sparse_grouping = if mode == "ism" { stage::ISM_SAMPLING } else { stage::CLUSTERING };
        assert!(stages.iter().position(|s| *s == sparse_grouping).unwrap() > at + want.len() - 1, "{stages:?}");

        let all = renderer.read_vals(&gpu).unwrap();
        let first = &all[..all.len() - 48];
        let bounce = renderer.second_bounce().unwrap();
        let groups = bounce.visibility().expect("the first bounce's groups");
        let r = groups.read(&gpu, first.len(), 700).unwrap();
        let m = r.clusters.len();
        if mode == "ism" {
            let (_, cpu_groups) = ism_twin::groups(first, m as u32, &r.kmeans);
            let differ = cpu_groups.iter().zip(&r.group_of_val).filter(|(a, b)| a != b).count();
            assert!(differ * 200 <= first.len(), "{differ} of {} first-bounce VALs in another group", first.len());
        }

        // The lookup at the bounce points, on the GPU's own maps.
        let points = surfaces(&renderer);
        let slope_bias_texels = r.ism.map_or(0.0, |p| p.slope_bias_texels);
        let resolution = r.settings.shadow_map_resolution;
        let (mut differ, mut sum_diff, mut shadowed) = (0, 0.0, 0);
        for (i, p) in points.iter().enumerate() {
            for (k, c) in r.clusters.iter().enumerate() {
                let tile = ctwin::DepthTile { resolution, depths: &r.maps[k], slope_bias_texels };
                let receiver = ctwin::ShadowReceiver { offset: p.position - c.position, normal: p.normal };
                let cpu = ctwin::cluster_visibility(&tile, c, &receiver, r.settings.soft);
                let d = (cpu - r.visibility[i * m + k]).abs();
                sum_diff += d;
                differ += usize::from(d > 1e-3);
                shadowed += usize::from(r.visibility[i * m + k] < 0.5);
            }
        }
        let n = points.len() * m;
        assert!(differ * 100 <= n, "{mode}: {differ} of {n} visibilities differ");
        assert!(sum_diff / (n as f32) < 1e-3, "{mode}: mean difference {}", sum_diff / n as f32);
        assert!(shadowed > 0, "{mode}: the bunny and the box shadow some bounce points");

        // The candidates through that table.
        let gpu_candidates = bounce.read_candidates(&gpu).unwrap();
        let cpu_candidates = twin::grouped_candidate_vals(&points, first, &r.group_of_val, &r.visibility, m);
        let largest = cpu_candidates.iter().map(|c| c.flux.max_element()).fold(0.0, f32::max);
        assert!(largest > 0.0, "{mode}: the first bounce lights some points");
        for (k, (g, c)) in gpu_candidates.iter().zip(&cpu_candidates).enumerate() {
            assert!((g.flux - c.flux).abs().max_element() <= 1e-4 * largest, "{mode} point {k}: GPU {g:?} CPU {c:?}");
        }
        let open = luminance_sum(&twin::candidate_vals(&points, first, None));
        let seen = luminance_sum(&gpu_candidates);
        eprintln!("{mode}: the candidates carry {:.4} of their unoccluded flux", seen / open);
        assert!(seen < 0.99 * open, "{mode}: occluders take light from the bounce points: {seen} of {open}");

        // The brute force is the no-visibility reference: unoccluded points, no lookup.
        let frame = renderer.render(&gpu, Method::BruteForce, 16, 16).unwrap();
        let stages = stage_names(&frame);
        assert!(!stages.iter().any(|s| s.starts_with("bounce2_") && !s.ends_with("points") && !s.ends_with("vals")));
        let bounce = renderer.second_bounce().unwrap();
        assert!(bounce.visibility().is_none(), "{mode}: no groups for the brute force");
        let all = renderer.read_vals(&gpu).unwrap();
        let gpu_candidates = bounce.read_candidates(&gpu).unwrap();
        let cpu_candidates = twin::candidate_vals(&points, &all[..all.len() - 48], None);
        for (k, (g, c)) in gpu_candidates.iter().zip(&cpu_candidates).enumerate() {
            assert!((g.flux - c.flux).abs().max_element() <= 1e-4 * largest, "{mode} point {k}: GPU {g:?} CPU {c:?}");
        }
    }
}

/// With the sparse method's `disks` the bounce points get the sparse points' occlusion
/// (`bounce2_occlusion`, after `bounce2_points`, before the draw): each point's light sphere
/// from its VALs' moments, occluded by the sparse points' discs with the scene's rule. For both
/// rules: the GPU's moments against `twin::bounce::point_gathered` on the GPU's own first-bounce
/// VALs, each candidate against the unoccluded twin candidate times `disks::twin::visibility`
/// of the GPU's own light sphere (as `twins::occlusion_matches_cpu_twin` checks the sparse
/// points), and the whole twin (`twin::disk_occluded_candidate_vals`, its own spheres) in
/// total. Visibility off keeps them unoccluded (no stage), and so does the brute force.
///
/// Tolerances: the moments are luminance-weighted means over ~800 VALs in f32 (a few ulp per
/// term on lavapipe): 1e-3 m (m² for the second moment) relative to 1 + their size; the
/// candidates 1e-3 of the largest, the occlusion twin test's tolerance (a disc's square edge
/// can move an overlap by an ulp's worth of the sphere's square); the totals 1 % (the twin's
/// own spheres differ from the GPU's by those ulps, and a disc at a square's edge or a depth
/// cut may flip for a few of the 700 points).
#[test]
fn second_bounce_through_disks_matches_cpu_twin() {
    use relume::gpu::visibility::disks::twin::{Combine, Disc, light_sphere, visibility};
    let gpu = gpu();
    for (rule, combine) in [("sum", Combine::Sum), ("product", Combine::Product)] {
        let settings =
            format!(r#""occlusion_rule": "{rule}", "bounces": 2, "second_bounce": {{"points": 700, "vals": 48}}"#);
        let scene = small_scene_with("disks", &settings);
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
        let stages = stage_names(&frame);
        let at = stages.iter().position(|s| *s == stage::BOUNCE2_POINTS).expect("the bounce stages");
        assert_eq!(&stages[at..at + 3], &[stage::BOUNCE2_POINTS, stage::BOUNCE2_OCCLUSION, stage::BOUNCE2_VALS]);
        assert!(!stages.contains(&stage::BOUNCE2_VISIBILITY), "{rule}: no group table: {stages:?}");

        let all = renderer.read_vals(&gpu).unwrap();
        let first = &all[..all.len() - 48];
        let bounce = renderer.second_bounce().unwrap();
        let points = surfaces(&renderer);
        let moments = bounce.read_moments(&gpu).unwrap().expect("disks keep the points' moments");
        let discs: Vec<Disc> = renderer
            .scene
            .flat
            .sparse_points
            .iter()
            .map(|p| Disc { position: p.position.into(), normal: p.normal.into(), radius: p.occluder_radius })
            .collect();
        let open = twin::candidate_vals(&points, first, None);
        let gpu_candidates = bounce.read_candidates(&gpu).unwrap();
        let largest = open.iter().map(|c| c.flux.max_element()).fold(0.0, f32::max);
        assert!(largest > 0.0, "{rule}: the first bounce lights some points");
        let mut occluded = 0;
        for (i, p) in points.iter().enumerate() {
            let m = &moments[i];
            let cpu = twin::point_gathered(p, first);
            if cpu.irradiance.max_element() > 0.0 {
                for (g, c) in [(m.position, cpu.diffuse_position), (m.second_moment, cpu.diffuse_second_moment)] {
                    let g = Vec3::from(g);
                    assert!((g - c).length() <= 1e-3 * (1.0 + c.length()), "{rule} point {i}: GPU {g} CPU {c}");
                }
            }
            let sphere = light_sphere(m.position.into(), m.second_moment.into());
            let v = visibility(p.position, p.normal, &sphere, &discs, combine);
            occluded += usize::from(v < 0.9 && open[i].flux.max_element() > 0.0);
            let want = open[i].flux * v;
            let got = gpu_candidates[i].flux;
            assert!((got - want).abs().max_element() <= 1e-3 * largest, "{rule} point {i}: GPU {got} CPU {want}");
        }
        assert!(occluded > 10, "{rule}: the bunny and the boxes occlude some bounce points ({occluded})");
        let full = luminance_sum(&twin::disk_occluded_candidate_vals(&points, first, &discs, combine));
        let (seen, unoccluded) = (luminance_sum(&gpu_candidates), luminance_sum(&open));
        assert!((seen / full - 1.0).abs() < 0.01, "{rule}: GPU {seen} vs twin {full}");
        eprintln!("{rule}: the candidates carry {:.4} of their unoccluded flux", seen / unoccluded);
        assert!(seen < 0.99 * unoccluded, "{rule}: the discs take light from the bounce points");

        // The brute force is the no-visibility reference: unoccluded points, no occlusion pass.
        let frame = renderer.render(&gpu, Method::BruteForce, 16, 16).unwrap();
        assert!(!stage_names(&frame).contains(&stage::BOUNCE2_OCCLUSION), "{rule}");
        let bounce = renderer.second_bounce().unwrap();
        assert!(bounce.read_moments(&gpu).unwrap().is_none(), "{rule}: no moments for the brute force");
        let all = renderer.read_vals(&gpu).unwrap();
        let cpu_candidates = twin::candidate_vals(&points, &all[..all.len() - 48], None);
        for (k, (g, c)) in bounce.read_candidates(&gpu).unwrap().iter().zip(&cpu_candidates).enumerate() {
            assert!((g.flux - c.flux).abs().max_element() <= 1e-4 * largest, "{rule} point {k}: GPU {g:?} CPU {c:?}");
        }
    }
    // Visibility off: no occlusion stage.
    let scene = small_scene_with("off", r#""bounces": 2, "second_bounce": {"points": 700, "vals": 48}"#);
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
    assert!(!stage_names(&frame).contains(&stage::BOUNCE2_OCCLUSION));
}

/// A wall lit by a spot light (the first bounce's VALs, at x = -1), a receiving wall facing it
/// (x = 1) and a plate halfway between them covering the receiver's half z > 0: with
/// `visibility: "ism"` the receiver's bounce points that the plate hides from every
/// first-bounce VAL receive ~0 through the imperfect shadow maps, and those it hides from none
/// receive what they receive with visibility off.
///
/// Geometry: the spot lights a disc of radius 0.5 tan 50° = 0.60 m on the wall around z = 0, so
/// a receiver point at z sees VAL z' through the plate's plane at (z + z') / 2: hidden from
/// every VAL for z > 0.60, from none for z < -0.60; points within 0.3 m beyond those are left
/// out (the groups' spread and the lookup's texels). Tolerance: a hidden point keeps at most
/// 2 % of its unoccluded flux (measured: 0 in 8 runs); the maps (64 of 128², 30,000 points
/// each, hard lookup) resolve a plate 1 m away to a few texels. An open point keeps 94-102 %
/// and 99.5 % on average (measured 99.95-99.99 %): it lies on a wall that is itself splatted into every map, and for one
/// to three of the 64 groups its hard lookup finds one of its own wall's points nearer than
/// itself (the slope bias is a fraction of a texel here), which groups depends on the VALs the
/// flux draw picks, and the RSM appends them in no fixed order (8 runs: the worst open point
/// kept 0.957-0.989). With visibility off the hidden points keep all their light, so the test
/// fails.
#[test]
fn plate_hides_bounce_points_through_the_ism() {
    let quad = |corners: [Vec3; 4], normal: Vec3| {
        let [a, b, c, d] = corners;
        let winding = (b - a).cross(c - a).dot(normal);
        let (b, d) = if winding > 0.0 { (b, d) } else { (d, b) };
        [a, b, c, d]
    };
    let v = Vec3::new;
    let quads = [
        quad([v(-1.0, 0.0, -2.0), v(-1.0, 0.0, 2.0), v(-1.0, 2.0, 2.0), v(-1.0, 2.0, -2.0)], Vec3::X),
        quad([v(1.0, 0.0, -2.0), v(1.0, 0.0, 2.0), v(1.0, 2.0, 2.0), v(1.0, 2.0, -2.0)], -Vec3::X),
        quad([v(0.0, -0.5, 0.0), v(0.0, -0.5, 2.5), v(0.0, 2.5, 2.5), v(0.0, 2.5, 0.0)], -Vec3::X),
    ];
    let mut obj = String::new();
    for (q, corners) in quads.iter().enumerate() {
        for p in corners {
            obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
        }
        let base = 4 * q + 1;
        obj += &format!("f {} {} {} {}\n", base, base + 1, base + 2, base + 3);
    }
    let scene = |visibility: &str| {
        let json = serde_json::json!({
            "meshes": [{ "obj": "plate.obj", "obj_text": obj, "sparse_points": 2000,
                         "material": { "diffuse": [0.8, 0.8, 0.8] } }],
            "light": { "position": [-0.5, 1.0, 0.0], "direction": [-1, 0, 0], "inner_angle_deg": 45,
                       "outer_angle_deg": 50, "intensity": [5, 5, 5] },
            "camera": { "position": [0, 1, -3], "target": [0, 1, 0], "fov_y_deg": 60, "width": 8, "height": 8 },
            "settings": { "bounces": 2,
                          "tuning": { "rsm_resolution": 32, "visibility": visibility,
                                      "ism": { "count": 64, "resolution": 128, "points": 30000, "soft": "hard" },
                                      "second_bounce": { "points": 4096, "vals": 64 } } }
        });
        Scene::from_json_str(&json.to_string(), std::path::Path::new(".")).expect("plate scene")
    };
    let gpu = gpu();
    let candidates = |visibility: &str| {
        let mut renderer = Renderer::new(&gpu, &scene(visibility)).unwrap();
        renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
        let b = renderer.second_bounce().unwrap();
        assert_eq!(b.visibility().is_some(), visibility == "ism");
        b.read_candidates(&gpu).unwrap()
    };
    let (through, open) = (candidates("ism"), candidates("off"));
    let (mut hidden, mut seen, mut open_kept) = (0, 0, 0.0f64);
    for (t, o) in through.iter().zip(&open) {
        assert!((t.position - o.position).length() < 1e-6, "the same points");
        let on_receiver = (o.position.x - 1.0).abs() < 1e-3;
        let (y, z) = (relume::twin::luminance(t.flux), relume::twin::luminance(o.flux));
        if !on_receiver || z <= 0.0 {
            continue;
        }
        if o.position.z > 0.9 {
            hidden += 1;
            assert!(y <= 0.02 * z, "hidden at {}: {y} of {z}", o.position);
        } else if o.position.z < -0.9 {
            seen += 1;
            open_kept += f64::from(y / z);
            assert!(y <= 1.02 * z && y >= 0.94 * z, "open at {}: {y} vs {z}", o.position);
        }
    }
    let open_kept = open_kept / f64::from(seen.max(1));
    eprintln!("{hidden} hidden and {seen} open receiver points; the open ones keep {open_kept:.4} on average");
    assert!(hidden > 100 && seen > 100, "{hidden} hidden, {seen} open");
    assert!(open_kept >= 0.995, "open points keep {open_kept} of their light on average");
}
