//! The renderer at extreme scene scales: `cornell_bunny_small.json` scaled as a whole by `s`
//! (every mesh's translation and scale, the camera's position and target, the light's
//! position; the intensity kept) renders `1/s²` as bright, its direct and its indirect image
//! alike, at every scale the loader accepts, and one step beyond each of its bounds is refused
//! with an error naming the field (`MIN_SCENE_EXTENT_M`, `MAX_SCENE_EXTENT_M`,
//! `MESH_SCALE_RANGE`).
//!
//! Measured on lavapipe at 24², relative to `s = 1` (sum × s²): direct and indirect each
//! within 1 % from `s = 1e-4` to `1.5e6` (at most 0.8 %, the direct image at `1e5`); at `1e-5` the direct light was black (the spot's
//! inverse-square law is clamped at `twin::MIN_LIGHT_DISTANCE`, 0.1 mm, which also shortens
//! its direction out of the cone), at `1e-8` the whole image (the camera's far plane floored
//! at 1 mm put its near plane past the scene), and from `1.7e6` the indirect image is 8-11 %
//! too bright, the brute force's too (the RSM's VALs, not the sparse interpolation) and the
//! direct image 1 % too dark.

use super::{fixture, gpu};
use relume::gpu::Gpu;
use relume::image::LinearImage;
use relume::renderer::{Method, Renderer};
use relume::scene::{
    MAX_SCENE_EXTENT_M, MESH_SCALE_RANGE, MIN_SCENE_EXTENT_M, ScaleDescription, Scene, SceneDescription, SceneError,
};

/// Image side, pixels: small, to stay fast on lavapipe.
const SIDE: u32 = 24;

/// Largest relative difference of an image's sum × s² from the sum at `s = 1`. Measured over
/// the accepted scales: at most 0.8 % (the direct image at `1e5`), the indirect 0.3 %.
const TOLERANCE: f64 = 0.01;

/// The scales swept: powers of ten, the smallest and largest the bounds accept for this scene
/// (its box's diagonal is 3.49 m at `s = 1`).
const SCALES: [f64; 9] = [1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3, 1e4, 1e5];

fn description() -> SceneDescription {
    let text = std::fs::read_to_string(fixture("scenes/cornell_bunny_small.json")).expect("fixture");
    SceneDescription::from_json_str(&text).expect("parses")
}

fn times(scale: ScaleDescription, s: f64) -> ScaleDescription {
    let k = |x: f32| (f64::from(x) * s) as f32;
    match scale {
        ScaleDescription::Uniform(x) => ScaleDescription::Uniform(k(x)),
        ScaleDescription::PerAxis(x) => ScaleDescription::PerAxis(x.map(k)),
    }
}

/// The fixture scaled by `s` about the origin: every mesh's transform, the light's position,
/// the camera's position and target.
fn scaled(s: f64) -> SceneDescription {
    let mut d = description();
    assert!(d.anchor.is_none(), "the fixture has no anchor");
    for mesh in &mut d.meshes {
        let t = &mut mesh.transform;
        t.translation = t.translation.map(|x| x * s);
        t.scale = times(t.scale, s);
    }
    if let Some(light) = d.light.as_mut() {
        light.position = light.position.map(|x| x * s);
    }
    d.camera.position = d.camera.position.map(|x| x * s);
    d.camera.target = d.camera.target.map(|x| x * s);
    d
}

fn load(description: &SceneDescription) -> Result<Scene, SceneError> {
    Scene::from_description(description, &fixture("scenes"))
}

fn sum(image: &LinearImage) -> f64 {
    image.pixels.iter().map(|p| f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2])).sum()
}

/// The direct and the indirect image's sums at scale `s`, times `s²`.
fn sums(gpu: &Gpu, s: f64) -> (f64, f64) {
    let scene = load(&scaled(s)).unwrap_or_else(|e| panic!("scale {s:e} is refused: {e}"));
    let mut renderer = Renderer::new(gpu, &scene).expect("renderer");
    let frame = renderer.render(gpu, Method::Sparse, SIDE, SIDE).expect("renders");
    (sum(&frame.direct) * s * s, sum(&frame.indirect) * s * s)
}

