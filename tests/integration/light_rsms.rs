//! VALs from the RSMs of the scene's `lights` (`gpu::lights::light_rsms`, README "Many direct
//! lights") against their CPU twins (`twin::light_rsms`) on the GPU's own atlas, their total
//! flux in a closed box against the light's power, every indirect method taking them, and a
//! scene without `lights` keeping its stages and VALs.

use super::{gpu, load_scene, scratch};
use glam::Vec3;
use relume::gpu::lights::light_rsms::{RASTER_STAGE, VALS_STAGE};
use relume::renderer::{Components, Method, Renderer};
use relume::scene::{DirectSettings, Light, PointLight, Scene, SpotLight};
use relume::twin::Val;
use relume::twin::light_rsms::view_texel_val;
use relume::twin::rsm::rsm_texel_ndc;

/// Three point lights (one with a range) and a spot in the Cornell box of
/// `cornell_bunny_small`, without its `light`: flux 0.6 : 1.2 : 2.4 (x 4 pi) and the spot's.
fn lights() -> Vec<Light> {
    let point = |p: Vec3, i: f32, range: Option<f32>| {
        Light::Point(PointLight { position: p, intensity: Vec3::new(i, 0.8 * i, 0.6 * i), range })
    };
    vec![
        point(Vec3::new(-0.5, 1.5, 0.2), 0.6, None),
        point(Vec3::new(0.45, 1.3, -0.3), 1.2, Some(1.5)),
        point(Vec3::new(0.0, 1.8, 0.0), 2.4, None),
        Light::Spot(SpotLight {
            position: Vec3::new(0.6, 1.6, 0.6),
            direction: Vec3::new(-1.6, -0.3, -0.8).normalize(),
            inner_angle: 15f32.to_radians(),
            outer_angle: 25f32.to_radians(),
            intensity: Vec3::splat(10.0),
            up: Vec3::Y,
        }),
    ]
}

fn scene_with_lights(budget: u32) -> Scene {
    let mut scene = load_scene("cornell_bunny_small");
    scene.light = None;
    scene.lights = super::local_lights(&scene, lights());
    scene.settings.direct = DirectSettings { val_budget: budget, ..DirectSettings::default() };
    scene
}

fn stage_names(frame: &relume::renderer::Rendered) -> Vec<String> {
    frame.timings.stages.iter().map(|(n, _)| n.clone()).collect()
}

/// The twin's VALs from the GPU's atlas: every texel of every view that sees a surface, with
/// flux.
fn twin_vals(renderer: &Renderer, gpu: &relume::gpu::Gpu) -> Vec<Val> {
    let rsms = renderer.light_rsms().expect("the scene has lights");
    let atlas = rsms.read_atlas(gpu).unwrap();
    let width = rsms.atlas_size[0];
    let flat = &renderer.scene.flat;
    let mut vals = Vec::new();
    for placed in &rsms.views {
        let r = placed.view.resolution;
        for iy in 0..r {
            for ix in 0..r {
                let texel = ((placed.origin[1] + iy) * width + placed.origin[0] + ix) as usize;
                let Some(hit) = atlas[texel] else { continue };
                let (y, n, m) = flat.surface_at(hit.triangle, hit.barycentrics);
                let val = view_texel_val(rsm_texel_ndc(ix, iy, r), &placed.view, y, n, m.diffuse);
                if val.flux.max_element() > 0.0 {
                    vals.push(val);
                }
            }
        }
    }
    vals
}

