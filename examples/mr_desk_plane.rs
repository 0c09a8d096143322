//! Where a mixed-reality scene's virtual content meets the real desk: per frame of
//! a TUM recording, the plane fitted to the depth frame's points under the content's lowest
//! vertices, the signed distance of the lowest vertex above that plane, and the pixel where
//! the contact is seen.
//!
//! `cargo run --example mr_desk_plane -- SCENE.json [RECORDING] [FRAME ...]`
//! (default: `fixtures/recordings/tum_fr1_xyz`, frames 0 9 18 27 36).
//!
//! The plane: the depth points (every second pixel) within `RADIUS` of the lowest vertices'
//! centre across and 0.15 m along z, fitted by least squares (the covariance's smallest
//! eigenvector), then refitted three times to the points within 1 cm of the last fit.

use glam::{DMat3, DVec3};
use relume::rgbd::recording::{Recording, RecordingOptions};
use relume::scene::Scene;
use std::path::Path;

/// Horizontal radius (m) of the desk patch fitted.
const RADIUS: f64 = 0.12;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene_path = Path::new(args.first().ok_or("usage: mr_desk_plane SCENE.json [RECORDING] [FRAME ...]")?);
    let recording = args.get(1).map_or("fixtures/recordings/tum_fr1_xyz", String::as_str);
    let frames: Vec<usize> = match args.len() > 2 {
        true => args[2..].iter().map(|s| s.parse()).collect::<Result<_, _>>()?,
        false => vec![0, 9, 18, 27, 36],
    };
    let scene = Scene::load(scene_path)?;
    let vertices: Vec<DVec3> = scene
        .meshes
        .iter()
        .flat_map(|m| m.placed(m.model_to_world).positions())
        .map(|p| scene.origin + p.as_dvec3())
        .collect();
    let lowest = vertices.iter().map(|p| p.z).fold(f64::MAX, f64::min);
    let base: Vec<DVec3> = vertices.iter().copied().filter(|p| p.z < lowest + 0.005).collect();
    let centre = base.iter().copied().sum::<DVec3>() / base.len() as f64;
    println!("lowest vertex z {lowest:.4} m; {} vertices within 5 mm of it, centred at {centre:.3}", base.len());
    let recording = Recording::open(Path::new(recording), &RecordingOptions::default())?;
    for f in frames.into_iter().filter(|f| *f < recording.len()) {
        let frame = recording.frame(f)?;
        let k = frame.intrinsics;
        let mut points = Vec::new();
        for v in (0..k.height).step_by(2) {
            for u in (0..k.width).step_by(2) {
                let z = frame.depth[(v * k.width + u) as usize];
                if !(z > 0.0 && z.is_finite()) {
                    continue;
                }
                let camera = relume::twin::rgbd::unproject(&k, u as f32, v as f32, z).as_dvec3();
                let w = frame.camera_to_world.transform_point3(camera);
                let d = w - centre;
                if d.truncate().length() < RADIUS && d.z.abs() < 0.15 {
                    points.push(w);
                }
            }
        }
        let (mut mean, mut normal) = (DVec3::ZERO, DVec3::Z);
        for _ in 0..4 {
            if !points.is_empty() && mean != DVec3::ZERO {
                points.retain(|p| (*p - mean).dot(normal).abs() < 0.01);
            }
            (mean, normal) = fit_plane(&points);
        }
        let n = points.len().max(1) as f64;
        let rms = (points.iter().map(|p| (*p - mean).dot(normal).powi(2)).sum::<f64>() / n).sqrt();
        let above = vertices.iter().map(|p| (*p - mean).dot(normal)).fold(f64::MAX, f64::min);
        let to_camera = frame.camera_to_world.inverse();
        let pixel = k.project(to_camera.transform_point3(centre).as_vec3());
        println!(
            "frame {f}: plane normal {normal:.3} from {} points (rms {:.1} mm); lowest vertex {:+.1} mm above it; \
             contact seen at pixel ({:.0}, {:.0}) of {}x{}",
            points.len(),
            rms * 1e3,
            above * 1e3,
            pixel.x,
            pixel.y,
            k.width,
            k.height
        );
    }
    Ok(())
}

/// Centroid and unit normal (z >= 0) of the least-squares plane through `points`.
fn fit_plane(points: &[DVec3]) -> (DVec3, DVec3) {
    let n = points.len().max(1) as f64;
    let mean = points.iter().copied().sum::<DVec3>() / n;
    let mut covariance = DMat3::ZERO;
    for p in points {
        let d = *p - mean;
        covariance += DMat3::from_cols(d * d.x, d * d.y, d * d.z) / n;
    }
    // Power iteration on trace * I - C converges to C's smallest eigenvector.
    let shifted = DMat3::from_diagonal(DVec3::splat(covariance.x_axis.x + covariance.y_axis.y + covariance.z_axis.z))
        - covariance;
    let mut normal = DVec3::Z;
    for _ in 0..200 {
        normal = (shifted * normal).normalize_or(DVec3::Z);
    }
    (mean, if normal.z < 0.0 { -normal } else { normal })
}
