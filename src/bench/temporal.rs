//! Temporal stability: a camera orbit, a moving light and a moving model, a few frames each,
//! rendered with the sparse method and the brute force; the mean frame-to-frame change of the
//! indirect image of each, of their difference, and of the light gathered at the sparse points.

use super::BenchError;
use crate::gpu::Gpu;
use crate::image::LinearImage;
use crate::renderer::{Method, Renderer};
use crate::scene::Scene;
use glam::{Mat4, Quat, Vec3};

/// One motion's figures: each is the mean over consecutive frame pairs of
/// `sum |x_t - x_{t-1}| / sum |x_{t-1}|` (RGB, over pixels covered in both frames).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Motion {
    pub motion: &'static str,
    /// What moves by how much per frame.
    pub step: String,
    /// The sparse method's indirect image.
    pub sparse_image_change: f64,
    /// The brute force's indirect image.
    pub brute_force_image_change: f64,
    /// The error image (sparse − brute force), relative to the brute force image: the change
    /// that is the sparse method's own (flicker), not the scene's.
    pub error_image_change: f64,
    /// The diffuse irradiance gathered at the sparse points (independent of the view).
    pub sparse_point_irradiance_change: f64,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct TemporalReport {
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    pub motions: Vec<Motion>,
    pub note: &'static str,
}

const NOTE: &str = "camera orbit: the image moves, so the image changes measure the motion itself; the \
     sparse points' light must not change (it is gathered in model space, independent of the view), and the \
     error image's change is the part of the change due to the method";

/// Relative L1 change from `prev` to `next` over pixels covered in both.
pub fn image_change(prev: &LinearImage, next: &LinearImage) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for i in 0..prev.pixels.len().min(next.pixels.len()) {
        if prev.covered(i) && next.covered(i) {
            let (a, b) = (prev.rgb(i), next.rgb(i));
            num += (b - a).abs().element_sum() as f64;
            den += a.abs().element_sum() as f64;
        }
    }
    if den > 0.0 { num / den } else { 0.0 }
}

fn values_change(prev: &[Vec3], next: &[Vec3]) -> f64 {
    let num: f64 = prev.iter().zip(next).map(|(a, b)| (*b - *a).abs().element_sum() as f64).sum();
    let den: f64 = prev.iter().map(|a| a.abs().element_sum() as f64).sum();
    if den > 0.0 { num / den } else { 0.0 }
}

fn difference(a: &LinearImage, b: &LinearImage) -> LinearImage {
    let pixels =
        a.pixels.iter().zip(&b.pixels).map(|(p, q)| [p[0] - q[0], p[1] - q[1], p[2] - q[2], p[3].min(q[3])]).collect();
    LinearImage { width: a.width, height: a.height, pixels }
}

struct Frame {
    sparse: LinearImage,
    brute: LinearImage,
    irradiance: Vec<Vec3>,
}

/// Run the three motions on `scene` (which must have a spot light).
pub fn measure(gpu: &Gpu, scene: &Scene, quick: bool) -> Result<TemporalReport, BenchError> {
    let (frames, side) = if quick { (3u32, 16u32) } else { (6, 48) };
    let (_, radius) = Renderer::new(gpu, scene)?.scene.flat.bounding_sphere();
    let light = scene.light.expect("bench scenes have a spot light");
    let camera = scene.camera;
    let orbit_deg = 2.0f32;
    let light_step = 0.02 * radius;
    let model_step = 0.01 * radius;
    let render = |renderer: &mut Renderer| -> Result<Frame, BenchError> {
        let sparse = renderer.render(gpu, Method::Sparse, side, side)?.indirect;
        let irradiance = renderer.read_gathered_irradiance(gpu)?;
        let brute = renderer.render(gpu, Method::BruteForce, side, side)?.indirect;
        Ok(Frame { sparse, brute, irradiance })
    };
    let mut motions = Vec::new();

    // Camera orbit about the vertical through the camera target.
    let mut renderer = Renderer::new(gpu, scene)?;
    let mut orbit = Vec::new();
    for t in 0..frames {
        let rotation = Quat::from_axis_angle(camera.up, (orbit_deg * t as f32).to_radians());
        let mut c = camera;
        c.position = camera.target + rotation * (camera.position - camera.target);
        renderer.set_camera(c);
        orbit.push(render(&mut renderer)?);
    }
    motions.push(summarise("camera_orbit", format!("{orbit_deg} degrees about the target"), &orbit));

    // The spot light translated sideways (perpendicular to its axis and to up).
    let side_dir = light.direction.cross(Vec3::Y).try_normalize().unwrap_or(Vec3::X);
    let mut renderer = Renderer::new(gpu, scene)?;
    let mut moving_light = Vec::new();
    for t in 0..frames {
        let mut l = light;
        l.position += side_dir * light_step * t as f32;
        renderer.set_spot_light(&l);
        moving_light.push(render(&mut renderer)?);
    }
    motions.push(summarise("moving_light", format!("{light_step:.4} m sideways"), &moving_light));

    // The last mesh translated along x; its sparse points move with it (model space).
    let mut moving_model = Vec::new();
    for t in 0..frames {
        let mut s = scene.clone();
        if let Some(mesh) = s.meshes.last_mut() {
            mesh.model_to_world = Mat4::from_translation(Vec3::X * model_step * t as f32) * mesh.model_to_world;
        }
        let mut renderer = Renderer::new(gpu, &s)?;
        moving_model.push(render(&mut renderer)?);
    }
    let name = scene.meshes.last().map_or("", |m| m.name.as_str());
    motions.push(summarise("moving_model", format!("{name} {model_step:.4} m along x"), &moving_model));
    Ok(TemporalReport { frames, width: side, height: side, motions, note: NOTE })
}

fn summarise(motion: &'static str, step: String, frames: &[Frame]) -> Motion {
    let n = frames.len().saturating_sub(1).max(1) as f64;
    let mean = |f: &dyn Fn(&Frame, &Frame) -> f64| frames.windows(2).map(|w| f(&w[0], &w[1])).sum::<f64>() / n;
    Motion {
        motion,
        step,
        sparse_image_change: mean(&|a, b| image_change(&a.sparse, &b.sparse)),
        brute_force_image_change: mean(&|a, b| image_change(&a.brute, &b.brute)),
        error_image_change: mean(&|a, b| {
            let (ea, eb) = (difference(&a.sparse, &a.brute), difference(&b.sparse, &b.brute));
            // |e_t - e_{t-1}| relative to the brute force image.
            let num = l1(&difference(&eb, &ea));
            let den = l1(&a.brute);
            if den > 0.0 { num / den } else { 0.0 }
        }),
        sparse_point_irradiance_change: mean(&|a, b| values_change(&a.irradiance, &b.irradiance)),
    }
}

/// Sum of |RGB| over covered pixels.
fn l1(img: &LinearImage) -> f64 {
    (0..img.pixels.len()).filter(|&i| img.covered(i)).map(|i| img.rgb(i).abs().element_sum() as f64).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_change_is_relative_l1_over_pixels_covered_in_both() {
        let a = LinearImage { width: 3, height: 1, pixels: vec![[1.0; 4], [2.0, 2.0, 2.0, 1.0], [9.0, 9.0, 9.0, 0.0]] };
        let b = LinearImage { width: 3, height: 1, pixels: vec![[1.5, 1.0, 1.0, 1.0], [2.0, 2.0, 2.0, 1.0], [0.0; 4]] };
        assert!((image_change(&a, &b) - 0.5 / 9.0).abs() < 1e-9);
        assert_eq!(image_change(&a, &a), 0.0);
    }
}
