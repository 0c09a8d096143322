//! `relume record-synthetic`: a synthetic RGB-D recording of a known, lit room rendered by
//! relume itself, in the TUM layout that [`crate::rgbd::recording::Recording::open_tum`] reads.
//! Replaying it against virtual content closes the loop: the content's indirect light from the
//! recording's VALs can be compared with the RSM path on the same room and light
//! (docs/measurements/closed-loop.md).
//!
//! Per frame `i` (timestamp `i / FRAME_RATE_HZ` s) the directory gets
//!
//! - `rgb/NNNN.png`: the room's direct-lit radiance (W/(m² sr), the renderer's `direct`
//!   component, diffuse and glossy) divided by `radiance_scale`, clipped to [0, 1] and
//!   sRGB-encoded to 8 bits, so a replay with `settings.rgbd.radiance_scale = radiance_scale`
//!   recovers the radiance (`L = radiance_scale * srgb_to_linear(rgb)`) up to quantisation;
//! - `depth/NNNN.png`: 16-bit depth along the optical axis at [`TUM_DEPTH_SCALE`] units per
//!   metre ([`super::virtual_depth`]), 0 where no surface is hit or beyond the 16-bit range;
//! - a line of `rgb.txt`, `depth.txt` and `groundtruth.txt` (`timestamp tx ty tz qx qy qz qw`,
//!   camera-to-world of the optical frame x right, y down, z forward, in the scene's user world
//!   coordinates: the reader takes the quaternion and translation as they are);
//!
//! and once `intrinsics.json` (pinhole from the scene camera's vertical field of view, square
//! pixels, principal point at the image centre, `depth_scale`) and `synthetic.json`
//! ([`SyntheticMetadata`]: the radiance scale and the trajectory).
//!
//! Trajectory: the scene camera's eye swept along a horizontal arc around its target (about
//! the camera's up axis through the target), `arc_deg` wide and centred on the scene camera
//! turned by `turn_deg`, frames evenly spaced from `turn_deg - arc_deg / 2` to
//! `turn_deg + arc_deg / 2` (one frame, no turn: the scene camera). Turning the arc away from
//! the lit surfaces measures what the replay loses when the camera does not see them.

use crate::gpu::Gpu;
use crate::image::encode_srgb;
use crate::renderer::{Components, Method, Renderer};
use crate::rgbd::Intrinsics;
use crate::rgbd::recording::{INTRINSICS_FILE, TUM_DEPTH_SCALE};
use crate::scene::Scene;
use anyhow::Context;
use glam::{DAffine3, DMat3, DQuat, DVec3};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Frames per second of the written timestamps.
pub const FRAME_RATE_HZ: f64 = 30.0;
/// Default number of frames.
pub const DEFAULT_FRAMES: u32 = 8;
/// Default width of the arc (degrees).
pub const DEFAULT_ARC_DEG: f64 = 60.0;
/// Bounds of `frames`.
pub const MAX_FRAMES: u32 = 1000;
/// Bounds of `arc_deg`: less than a full turn, so no two frames coincide.
pub const MAX_ARC_DEG: f64 = 300.0;
/// Bounds of `turn_deg`: either way round, half a turn.
pub const MAX_TURN_DEG: f64 = 180.0;
/// Written beside the TUM files: how the colours were made.
pub const METADATA_FILE: &str = "synthetic.json";

/// What to record.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticOptions {
    pub out: PathBuf,
    /// Frames along the arc, in 1..=[`MAX_FRAMES`].
    pub frames: u32,
    /// Image size (pixels).
    pub width: u32,
    pub height: u32,
    /// Width of the arc (degrees), in 0..=[`MAX_ARC_DEG`].
    pub arc_deg: f64,
    /// Turn of the arc's centre from the scene camera about its up axis (degrees), in
    /// -[`MAX_TURN_DEG`]..=[`MAX_TURN_DEG`].
    pub turn_deg: f64,
    /// Radiance (W/(m² sr)) written as a colour of 1; `None`: the largest direct radiance of
    /// any channel over all frames, so nothing clips.
    pub radiance_scale: Option<f32>,
}

impl SyntheticOptions {
    /// `Err((flag, message))` for the first option out of range.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if !(1..=MAX_FRAMES).contains(&self.frames) {
            return Err(("frames", format!("must be in 1..={MAX_FRAMES}, got {}", self.frames)));
        }
        if !(self.arc_deg.is_finite() && (0.0..=MAX_ARC_DEG).contains(&self.arc_deg)) {
            return Err(("arc-deg", format!("must be in 0..={MAX_ARC_DEG}, got {}", self.arc_deg)));
        }
        if !(self.turn_deg.is_finite() && (-MAX_TURN_DEG..=MAX_TURN_DEG).contains(&self.turn_deg)) {
            return Err(("turn-deg", format!("must be in -{MAX_TURN_DEG}..={MAX_TURN_DEG}, got {}", self.turn_deg)));
        }
        if let Some(s) = self.radiance_scale
            && !(s.is_finite() && s > 0.0)
        {
            return Err(("radiance-scale", format!("must be a positive number, got {s}")));
        }
        Ok(())
    }
}

