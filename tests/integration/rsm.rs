//! The RSM against closed forms (docs/design.md §2).

use super::{gpu, scratch};
use glam::Vec3;
use relume::gpu::Gpu;
use relume::renderer::{Method, Renderer};
use relume::scene::Scene;
use relume::scene::SpotLight;
use relume::twin::rsm::{rsm_texel_direction, rsm_texel_ndc, spot_cone_flux};

/// The scene `json`, whose mesh is `plane.obj` (a 200 m square at y = 0, facing up), loaded
/// from a scratch directory `name` and rendered once at 8x8 with the sparse method.
fn rendered_over_plane(name: &str, json: &str) -> (Gpu, Renderer) {
    let dir = scratch(name);
    std::fs::write(dir.join("plane.obj"), "v -100 0 -100\nv 100 0 -100\nv 100 0 100\nv -100 0 100\nf 1 3 2\nf 1 4 3\n")
        .unwrap();
    let scene = Scene::from_json_str(json, &dir).unwrap();
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    renderer.render(&gpu, Method::Sparse, 8, 8).unwrap();
    (gpu, renderer)
}

/// A spot aimed straight down at a large plane: every ray of the cone hits the plane, so the
/// VALs' total flux is `rho_d * I * 2 pi * integral falloff sin` (§2). Tolerance 0.5 %: the RSM
/// samples the falloff and `cos^3` at texel centres, a midpoint rule whose error at R = 256 is
/// ~1e-4, plus float accumulation over 50k texels.
#[test]
fn rsm_flux_equals_analytic_cone_flux_on_a_plane() {
    let json = r#"{
        "meshes": [{ "obj": "plane.obj", "sparse_points": 16, "material": { "diffuse": [0.8, 0.5, 0.2] } }],
        "light": { "position": [0, 2, 0], "direction": [0, -1, 0], "inner_angle_deg": 20, "outer_angle_deg": 35, "intensity": [3, 2, 1] },
        "camera": { "position": [0, 5, 5], "target": [0, 0, 0], "fov_y_deg": 45, "width": 8, "height": 8 },
        "settings": { "tuning": { "rsm_resolution": 256 } }
    }"#;
    let (gpu, renderer) = rendered_over_plane("rsm_plane", json);
    let total: Vec3 = renderer.read_vals(&gpu).unwrap().iter().map(|v| v.flux).sum();
    let spot = SpotLight {
        position: Vec3::new(0.0, 2.0, 0.0),
        direction: -Vec3::Y,
        inner_angle: 20f32.to_radians(),
        outer_angle: 35f32.to_radians(),
        intensity: Vec3::new(3.0, 2.0, 1.0),
        up: Vec3::Z,
    };
    let want = Vec3::new(0.8, 0.5, 0.2) * spot_cone_flux(&spot, 100_000);
    let err = ((total - want) / want).abs().max_element();
    assert!(err <= 0.005, "VAL flux {total} vs analytic {want}: {:.3} % off", err * 100.0);
}

/// The light's `up` orients the RSM grid: with the grid turned 45° about the axis (and tilted
/// off the world's axes), every texel's hit on the plane lies on the direction the CPU twin
/// gives that texel (within 1e-4 rad: f32 raster), which the default up would miss by ~45°.
#[test]
fn rsm_grid_follows_the_lights_up() {
    let json = r#"{
        "meshes": [{ "obj": "plane.obj", "sparse_points": 16 }],
        "light": { "position": [0, 2, 0], "direction": [0.1, -1, 0.05], "up": [1, 0.3, 1],
                   "inner_angle_deg": 20, "outer_angle_deg": 35, "intensity": [1, 1, 1] },
        "camera": { "position": [0, 5, 5], "target": [0, 0, 0], "fov_y_deg": 45, "width": 8, "height": 8 },
        "settings": { "tuning": { "rsm_resolution": 32 } }
    }"#;
    let (gpu, renderer) = rendered_over_plane("rsm_up", json);
    let spot = renderer.spot().unwrap();
    assert!(spot.up.abs_diff_eq(Vec3::new(1.0, 0.3, 1.0).normalize(), 1e-6), "{}", spot.up);
    let view = renderer.rsm_view().unwrap();
    let r = view.width;
    let mut worst = 0.0f32;
    for (t, hit) in view.read(&gpu).unwrap().iter().enumerate() {
        let h = hit.expect("every texel sees the plane");
        let (y, _, _) = renderer.scene.flat.surface_at(h.triangle, h.barycentrics);
        let twin = rsm_texel_direction(rsm_texel_ndc(t as u32 % r, t as u32 / r, r), &spot);
        // sin of the angle (acos near 1 resolves only ~3e-4 in f32).
        worst = worst.max((y - spot.position).normalize().cross(twin).length());
    }
    assert!(worst <= 1e-4, "worst angle between the GPU's texel and the twin's: {worst} rad");
}
