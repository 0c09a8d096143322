//! Direct light from many lights (`gpu::lights::many`, docs/measurements/many-lights.md) against its
//! CPU twins (`twin::many_lights`) on the GPU's own shadow maps and visibility buffer, in both
//! modes, and against the exact shadow-ray reference.
//!
//! Tolerances: the lookup rounds continuous texel positions down, and lavapipe's projections
//! differ from the CPU's by a few ulp, so a texel exactly on an edge may go either way and flip
//! one light's (or one tap's) visibility at a pixel: 2 % of covered pixels may differ; the
//! others must agree to 1e-3 relative (the other twins' tolerance, `twins.rs`) plus 1e-6 of
//! the image's peak.

use super::{gpu, load_scene};
use glam::Vec3;
use relume::gpu::lights::many::{SHADE_STAGE, SHADOW_MAPS_STAGE};
use relume::image::{LinearImage, relative_rmse};
use relume::renderer::{Components, Method, Renderer};
use relume::scene::{DirectSettings, DirectShadows, Light, PointLight, Scene};
use relume::twin::many_lights::{direct_shadow_mapped, exact_image, image_of};

const SIDE: u32 = 64;

/// Eight point lights in the Cornell box of `cornell_bunny_small`: two tight pairs and a
/// triple (grouped at d_init = 0.3) and a lone one low beside the bunny.
fn lights() -> Vec<Light> {
    let at = |x: f32, y: f32, z: f32| {
        Light::Point(PointLight { position: Vec3::new(x, y, z), intensity: Vec3::splat(0.6), range: Some(4.0) })
    };
    vec![
        at(-0.5, 1.5, 0.2),
        at(-0.4, 1.55, 0.25),
        at(0.45, 1.3, -0.3),
        at(0.5, 1.25, -0.2),
        at(0.0, 1.8, 0.0),
        at(0.1, 1.75, 0.05),
        at(0.05, 1.7, -0.1),
        at(-0.1, 0.35, 0.8),
    ]
}

fn scene_with(shadows: DirectShadows, spot: bool) -> Scene {
    let mut scene = load_scene("cornell_bunny_small");
    if !spot {
        scene.light = None;
    }
    scene.lights = super::local_lights(&scene, lights());
    scene.settings.direct = DirectSettings { shadows, d_init: 0.3, ..DirectSettings::default() };
    scene
}

fn direct(gpu: &relume::gpu::Gpu, renderer: &mut Renderer) -> (LinearImage, Vec<String>) {
    let frame = renderer.render_components(gpu, Method::Sparse, SIDE, SIDE, Components::DIRECT).unwrap();
    (frame.direct, frame.timings.stages.iter().map(|(n, _)| n.clone()).collect())
}