/// `synthetic.json`: how the recording was made.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct SyntheticMetadata {
    /// Radiance (W/(m² sr)) of a linear colour of 1: replay with
    /// `settings.rgbd.radiance_scale` set to it.
    pub radiance_scale: f32,
    /// Whether `radiance_scale` was chosen from the frames' largest radiance.
    pub radiance_scale_auto: bool,
    /// Fraction of colour channels (over all frames) whose value was clipped at 1.
    pub clipped_fraction: f64,
    /// Fraction of pixels (over all frames) with depth 0.
    pub depth_missing_fraction: f64,
    pub frames: u32,
    pub arc_deg: f64,
    pub turn_deg: f64,
    pub frame_rate_hz: f64,
    pub width: u32,
    pub height: u32,
    pub depth_scale: f32,
    /// Centre of the arc (the scene camera's target), user world coordinates (m).
    pub target: [f64; 3],
}

/// The pinhole intrinsics of `scene`'s camera at `width x height`: vertical field of view kept,
/// square pixels, principal point at the image centre.
pub fn intrinsics(scene: &Scene, width: u32, height: u32) -> Intrinsics {
    let f = 0.5 * height as f32 / (0.5 * scene.camera.fov_y).tan();
    Intrinsics { width, height, fx: f, fy: f, cx: 0.5 * width as f32 - 0.5, cy: 0.5 * height as f32 - 0.5 }
}

/// Camera-to-world (optical axes: x right, y down, z forward; user world coordinates) of each
/// of `frames` frames along the arc (see the module docs).
pub fn trajectory(scene: &Scene, frames: u32, arc_deg: f64, turn_deg: f64) -> Vec<DAffine3> {
    let camera = &scene.camera;
    let target = scene.origin + camera.target.as_dvec3();
    let eye = scene.origin + camera.position.as_dvec3();
    let up = camera.up.as_dvec3().normalize();
    (0..frames)
        .map(|i| {
            let s = if frames > 1 { f64::from(i) / f64::from(frames - 1) - 0.5 } else { 0.0 };
            let angle = (turn_deg + arc_deg * s).to_radians();
            let eye = target + DQuat::from_axis_angle(up, angle) * (eye - target);
            look_at_optical(eye, target, up)
        })
        .collect()
}

/// Camera-to-world in optical axes of a camera at `eye` looking at `target`, `up` roughly up.
pub fn look_at_optical(eye: DVec3, target: DVec3, up: DVec3) -> DAffine3 {
    let forward = (target - eye).normalize();
    let right = forward.cross(up).normalize();
    let down = forward.cross(right);
    DAffine3::from_mat3_translation(DMat3::from_cols(right, down, forward), eye)
}