/// The GPU's VALs (appended in any order) match the twin's on the GPU's own atlas, one to one:
/// each twin VAL is paired with the GPU VAL nearest its position (the GPU and CPU interpolate
/// the same barycentrics, so positions agree to ~1e-6 m, far below the texels' spacing), and
/// flux and area must agree to 1e-4 relative (f32 `inverseSqrt`, `tan` and `atan2` on lavapipe
/// against Rust's, a few ulp each, through products of a handful of factors) plus 1e-9 of the
/// largest (a texel on the spot's falloff edge may round either side of it).
#[test]
fn light_rsm_vals_match_their_twin() {
    let gpu = gpu();
    let scene = scene_with_lights(900);
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
    let stages = stage_names(&frame);
    assert!(stages.iter().any(|s| s == RASTER_STAGE) && stages.iter().any(|s| s == VALS_STAGE), "{stages:?}");
    let rsms = renderer.light_rsms().unwrap();
    // Budget 900 split by flux: the texels stay within it.
    assert!(rsms.texels <= 900, "{} texels", rsms.texels);
    assert_eq!(rsms.views.len(), 3 * 6 + 1);
    let gpu_vals = renderer.read_vals(&gpu).unwrap();
    let twin = twin_vals(&renderer, &gpu);
    assert!(twin.len() > 400, "most texels see the box: {}", twin.len());
    assert_eq!(gpu_vals.len(), twin.len(), "VAL count");
    let peak = twin.iter().map(|v| v.flux.max_element()).fold(0.0f32, f32::max);
    let mut used = vec![false; gpu_vals.len()];
    for t in &twin {
        let (k, g) = gpu_vals
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.position.distance(t.position).total_cmp(&b.1.position.distance(t.position)))
            .unwrap();
        assert!(g.position.distance(t.position) < 1e-4, "{} vs {}", g.position, t.position);
        assert!(!used[k], "two twin VALs on one GPU VAL at {}", t.position);
        used[k] = true;
        let tol = 1e-4 * t.flux.max_element() + 1e-9 * peak;
        assert!((g.flux - t.flux).abs().max_element() <= tol, "flux {} vs {}", g.flux, t.flux);
        assert!((g.area - t.area).abs() <= 1e-4 * t.area, "area {} vs {}", g.area, t.area);
        assert!(g.normal.dot(t.normal) > 0.9999, "normal {} vs {}", g.normal, t.normal);
    }
}

/// A point light inside a closed box of albedo 0.5 (2 m cube, 12 triangles): every direction
/// meets a wall, so the VALs' flux is 0.5 x 4 pi I, whatever the light's share: one texel per
/// face (budget 6) and 32² per face (budget 6144). Tolerance 1e-3: the six faces' rescaled
/// solid angles sum to 4 pi in f32 (~1e-6), the perspective raster covers every texel once,
/// and the sum of up to 6144 f32 fluxes (~1e-5); what is left is lavapipe's `inverseSqrt`
/// against the CPU's rescale (a few 1e-6).
#[test]
fn point_light_in_a_closed_box_reflects_albedo_times_power() {
    let dir = scratch("light_rsms_box");
    let mut obj = String::new();
    for x in [-1, 1] {
        for y in [-1, 1] {
            for z in [-1, 1] {
                obj += &format!("v {x} {y} {z}\n");
            }
        }
    }
    // Vertex (x, y, z) is 1 + 4 (x > 0) + 2 (y > 0) + (z > 0).
    obj +=
        "f 1 2 4\nf 1 4 3\nf 5 7 8\nf 5 8 6\nf 1 5 6\nf 1 6 2\nf 3 4 8\nf 3 8 7\nf 1 3 7\nf 1 7 5\nf 2 6 8\nf 2 8 4\n";
    std::fs::write(dir.join("box.obj"), obj).unwrap();
    let intensity = Vec3::new(2.0, 1.0, 0.5);
    for budget in [6u32, 6 * 32 * 32] {
        let json = format!(
            r#"{{
            "meshes": [{{ "obj": "box.obj", "sparse_points": 64, "material": {{ "diffuse": [0.5, 0.5, 0.5] }} }}],
            "lights": [{{ "type": "point", "position": [0.1, -0.2, 0.15], "intensity": [2, 1, 0.5] }}],
            "camera": {{ "position": [0, 0, 0.9], "target": [0, 0, 0], "fov_y_deg": 60, "width": 8, "height": 8 }},
            "settings": {{ "tuning": {{ "direct": {{ "val_budget": {budget} }} }} }}
        }}"#
        );
        let scene = Scene::from_json_str(&json, &dir).unwrap();
        let gpu = gpu();
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        let frame = renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
        let texels = renderer.light_rsms().unwrap().texels;
        assert_eq!(texels, budget, "one light takes the whole budget");
        assert_eq!(frame.val_count, budget, "every texel sees a wall");
        let total: Vec3 = renderer.read_vals(&gpu).unwrap().iter().map(|v| v.flux).sum();
        let want = 0.5 * 4.0 * std::f32::consts::PI * intensity;
        let err = ((total - want) / want).abs().max_element();
        assert!(err <= 1e-3, "budget {budget}: VAL flux {total} vs rho x power {want}: {:.4} % off", err * 100.0);
    }
}