#[test]
fn many_lights_match_cpu_twins_in_both_modes() {
    let gpu = gpu();
    for shadows in [DirectShadows::PerLight, DirectShadows::LightCluster] {
        let scene = scene_with(shadows, false);
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        let (image, stages) = direct(&gpu, &mut renderer);
        assert!(stages.iter().any(|s| s == SHADOW_MAPS_STAGE) && stages.iter().any(|s| s == SHADE_STAGE), "{stages:?}");
        let many = renderer.many_lights().unwrap();
        let expected_groups = if shadows == DirectShadows::PerLight { 8 } else { 4 };
        assert_eq!(many.groups.len(), expected_groups, "{shadows:?}: {:?}", many.groups);
        let maps = many.read_maps(&gpu).unwrap();
        let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
        let eye = renderer.view().eye();
        let (groups, resolution, soft) = (&many.groups, many.map_resolution(), many.soft());
        let twin = image_of(&renderer.scene.flat, &hits, (SIDE, SIDE), eye, |r| {
            direct_shadow_mapped(r, eye, &scene.lights, groups, &maps, resolution, soft)
        });
        let peak = (0..twin.pixels.len()).map(|i| twin.rgb(i).max_element()).fold(0.0f32, f32::max);
        assert!(peak > 0.0, "the lights reach the image");
        let (mut covered, mut off) = (0, 0);
        for i in 0..twin.pixels.len() {
            assert_eq!(image.pixels[i][3], twin.pixels[i][3], "coverage at pixel {i}");
            if twin.pixels[i][3] == 0.0 {
                continue;
            }
            covered += 1;
            let (a, b) = (image.rgb(i), twin.rgb(i));
            if (a - b).abs().max_element() > 1e-3 * a.max(b).max_element() + 1e-6 * peak {
                off += 1;
            }
        }
        assert!(off * 50 <= covered, "{shadows:?}: {off} of {covered} pixels differ from the twin");
        // The shadows are there: the exact reference is darker than no shadows at all, and
        // the shadow maps are nearer the reference than no shadows.
        let exact = exact_image(&renderer.scene.flat, &hits, (SIDE, SIDE), eye, &scene.lights);
        let unshadowed = image_of(&renderer.scene.flat, &hits, (SIDE, SIDE), eye, |r| {
            scene.lights.iter().map(|l| relume::twin::many_lights::unshadowed_radiance(r, eye, l)).sum()
        });
        let (e_maps, e_none) = (relative_rmse(&image, &exact), relative_rmse(&unshadowed, &exact));
        // Inside the box the bunny and the two boxes shadow the lights: 0.0495 without shadows
        // (the maps: 0.014 per light, 0.023 LightCluster).
        assert!(e_none > 0.03, "the lights cast shadows in this scene: {e_none}");
        assert!(e_maps < 0.5 * e_none, "{shadows:?}: rel RMSE vs exact {e_maps}, without shadows {e_none}");
    }
}

/// With a spot `light` too, the pass adds the lights' direct light to the spot's: the sum of
/// the two rendered alone (within float rounding of one addition per pixel).
#[test]
fn lights_add_to_the_spot_lights_direct_light() {
    let gpu = gpu();
    let both = scene_with(DirectShadows::LightCluster, true);
    let mut spot_only = both.clone();
    spot_only.lights.clear();
    let lights_only = scene_with(DirectShadows::LightCluster, false);
    let (sum, _) = direct(&gpu, &mut Renderer::new(&gpu, &both).unwrap());
    let (a, stages) = direct(&gpu, &mut Renderer::new(&gpu, &spot_only).unwrap());
    assert!(!stages.iter().any(|s| s == SHADE_STAGE), "no lights, no many-light stage: {stages:?}");
    let (b, _) = direct(&gpu, &mut Renderer::new(&gpu, &lights_only).unwrap());
    for i in 0..sum.pixels.len() {
        let expected = a.rgb(i) + b.rgb(i);
        assert!(
            (sum.rgb(i) - expected).abs().max_element() <= 1e-5 * expected.max_element() + 1e-12,
            "pixel {i}: {} vs {expected}",
            sum.rgb(i)
        );
    }
}

