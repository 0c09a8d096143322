//! Diffuse textures (`map_Kd`): the GPU's sampled albedo against the CPU twin's bilinear sample.

use super::{assert_close, gpu, scratch};
use relume::renderer::{Method, Renderer};
use relume::scene::Scene;
use relume::twin;

/// A textured floor under a spot light. The direct pass applies the sampled albedo, so the
/// direct image against `twin::rsm::direct_radiance` with `FlatScene::surface_at` (which
/// samples with `twin::sample_bilinear`) checks texture coordinates, the v flip, sRGB
/// decoding and filtering. Tolerance 1 % of the image maximum: GPUs (lavapipe included) filter
/// with 8-bit sub-texel weights, an error of up to 1/256 of the contrast between texels, and
/// the spot's falloff differs by ~1e-4 as in the other twins.
#[test]
fn textured_albedo_matches_cpu_twin() {
    let dir = scratch("textures");
    let mut img = image::RgbaImage::new(8, 4);
    for (x, y, p) in img.enumerate_pixels_mut() {
        *p = if (x + y) % 2 == 0 { image::Rgba([250, 40, 40, 255]) } else { image::Rgba([30, 60, 220, 255]) };
    }
    img.save(dir.join("checker.png")).unwrap();
    std::fs::write(dir.join("floor.mtl"), "newmtl floor\nKd 0.9 0.9 0.9\nmap_Kd checker.png\n").unwrap();
    std::fs::write(
        dir.join("floor.obj"),
        "mtllib floor.mtl\nv -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nvt 0 1\nvt 2 1\nvt 2 0\nvt 0 0\nvn 0 1 0\n\
         usemtl floor\nf 1/1/1 3/3/1 2/2/1\nf 1/1/1 4/4/1 3/3/1\n",
    )
    .unwrap();
    let json = r#"{
        "meshes": [{ "obj": "floor.obj", "sparse_points": 64 }],
        "light": { "position": [0, 1.5, 0], "direction": [0, -1, 0], "inner_angle_deg": 40, "outer_angle_deg": 50, "intensity": [5, 5, 5] },
        "camera": { "position": [0, 2.5, 2.0], "target": [0, 0, 0], "fov_y_deg": 50, "width": 48, "height": 48 },
        "settings": { "tuning": { "rsm_resolution": 32 } }
    }"#;
    let scene = Scene::from_json_str(json, &dir).unwrap();
    assert_eq!(scene.textures.len(), 1);
    let gpu = gpu();
    let mut renderer = Renderer::new(&gpu, &scene).unwrap();
    assert!(renderer.scene.textured());
    let frame = renderer.render(&gpu, Method::Sparse, 48, 48).unwrap();
    let hits = renderer.camera_view().unwrap().read(&gpu).unwrap();
    let flat = &renderer.scene.flat;
    let (eye, spot) = (renderer.view().eye(), renderer.spot().unwrap());
    let expected = super::per_hit(flat, &hits, |p, n, surface| twin::rsm::direct_radiance(p, n, surface, eye, &spot));
    let scale = expected.iter().flatten().map(|v| v.max_element()).fold(0.0, f32::max);
    let (mut reddish, mut bluish) = (0, 0);
    for (i, e) in expected.iter().enumerate() {
        let Some(e) = e else { continue };
        let got = frame.direct.rgb(i);
        if got.max_element() > 0.0 {
            assert_close(got, *e, 1e-2, scale, 1e-9, &format!("textured direct pixel {i}"));
            reddish += usize::from(got.x > 2.0 * got.z);
            bluish += usize::from(got.z > 2.0 * got.x);
        }
    }
    assert!(reddish > 20 && bluish > 20, "both checker colours must show: {reddish} red, {bluish} blue");
}