/// Record `scene` (which must have a spot light) into `options.out`; returns what
/// `synthetic.json` says.
pub fn record(gpu: &Gpu, scene: &Scene, options: &SyntheticOptions) -> anyhow::Result<SyntheticMetadata> {
    options.check().map_err(|(flag, message)| anyhow::anyhow!("--{flag}: {message}"))?;
    anyhow::ensure!(scene.light.is_some(), "the scene has no light: a synthetic recording needs a lit room");
    let (w, h) = (options.width, options.height);
    let k = intrinsics(scene, w, h);
    let poses = trajectory(scene, options.frames, options.arc_deg, options.turn_deg);
    let mut renderer = Renderer::new(gpu, scene)?;
    let mut render = |pose: &DAffine3| -> anyhow::Result<_> {
        renderer.set_pinhole_view(k, pose);
        let frame = renderer.render_components(gpu, Method::Sparse, w, h, Components::DIRECT)?;
        let depth = super::virtual_depth(gpu, &renderer, pose)?;
        Ok((frame.direct, depth))
    };
    // Auto scale: a first pass for the largest radiance (direct light only: cheap).
    let radiance_scale = match options.radiance_scale {
        Some(s) => s,
        None => {
            let mut largest = 0.0f32;
            for pose in &poses {
                let (direct, _) = render(pose)?;
                for i in 0..direct.pixels.len() {
                    largest = largest.max(direct.rgb(i).max_element());
                }
            }
            anyhow::ensure!(largest > 0.0, "the room receives no direct light from any frame's view");
            largest
        }
    };
    let out = &options.out;
    for dir in [out.join("rgb"), out.join("depth")] {
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let (mut rgb_txt, mut depth_txt, mut groundtruth) = (
        String::from("# colour images (relume record-synthetic)\n# timestamp filename\n"),
        String::from("# depth images (relume record-synthetic)\n# timestamp filename\n"),
        String::from("# ground truth camera-to-world (optical axes)\n# timestamp tx ty tz qx qy qz qw\n"),
    );
    let (mut clipped, mut missing) = (0u64, 0u64);
    for (i, pose) in poses.iter().enumerate() {
        let (direct, depth) = render(pose)?;
        let colour: Vec<[u8; 3]> = (0..direct.pixels.len())
            .map(|p| {
                let c = direct.rgb(p) / radiance_scale;
                clipped += c.to_array().iter().filter(|&&v| v > 1.0).count() as u64;
                [encode_srgb(c.x), encode_srgb(c.y), encode_srgb(c.z)]
            })
            .collect();
        let depth: Vec<u16> = depth
            .iter()
            .map(|z| match z.map(|z| (f64::from(z) * f64::from(TUM_DEPTH_SCALE)).round()) {
                Some(units) if units >= 1.0 && units <= f64::from(u16::MAX) => units as u16,
                _ => {
                    missing += 1;
                    0
                }
            })
            .collect();
        let t = i as f64 / FRAME_RATE_HZ;
        let name = format!("{i:04}.png");
        let rgb_path = out.join("rgb").join(&name);
        crate::image::rgb8_image(w, h, &colour)
            .context("colour image")?
            .save(&rgb_path)
            .with_context(|| format!("writing {}", rgb_path.display()))?;
        let depth_path = out.join("depth").join(&name);
        ::image::ImageBuffer::<::image::Luma<u16>, Vec<u16>>::from_raw(w, h, depth)
            .context("depth image size")?
            .save(&depth_path)
            .with_context(|| format!("writing {}", depth_path.display()))?;
        let q = DQuat::from_mat3(&pose.matrix3).normalize();
        let p = pose.translation;
        writeln!(rgb_txt, "{t:.6} rgb/{name}")?;
        writeln!(depth_txt, "{t:.6} depth/{name}")?;
        writeln!(groundtruth, "{t:.6} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}", p.x, p.y, p.z, q.x, q.y, q.z, q.w)?;
    }
    let pixels = f64::from(options.frames) * f64::from(w) * f64::from(h);
    let target = scene.origin + scene.camera.target.as_dvec3();
    let metadata = SyntheticMetadata {
        radiance_scale,
        radiance_scale_auto: options.radiance_scale.is_none(),
        clipped_fraction: clipped as f64 / (3.0 * pixels),
        depth_missing_fraction: missing as f64 / pixels,
        frames: options.frames,
        arc_deg: options.arc_deg,
        turn_deg: options.turn_deg,
        frame_rate_hz: FRAME_RATE_HZ,
        width: w,
        height: h,
        depth_scale: TUM_DEPTH_SCALE,
        target: target.to_array(),
    };
    let intrinsics_json = serde_json::json!({
        "width": w, "height": h, "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy, "depth_scale": TUM_DEPTH_SCALE,
    });
    write_text(out, "rgb.txt", &rgb_txt)?;
    write_text(out, "depth.txt", &depth_txt)?;
    write_text(out, "groundtruth.txt", &groundtruth)?;
    write_text(out, INTRINSICS_FILE, &serde_json::to_string_pretty(&intrinsics_json)?)?;
    write_text(out, METADATA_FILE, &serde_json::to_string_pretty(&metadata)?)?;
    Ok(metadata)
}

fn write_text(dir: &Path, name: &str, text: &str) -> anyhow::Result<()> {
    let path = dir.join(name);
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The optical frame looks at the target, x right of it and y down, right-handed.
    #[test]
    fn look_at_optical_looks_at_the_target() {
        let pose = look_at_optical(DVec3::new(0.0, 1.0, 3.0), DVec3::new(0.0, 1.0, 0.0), DVec3::Y);
        let m = pose.matrix3;
        assert!(m.z_axis.abs_diff_eq(DVec3::NEG_Z, 1e-12), "forward {}", m.z_axis);
        assert!(m.x_axis.abs_diff_eq(DVec3::X, 1e-12), "right {}", m.x_axis);
        assert!(m.y_axis.abs_diff_eq(DVec3::NEG_Y, 1e-12), "down {}", m.y_axis);
        assert!((m.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn options_out_of_range_name_their_flag() {
        let ok = SyntheticOptions {
            out: PathBuf::from("x"),
            frames: 8,
            width: 64,
            height: 48,
            arc_deg: 60.0,
            turn_deg: 0.0,
            radiance_scale: None,
        };
        assert_eq!(ok.check(), Ok(()));
        let flag = |o: SyntheticOptions| o.check().unwrap_err().0;
        assert_eq!(flag(SyntheticOptions { frames: 0, ..ok.clone() }), "frames");
        assert_eq!(flag(SyntheticOptions { frames: MAX_FRAMES + 1, ..ok.clone() }), "frames");
        assert_eq!(flag(SyntheticOptions { arc_deg: -1.0, ..ok.clone() }), "arc-deg");
        assert_eq!(flag(SyntheticOptions { arc_deg: f64::NAN, ..ok.clone() }), "arc-deg");
        assert_eq!(flag(SyntheticOptions { turn_deg: 181.0, ..ok.clone() }), "turn-deg");
        assert_eq!(flag(SyntheticOptions { turn_deg: f64::INFINITY, ..ok.clone() }), "turn-deg");
        assert_eq!(flag(SyntheticOptions { radiance_scale: Some(0.0), ..ok.clone() }), "radiance-scale");
        assert_eq!(flag(SyntheticOptions { radiance_scale: Some(f32::INFINITY), ..ok }), "radiance-scale");
    }
}