#[test]
fn the_scene_scaled_renders_one_over_s_squared_as_bright_at_every_accepted_scale() {
    let gpu = gpu();
    let (direct, indirect) = sums(&gpu, 1.0);
    assert!(direct > 0.0 && indirect > 0.0, "the fixture is lit: direct {direct}, indirect {indirect}");
    let mut failures = Vec::new();
    for s in SCALES {
        let (d, i) = sums(&gpu, s);
        let (d, i) = (d / direct, i / indirect);
        eprintln!("scale {s:e}: direct × s² {d:.4}, indirect × s² {i:.4} of scale 1's");
        if (d - 1.0).abs() > TOLERANCE || (i - 1.0).abs() > TOLERANCE {
            failures.push(format!("scale {s:e}: direct {d:.4}, indirect {i:.4}"));
        }
    }
    assert!(failures.is_empty(), "off the 1/s² law by more than {TOLERANCE}: {failures:?}");
}

/// The error loading `description`, which must be refused.
fn refused(description: &SceneDescription, what: &str) -> SceneError {
    match load(description) {
        Ok(_) => panic!("{what} is accepted"),
        Err(e) => {
            eprintln!("{what}: {e}");
            e
        }
    }
}

#[test]
fn one_step_beyond_each_bound_is_refused_naming_the_field() {
    // The sweep's ends are the last powers of ten within the extent's bounds.
    let diagonal = |s: f64| {
        let scene = load(&scaled(s)).expect("accepted");
        let (lo, hi) = scene
            .meshes
            .iter()
            .flat_map(|m| m.positions.iter().map(|&p| m.model_to_world.transform_point3(p)))
            .fold((glam::Vec3::splat(f32::INFINITY), glam::Vec3::splat(f32::NEG_INFINITY)), |(lo, hi), p| {
                (lo.min(p), hi.max(p))
            });
        f64::from(lo.distance(hi))
    };
    let (smallest, largest) = (SCALES[0], SCALES[SCALES.len() - 1]);
    assert!(diagonal(smallest) >= MIN_SCENE_EXTENT_M && diagonal(smallest) < 10.0 * MIN_SCENE_EXTENT_M);
    assert!(diagonal(largest) <= MAX_SCENE_EXTENT_M && diagonal(largest) > MAX_SCENE_EXTENT_M / 10.0);
    // Too small, the meshes together are named; too large, the box, which alone spans more.
    for (s, field) in [(smallest / 10.0, "meshes"), (largest * 10.0, "meshes[0]")] {
        let e = refused(&scaled(s), &format!("the scene scaled by {s:e}"));
        assert_eq!(e.field_path(), Some(field), "{e}");
        assert!(e.to_string().contains("bounding box"), "{e}");
    }
    // A mesh's scale beyond its own bounds, or not finite (1e39 is infinite as an f32), names
    // the scale, before any file is read.
    let (lo, hi) = MESH_SCALE_RANGE;
    for (scale, field) in [
        (ScaleDescription::Uniform(1e30), "meshes[0].transform.scale"),
        (ScaleDescription::Uniform(hi * 10.0), "meshes[0].transform.scale"),
        (ScaleDescription::Uniform(lo / 10.0), "meshes[0].transform.scale"),
        (ScaleDescription::PerAxis([1.0, 1.0, f32::INFINITY]), "meshes[0].transform.scale[2]"),
        (ScaleDescription::PerAxis([1.0, hi * 10.0, 1.0]), "meshes[0].transform.scale[1]"),
    ] {
        let mut d = description();
        d.meshes[0].transform.scale = scale;
        let e = refused(&d, &format!("scale {scale:?}"));
        assert_eq!(e.field_path(), Some(field), "{e}");
    }
    let json = std::fs::read_to_string(fixture("scenes/cornell_bunny_small.json")).expect("fixture");
    let json = json.replacen(r#""sparse_points": 512"#, r#""transform": {"scale": 1e39}, "sparse_points": 512"#, 1);
    let e = refused(&SceneDescription::from_json_str(&json).expect("parses"), "scale 1e39 in JSON");
    assert_eq!(e.field_path(), Some("meshes[0].transform.scale"), "{e}");
    assert!(e.to_string().contains("finite"), "{e}");
    // Within the scale's bounds but far apart: the extent is what is refused.
    let mut d = description();
    d.meshes[1].transform.translation = [MAX_SCENE_EXTENT_M, 0.0, 0.0];
    let e = refused(&d, "the bunny 1,000 km from the box");
    assert_eq!(e.field_path(), Some("meshes"), "{e}");
    // A mesh that alone spans too much, or is the whole scene, is named.
    let mut d = scaled(smallest / 10.0);
    d.meshes.truncate(1);
    assert_eq!(refused(&d, "the box alone, 0.35 mm").field_path(), Some("meshes[0]"));
    let mut d = description();
    d.meshes[1].transform.scale = ScaleDescription::Uniform(1e7);
    assert_eq!(refused(&d, "a bunny over 1,000 km").field_path(), Some("meshes[1]"));
}