/// The cull of the lights' shadow maps (`ManyLights::draws`: each map draws the chunks that
/// reach the front of its hemisphere) changes the raster's work, not the light: in both modes
/// the culled frame draws fewer triangles, every map is the same texel for texel (a dropped
/// chunk lies wholly behind the map's plane, past the raster's slack, where no texel's ray
/// goes), and the direct image is the same bit for bit.
#[test]
fn culled_light_maps_give_the_same_direct_light() {
    let gpu = gpu();
    for shadows in [DirectShadows::PerLight, DirectShadows::LightCluster] {
        let scene = scene_with(shadows, false);
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        let mut runs = Vec::new();
        for culling in [false, true] {
            renderer.many_lights_mut().unwrap().set_culling(culling);
            let (image, _) = direct(&gpu, &mut renderer);
            let many = renderer.many_lights().unwrap();
            let drawn: u32 = many.draws(&renderer.scene).iter().flatten().map(|r| r.end - r.start).sum();
            runs.push((image, many.read_maps(&gpu).unwrap(), drawn));
        }
        let maps = 2 * renderer.many_lights().unwrap().groups.len() as u32;
        assert_eq!(runs[0].2, maps * renderer.scene.flat.triangle_count(), "{shadows:?}: unculled draws everything");
        assert!(runs[1].2 * 10 < runs[0].2 * 9, "{shadows:?}: the cull drops some: {} of {}", runs[1].2, runs[0].2);
        assert!(runs[0].1 == runs[1].1, "{shadows:?}: the maps differ");
        let (a, b) = (&runs[0].0, &runs[1].0);
        assert!(a.pixels.iter().any(|p| p[0] > 0.0), "{shadows:?}: the lights light something");
        assert!(a.pixels == b.pixels, "{shadows:?}: the direct images differ");
    }
}

/// Paper 003's view-frustum culling of lights, on the shadow maps: two lights whose `range`
/// spheres lie out of the camera's view (one behind the camera, one beside the frustum) are
/// out of view and their groups draw no map, in both modes; every other group is in view and
/// draws the same maps as without the cull; the direct image is the same bit for bit (an out
/// of view light adds nothing to a visible pixel, so its maps are never looked up).
#[test]
fn lights_out_of_view_draw_no_maps() {
    let gpu = gpu();
    let point = |x: f32, y: f32, z: f32, range: f32| {
        Light::Point(PointLight { position: Vec3::new(x, y, z), intensity: Vec3::splat(0.6), range: Some(range) })
    };
    for shadows in [DirectShadows::PerLight, DirectShadows::LightCluster] {
        let mut scene = scene_with(shadows, false);
        // The camera stands at (0, 1, 3.3) looking down -z with a 38° field of view.
        let mut all = lights();
        all.extend([point(0.0, 1.0, 5.0, 1.0), point(3.0, 1.0, 0.0, 0.5)]);
        scene.lights = super::local_lights(&scene, all);
        let mut renderer = Renderer::new(&gpu, &scene).unwrap();
        let mut runs = Vec::new();
        for culling in [false, true] {
            renderer.many_lights_mut().unwrap().set_light_culling(culling);
            let (image, _) = direct(&gpu, &mut renderer);
            runs.push((image, renderer.many_lights().unwrap().read_maps(&gpu).unwrap()));
        }
        let many = renderer.many_lights().unwrap();
        let seen = many.groups_in_view(renderer.camera_to_clip(SIDE, SIDE));
        let out: Vec<usize> = (0..seen.len()).filter(|&g| !seen[g]).collect();
        let groups_of = |lights: &[usize]| -> Vec<usize> {
            let mut g: Vec<usize> = lights.iter().map(|&l| many.groups.group_of_light[l] as usize).collect();
            g.sort();
            g.dedup();
            g
        };
        assert_eq!(out, groups_of(&[8, 9]), "{shadows:?}: the two lights out of view, alone in their groups");
        let ((unculled, maps_all), (culled, maps_culled)) = (&runs[0], &runs[1]);
        for (g, &in_view) in seen.iter().enumerate() {
            for k in [2 * g, 2 * g + 1] {
                if in_view {
                    assert!(maps_all[k] == maps_culled[k], "{shadows:?}: map {k} of a group in view changed");
                } else {
                    assert!(maps_culled[k].iter().all(|d| d.is_infinite()), "{shadows:?}: map {k} was drawn");
                    assert!(maps_all[k].iter().any(|d| d.is_finite()), "{shadows:?}: map {k} sees the box unculled");
                }
            }
        }
        assert!(unculled.pixels.iter().any(|p| p[0] > 0.0), "{shadows:?}: the lights light something");
        assert!(unculled.pixels == culled.pixels, "{shadows:?}: the direct images differ");
    }
}