/// Every indirect method and the direct-only frame (whose VALs the CPU exact reference reads)
/// get the lights' VALs: the same count, and light in the indirect image.
#[test]
fn every_method_takes_the_lights_vals() {
    let gpu = gpu();
    let scene = scene_with_lights(600);
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let mut counts = Vec::new();
    for method in [Method::Sparse, Method::BruteForce, Method::Exact] {
        let frame = renderer.render(&gpu, method, 16, 16).unwrap();
        let peak = (0..frame.indirect.pixels.len()).map(|i| frame.indirect.rgb(i).max_element()).fold(0.0, f32::max);
        assert!(peak > 0.0, "{method:?}: indirect light from the lights' VALs");
        counts.push(frame.val_count);
    }
    let direct = renderer.render_components(&gpu, Method::Sparse, 16, 16, Components::DIRECT).unwrap();
    counts.push(direct.val_count);
    assert!(counts[0] > 0 && counts.iter().all(|&c| c == counts[0]), "{counts:?}");
}

/// A scene without `lights` has none of the lights' RSM stages and no VALs but its spot's.
#[test]
fn scene_without_lights_has_no_light_rsms() {
    let gpu = gpu();
    let scene = load_scene("cornell_bunny_small");
    assert!(scene.lights.is_empty());
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    assert!(renderer.light_rsms().is_none());
    let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
    let stages = stage_names(&frame);
    assert!(!stages.iter().any(|s| s.starts_with("lights_rsm")), "{stages:?}");
    assert!(frame.val_count <= 32 * 32, "the spot's RSM alone: {}", frame.val_count);
    assert_eq!(renderer.val_capacity(), 32 * 32, "the VAL buffer holds the spot's RSM alone");
}

/// The VALs as sortable bit patterns (the GPU appends them in any order).
fn sorted_bits(vals: &[Val]) -> Vec<[u32; 10]> {
    let mut bits: Vec<[u32; 10]> = vals
        .iter()
        .map(|v| {
            let [p, n, f] = [v.position, v.normal, v.flux].map(|x| x.to_array().map(f32::to_bits));
            [p[0], p[1], p[2], n[0], n[1], n[2], v.area.to_bits(), f[0], f[1], f[2]]
        })
        .collect();
    bits.sort_unstable();
    bits
}

/// The cull of the RSM views (`raster::cull`, docs/measurements/many-lights.md "VALs from every light's RSM") changes the
/// raster's work, not its VALs: with the lights above plus a point light of range 0.4 m near the
/// floor, the culled frame draws far fewer triangles (the range drops some that the frustum
/// keeps), the atlas of every view without a range is the same texel for texel, and the VALs
/// are the same bit for bit. Exact equality: the drawn triangles keep their order, and a dropped
/// one made no fragment in its view (or, beyond the range, only texels without flux).
#[test]
fn culled_rsm_views_make_the_same_vals() {
    use relume::gpu::raster::cull::TriangleChunks;
    let gpu = gpu();
    let mut scene = load_scene("cornell_bunny_small");
    scene.light = None;
    let mut all = lights();
    let short =
        Light::Point(PointLight { position: Vec3::new(-0.2, 0.25, 0.2), intensity: Vec3::ONE, range: Some(0.4) });
    all.push(short);
    scene.lights = super::local_lights(&scene, all);
    scene.settings.direct = DirectSettings { val_budget: 3000, ..DirectSettings::default() };
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let mut runs = Vec::new();
    for culling in [false, true] {
        renderer.light_rsms_mut().unwrap().set_culling(culling);
        renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
        let rsms = renderer.light_rsms().unwrap();
        let draws = rsms.draws(&renderer.scene, &rsms.raw_views(&renderer.scene));
        let drawn: u32 = draws.iter().flatten().map(|r| r.end - r.start).sum();
        runs.push((sorted_bits(&renderer.read_vals(&gpu).unwrap()), rsms.read_atlas(&gpu).unwrap(), drawn, draws));
    }
    let rsms = renderer.light_rsms().unwrap();
    let triangles = renderer.scene.flat.triangle_count();
    assert_eq!(runs[0].2, triangles * rsms.views.len() as u32, "without the cull every view draws everything");
    assert!(runs[1].2 * 2 < runs[0].2, "the cull drops most: {} of {}", runs[1].2, runs[0].2);
    // The short light's views: the range drops what the frustum alone keeps.
    let chunks = TriangleChunks::new(&renderer.scene.flat);
    let raw = rsms.raw_views(&renderer.scene);
    let short_light = (scene.lights.len() - 1) as u32;
    let (mut frustum_only, mut with_range) = (0, 0);
    for (k, placed) in rsms.views.iter().enumerate().filter(|(_, p)| p.light == short_light) {
        let m = glam::Mat4::from_cols_array_2d(&raw[k].world_to_clip);
        frustum_only += chunks.visible(m, None).iter().map(|r| r.end - r.start).sum::<u32>();
        with_range += runs[1].3[k].iter().map(|r| r.end - r.start).sum::<u32>();
        assert_eq!(placed.view.range, Some(0.4));
    }
    assert!(with_range < frustum_only, "range 0.4 m: {with_range} vs {frustum_only} triangles");
    let width = rsms.atlas_size[0];
    for placed in rsms.views.iter().filter(|p| p.view.range.is_none()) {
        let r = placed.view.resolution;
        for iy in 0..r {
            for ix in 0..r {
                let texel = ((placed.origin[1] + iy) * width + placed.origin[0] + ix) as usize;
                assert_eq!(runs[0].1[texel], runs[1].1[texel], "light {} texel ({ix}, {iy})", placed.light);
            }
        }
    }
    assert!(runs[0].0.len() > 1000, "{} VALs", runs[0].0.len());
    assert!(runs[0].0 == runs[1].0, "VALs differ: {} unculled, {} culled", runs[0].0.len(), runs[1].0.len());
}

/// The scene's `light` stays outside `settings.direct.val_budget` (its RSM is also its direct
/// shadow map): with `lights` beside it, its RSM keeps `rsm_resolution`² texels, the lights
/// share the budget alone, and the frame's VALs stay within the bound the service admits
/// (`frame_val_parts`: the RSM's texels plus the budget), which the VAL buffer holds exactly.
#[test]
fn the_scenes_light_keeps_its_rsm_beside_the_budget() {
    let gpu = gpu();
    let mut scene = load_scene("cornell_bunny_small");
    assert!(scene.light.is_some());
    scene.lights = super::local_lights(&scene, lights());
    scene.settings.direct = DirectSettings { val_budget: 600, ..DirectSettings::default() };
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    let frame = renderer.render(&gpu, Method::Sparse, 16, 16).unwrap();
    let texels = renderer.light_rsms().unwrap().texels;
    assert!(texels <= 600 && texels > 300, "the lights' texels: {texels}");
    let rsm = scene.settings.rsm_resolution;
    assert_eq!(renderer.val_capacity(), rsm * rsm + texels, "the spot's RSM at rsm_resolution² beside the lights'");
    let bound: u64 = relume::scene::frame_val_parts(true, true, rsm, 600, None).iter().map(|(_, n)| n).sum();
    assert_eq!(bound, u64::from(rsm * rsm) + 600);
    assert!(u64::from(frame.val_count) <= bound, "{} VALs over the bound {bound}", frame.val_count);
    // More than the lights alone could make: the spot's VALs are there too.
    assert!(frame.val_count > texels, "{} VALs, the lights' texels {texels}", frame.val_count);
}
