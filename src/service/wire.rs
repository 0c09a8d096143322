//! The stream protocol (`proto/relume.proto`, package `relume.v1`): one protobuf `Envelope` per
//! WebSocket binary message. [`decode`] turns a client's envelope into validated domain values
//! ([`RgbdFrame`] with depth in metres, camera and light descriptions, transforms, quality and
//! RGB-D settings) or a [`WireError`] naming the field and, for limits, the setting; it never
//! panics, whatever the bytes. [`encode`] writes the server's answers.
//!
//! Field paths in errors follow the proto field names from the envelope's body down, e.g.
//! `rgbd_frame.color.rgb8` or `control.model_transforms[2].scale`.

use glam::{DAffine3, DVec3, Mat3, Mat4, Quat, Vec3};
use prost::Message;

use crate::rgbd::{Intrinsics, RgbdFrame, RgbdSettings};
use crate::scene::{
    CameraDescription, MAX_COORDINATE_M, Occlusion, ScaleDescription, SceneError, TransformDescription,
};

use super::api::{Component, LightOverride};
use super::config::{LimitExceeded, Limits, limit};
use crate::renderer::Method;

/// The code prost generates from `proto/relume.proto`.
#[allow(clippy::all, missing_docs)]
pub mod proto {
    include!(concat!(env!("OUT_DIR"), "/relume.v1.rs"));
}

pub use proto::ErrorCode;

/// The protocol version this server speaks (`Envelope.version`).
pub const PROTOCOL_VERSION: u32 = 1;

/// How far a quaternion's norm may be from 1, and a pose matrix's rotation from orthonormal.
pub const POSE_TOLERANCE: f32 = 1e-3;

/// A client message, validated.
#[derive(Clone, Debug)]
pub enum ClientMessage {
    Frame(FrameMessage),
    Control(ControlMessage),
}

/// An RGB-D frame and the id the client gave it.
#[derive(Clone, Debug)]
pub struct FrameMessage {
    pub frame_id: u64,
    pub frame: RgbdFrame,
}

/// A control message: each part, when present, is valid on its own. Parts that depend on the
/// scene (mesh indices, the light after overrides, RGB-D settings after merging) are checked
/// where they are applied, with the same field paths.
#[derive(Clone, Debug, Default)]
pub struct ControlMessage {
    pub request_id: u64,
    pub camera: Option<CameraDescription>,
    pub light: Option<LightOverride>,
    /// (mesh index, transform), each mesh at most once.
    pub model_transforms: Vec<(u32, TransformDescription)>,
    pub quality: Option<StreamQuality>,
    pub rgbd: Option<RgbdSettingsPatch>,
    pub render: Option<RenderSettingsPatch>,
}

/// Changes to a stream's render settings; absent fields keep their value.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderSettingsPatch {
    /// `Some(None)`: back to the scene's setting.
    pub occlusion: Option<Option<Occlusion>>,
    pub glossy: Option<bool>,
}

/// How a stream's frames are rendered and sent back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamQuality {
    pub method: Method,
    pub component: Component,
    /// > 0; `None`: automatic.
    pub exposure: Option<f32>,
    pub format: StreamImageFormat,
}

impl Default for StreamQuality {
    fn default() -> Self {
        StreamQuality {
            method: Method::Sparse,
            component: Component::Full,
            exposure: None,
            format: StreamImageFormat::Png,
        }
    }
}

/// The image format of `RenderedFrame`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StreamImageFormat {
    Png,
    Rgba8,
}

/// Changes to a stream's [`RgbdSettings`]; absent fields keep their value.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RgbdSettingsPatch {
    pub grid_step: Option<u32>,
    pub min_depth: Option<f32>,
    pub max_depth: Option<f32>,
    pub radiance_scale: Option<f32>,
    pub bilateral_radius: Option<u32>,
    pub bilateral_depth_sigma: Option<f32>,
    pub min_cosine: Option<f32>,
}

impl RgbdSettingsPatch {
    /// `base` with these changes, validated as a scene file's `settings.rgbd` is
    /// ([`RgbdSettings::validate`]); errors name fields under `field` (`control.rgbd`).
    pub fn apply(&self, base: &RgbdSettings, field: &str) -> Result<RgbdSettings, WireError> {
        let settings = RgbdSettings {
            grid_step: self.grid_step.unwrap_or(base.grid_step),
            min_depth: self.min_depth.unwrap_or(base.min_depth),
            max_depth: self.max_depth.unwrap_or(base.max_depth),
            radiance_scale: self.radiance_scale.unwrap_or(base.radiance_scale),
            bilateral_radius: self.bilateral_radius.unwrap_or(base.bilateral_radius),
            bilateral_depth_sigma: self.bilateral_depth_sigma.unwrap_or(base.bilateral_depth_sigma),
            min_cosine: self.min_cosine.unwrap_or(base.min_cosine),
        };
        // The scene file's one check of these settings, so a stream accepts what a scene accepts.
        settings.validate(field).map_err(WireError::from_scene)?;
        Ok(settings)
    }
}

/// Checks that a frame of these intrinsics yields at most `max_vals` VALs with `settings`'
/// grid (one VAL per `grid_step²` block of depth pixels, partial blocks included).
pub fn check_frame_vals(intrinsics: &Intrinsics, settings: &RgbdSettings, limits: &Limits) -> Result<(), WireError> {
    let step = settings.grid_step.max(1) as u64;
    let cells = (intrinsics.width as u64).div_ceil(step) * (intrinsics.height as u64).div_ceil(step);
    if cells > limits.max_vals as u64 {
        return Err(WireError::limit(
            limit::MAX_VALS,
            Some("rgbd_frame.intrinsics".to_owned()),
            format!(
                "a {} x {} frame at grid_step {} gives up to {cells} VALs, over the limit of {}",
                intrinsics.width, intrinsics.height, settings.grid_step, limits.max_vals
            ),
        ));
    }
    Ok(())
}

/// Why a message was refused; becomes an `Error` message.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct WireError {
    pub code: ErrorCode,
    /// Includes the field path when there is one.
    pub message: String,
    pub field: Option<String>,
    /// The exceeded setting, for [`ErrorCode::LimitExceeded`].
    pub limit: Option<&'static str>,
    pub frame_id: Option<u64>,
    pub request_id: Option<u64>,
}

impl From<LimitExceeded> for WireError {
    fn from(e: LimitExceeded) -> WireError {
        let message = format!("{} ({})", e.message, e.limit);
        WireError { limit: Some(e.limit), ..WireError::new(ErrorCode::LimitExceeded, e.field, message) }
    }
}

impl WireError {
    pub fn new(code: ErrorCode, field: Option<String>, message: impl Into<String>) -> WireError {
        WireError { code, message: message.into(), field, limit: None, frame_id: None, request_id: None }
    }

    /// [`ErrorCode::InvalidField`]; the message is prefixed with the field's path.
    pub fn invalid(field: impl Into<String>, message: impl std::fmt::Display) -> WireError {
        let field = field.into();
        WireError::new(ErrorCode::InvalidField, Some(field.clone()), format!("{field}: {message}"))
    }

    /// [`ErrorCode::LimitExceeded`] of setting `limit`.
    pub fn limit(limit: &'static str, field: Option<String>, message: impl std::fmt::Display) -> WireError {
        let message = match &field {
            Some(field) => format!("{field}: {message} ({limit})"),
            None => format!("{message} ({limit})"),
        };
        WireError { limit: Some(limit), ..WireError::new(ErrorCode::LimitExceeded, field, message) }
    }

    fn missing(field: &str) -> WireError {
        WireError::invalid(field, "required field is missing")
    }

    pub fn with_frame(self, frame_id: u64) -> WireError {
        WireError { frame_id: Some(frame_id), ..self }
    }

    pub fn with_request(self, request_id: u64) -> WireError {
        WireError { request_id: Some(request_id), ..self }
    }

    /// A scene-module validation error (its field path is already the full one).
    fn from_scene(error: SceneError) -> WireError {
        let field = error.field_path().map(str::to_owned);
        WireError::new(ErrorCode::InvalidField, field, error.to_string())
    }

    /// The code's name as in the proto file, e.g. `ERROR_CODE_INVALID_FIELD`.
    pub fn code_name(&self) -> &'static str {
        self.code.as_str_name()
    }
}

/// Decodes and validates one client envelope. Checks, in order: the size limit, the protobuf
/// encoding, the version, the body's kind, then every field.
pub fn decode(bytes: &[u8], limits: &Limits) -> Result<ClientMessage, WireError> {
    if bytes.len() > limits.max_message_bytes {
        return Err(WireError::limit(
            limit::MAX_MESSAGE_BYTES,
            None,
            format!("the message is {} bytes, over the limit of {}", bytes.len(), limits.max_message_bytes),
        ));
    }
    let envelope = proto::Envelope::decode(bytes)
        .map_err(|e| WireError::new(ErrorCode::Malformed, None, format!("not a relume.v1.Envelope: {e}")))?;
    // An empty message decodes as an envelope with neither version nor body: malformed, as
    // the protocol says of an empty body, not a version this server does not speak.
    if envelope.version == 0 && envelope.body.is_none() {
        return Err(WireError::new(
            ErrorCode::Malformed,
            None,
            "the message is empty (expected one relume.v1.Envelope with a version and a body)",
        ));
    }
    if envelope.version != PROTOCOL_VERSION {
        return Err(WireError::new(
            ErrorCode::UnsupportedVersion,
            Some("version".to_owned()),
            format!("version: this server speaks version {PROTOCOL_VERSION}, got {}", envelope.version),
        ));
    }
    use proto::envelope::Body;
    match envelope.body {
        None => Err(WireError::new(
            ErrorCode::Malformed,
            Some("body".to_owned()),
            "body: the envelope is empty (expected rgbd_frame or control)",
        )),
        Some(Body::RgbdFrame(frame)) => {
            let frame_id = frame.frame_id;
            decode_frame(frame, limits)
                .map(|frame| ClientMessage::Frame(FrameMessage { frame_id, frame }))
                .map_err(|e| e.with_frame(frame_id))
        }
        Some(Body::Control(control)) => {
            let request_id = control.request_id;
            decode_control(control, limits).map(ClientMessage::Control).map_err(|e| e.with_request(request_id))
        }
        Some(Body::RenderedFrame(_) | Body::Error(_) | Body::SettingsAck(_)) => Err(WireError::new(
            ErrorCode::UnexpectedMessage,
            Some("body".to_owned()),
            "body: rendered_frame, error and settings_ack are sent by the server, not to it",
        )),
    }
}

fn decode_frame(frame: proto::RgbdFrame, limits: &Limits) -> Result<RgbdFrame, WireError> {
    if !frame.timestamp.is_finite() {
        return Err(WireError::invalid("rgbd_frame.timestamp", format!("must be finite, got {}", frame.timestamp)));
    }
    let intrinsics =
        decode_intrinsics(frame.intrinsics.ok_or_else(|| WireError::missing("rgbd_frame.intrinsics"))?, limits)?;
    let color = decode_color(frame.color, &intrinsics)?;
    let depth = decode_depth(frame.depth, &intrinsics)?;
    let camera_to_world = decode_pose(frame.camera_to_world, "rgbd_frame.camera_to_world")?;
    Ok(RgbdFrame { timestamp: frame.timestamp, intrinsics, color, depth, camera_to_world })
}

fn decode_intrinsics(i: proto::Intrinsics, limits: &Limits) -> Result<Intrinsics, WireError> {
    let field = "rgbd_frame.intrinsics";
    for (name, value) in [("width", i.width), ("height", i.height)] {
        if value == 0 {
            return Err(WireError::invalid(format!("{field}.{name}"), "must be at least 1, got 0"));
        }
    }
    limits.check_image(i.width, i.height, field)?;
    for (name, value) in [("fx", i.fx), ("fy", i.fy)] {
        if !(value.is_finite() && value > 0.0) {
            return Err(WireError::invalid(format!("{field}.{name}"), format!("must be finite and > 0, got {value}")));
        }
    }
    for (name, value) in [("cx", i.cx), ("cy", i.cy)] {
        if !value.is_finite() {
            return Err(WireError::invalid(format!("{field}.{name}"), format!("must be finite, got {value}")));
        }
    }
    Ok(Intrinsics { width: i.width, height: i.height, fx: i.fx, fy: i.fy, cx: i.cx, cy: i.cy })
}

/// `width * height * bytes_per_pixel`, or an error naming `field` when `len` differs.
fn check_len(field: &str, len: usize, i: &Intrinsics, bytes_per_pixel: u64, what: &str) -> Result<(), WireError> {
    let expected = i.width as u64 * i.height as u64 * bytes_per_pixel;
    if len as u64 != expected {
        return Err(WireError::invalid(
            field,
            format!("expected {} x {} x {bytes_per_pixel} = {expected} bytes ({what}), got {len}", i.width, i.height),
        ));
    }
    Ok(())
}

fn decode_color(color: Option<proto::Color>, i: &Intrinsics) -> Result<Vec<[u8; 3]>, WireError> {
    use proto::color::Data;
    let field = "rgbd_frame.color";
    match color.and_then(|c| c.data) {
        None => Err(WireError::invalid(field, "required field is missing (rgb8 or png)")),
        Some(Data::Rgb8(bytes)) => {
            let field = format!("{field}.rgb8");
            check_len(&field, bytes.len(), i, 3, "sRGB, 3 bytes per pixel")?;
            Ok(bytes.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
        }
        Some(Data::Png(bytes)) => decode_png(&bytes, i, &format!("{field}.png")),
    }
}

/// Decodes a PNG of exactly the intrinsics' size to RGB8; the size is read from the header
/// before anything is decompressed.
fn decode_png(bytes: &[u8], i: &Intrinsics, field: &str) -> Result<Vec<[u8; 3]>, WireError> {
    use image::{ImageFormat, ImageReader};
    let reader = || ImageReader::with_format(std::io::Cursor::new(bytes), ImageFormat::Png);
    let (width, height) =
        reader().into_dimensions().map_err(|e| WireError::invalid(field, format!("not a readable PNG: {e}")))?;
    if (width, height) != (i.width, i.height) {
        return Err(WireError::invalid(
            field,
            format!("the PNG is {width} x {height} pixels, the intrinsics say {} x {}", i.width, i.height),
        ));
    }
    let mut reader = reader();
    let mut png_limits = image::Limits::default();
    png_limits.max_image_width = Some(width);
    png_limits.max_image_height = Some(height);
    // RGBA16 is the widest PNG pixel.
    png_limits.max_alloc = Some(width as u64 * height as u64 * 8 + (1 << 20));
    reader.limits(png_limits);
    let image = reader.decode().map_err(|e| WireError::invalid(field, format!("cannot decode the PNG: {e}")))?;
    Ok(image.into_rgb8().pixels().map(|p| p.0).collect())
}

fn decode_depth(depth: Option<proto::Depth>, i: &Intrinsics) -> Result<Vec<f32>, WireError> {
    use proto::depth::Data;
    let field = "rgbd_frame.depth";
    match depth.and_then(|d| d.data) {
        None => Err(WireError::invalid(field, "required field is missing (u16 or f32_metres)")),
        Some(Data::U16(d)) => {
            let scale_field = format!("{field}.u16.units_per_metre");
            if !(d.units_per_metre.is_finite() && d.units_per_metre > 0.0) {
                return Err(WireError::invalid(
                    scale_field,
                    format!("must be finite and > 0 (TUM: 5000, millimetres: 1000), got {}", d.units_per_metre),
                ));
            }
            check_len(&format!("{field}.u16.data"), d.data.len(), i, 2, "u16 little-endian")?;
            let metres_per_unit = 1.0 / d.units_per_metre;
            Ok(d.data.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]]) as f32 * metres_per_unit).collect())
        }
        Some(Data::F32Metres(bytes)) => {
            check_len(&format!("{field}.f32_metres"), bytes.len(), i, 4, "f32 little-endian, metres")?;
            Ok(bytes
                .chunks_exact(4)
                .map(|b| {
                    let metres = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                    // REP 117: +inf too far, -inf too near; both are "no measurement".
                    if metres.is_infinite() { f32::NAN } else { metres }
                })
                .collect())
        }
    }
}

fn vec3(v: Option<proto::Vec3>, field: &str) -> Result<Vec3, WireError> {
    let v = v.ok_or_else(|| WireError::missing(field))?;
    Ok(Vec3::new(v.x, v.y, v.z))
}

fn finite_vec3(v: Option<proto::Vec3>, field: &str) -> Result<Vec3, WireError> {
    let v = vec3(v, field)?;
    if !v.is_finite() {
        return Err(WireError::invalid(field, format!("must be finite, got [{}, {}, {}]", v.x, v.y, v.z)));
    }
    Ok(v)
}

/// A pose: its `transform` (f32) widened to f64, the translation replaced by
/// `translation_f64` when that is set.
fn decode_pose(pose: Option<proto::Pose>, field: &str) -> Result<DAffine3, WireError> {
    let pose = pose.unwrap_or_default();
    let mut decoded = decode_transform(pose.transform, field)?;
    if let Some(t) = pose.translation_f64 {
        let field = format!("{field}.translation_f64");
        for (axis, value) in ["x", "y", "z"].into_iter().zip([t.x, t.y, t.z]) {
            if !(value.is_finite() && value.abs() <= MAX_COORDINATE_M) {
                return Err(WireError::invalid(
                    format!("{field}.{axis}"),
                    format!("must be a finite number within +-{MAX_COORDINATE_M:e} m, got {value:e}"),
                ));
            }
        }
        decoded.translation = DVec3::new(t.x, t.y, t.z);
    }
    Ok(decoded)
}

fn decode_transform(transform: Option<proto::pose::Transform>, field: &str) -> Result<DAffine3, WireError> {
    use proto::pose::Transform;
    match transform {
        None => Err(WireError::invalid(field, "required field is missing (translation_rotation or matrix)")),
        Some(Transform::TranslationRotation(tr)) => {
            let base = format!("{field}.translation_rotation");
            let translation = finite_vec3(tr.translation, &format!("{base}.translation"))?;
            let rotation_field = format!("{base}.rotation");
            let q = tr.rotation.ok_or_else(|| WireError::missing(&rotation_field))?;
            let q = Quat::from_xyzw(q.x, q.y, q.z, q.w);
            if !q.is_finite() {
                return Err(WireError::invalid(rotation_field, format!("must be finite, got {q}")));
            }
            let norm = q.length();
            if (norm - 1.0).abs() > POSE_TOLERANCE {
                return Err(WireError::invalid(
                    rotation_field,
                    format!("must be a unit quaternion (norm within {POSE_TOLERANCE} of 1), got norm {norm}"),
                ));
            }
            Ok(DAffine3::from_rotation_translation((q / norm).as_dquat().normalize(), translation.as_dvec3()))
        }
        Some(Transform::Matrix(m)) => {
            let field = format!("{field}.matrix.column_major");
            let values = m.column_major;
            if values.len() != 16 {
                return Err(WireError::invalid(field, format!("must hold 16 numbers, got {}", values.len())));
            }
            if let Some(i) = values.iter().position(|v| !v.is_finite()) {
                return Err(WireError::invalid(format!("{field}[{i}]"), format!("must be finite, got {}", values[i])));
            }
            let matrix = Mat4::from_cols_slice(&values);
            let last_row = matrix.row(3);
            if last_row.abs_diff_eq(glam::Vec4::W, POSE_TOLERANCE) {
                let rotation = Mat3::from_mat4(matrix);
                let error = (rotation.transpose() * rotation - Mat3::IDENTITY)
                    .to_cols_array()
                    .iter()
                    .fold(0.0f32, |m, v| m.max(v.abs()));
                let det = rotation.determinant();
                if error > POSE_TOLERANCE || det <= 0.0 {
                    return Err(WireError::invalid(
                        field,
                        format!(
                            "must be rigid: the upper 3x3 must be a rotation (orthonormal within \
                             {POSE_TOLERANCE}, determinant +1), got |RᵀR - I| = {error}, det = {det}"
                        ),
                    ));
                }
                Ok(DAffine3::from_mat4(matrix.as_dmat4()))
            } else {
                Err(WireError::invalid(
                    field,
                    format!("must be rigid: the last row must be [0, 0, 0, 1], got {last_row}"),
                ))
            }
        }
    }
}

fn decode_control(c: proto::Control, limits: &Limits) -> Result<ControlMessage, WireError> {
    let camera = match c.camera {
        None => None,
        Some(camera) => Some(decode_camera(camera, limits)?),
    };
    let light = c.light.map(|l| LightOverride {
        position: l.position.map(|v| [v.x, v.y, v.z].map(f64::from)),
        direction: l.direction.map(|v| [v.x, v.y, v.z]),
        inner_angle_deg: l.inner_angle_deg,
        outer_angle_deg: l.outer_angle_deg,
        intensity: l.intensity.map(|v| [v.x, v.y, v.z]),
        up: l.up.map(|v| [v.x, v.y, v.z]),
    });
    let mut model_transforms: Vec<(u32, TransformDescription)> = Vec::with_capacity(c.model_transforms.len());
    for (i, t) in c.model_transforms.into_iter().enumerate() {
        let field = format!("control.model_transforms[{i}]");
        if model_transforms.iter().any(|(mesh, _)| *mesh == t.mesh_index) {
            return Err(WireError::invalid(
                format!("{field}.mesh_index"),
                format!("mesh {} appears more than once", t.mesh_index),
            ));
        }
        let transform = TransformDescription {
            translation: vec3(t.translation, &format!("{field}.translation"))?.as_dvec3().to_array(),
            rotation_deg: vec3(t.rotation_deg, &format!("{field}.rotation_deg"))?.to_array(),
            scale: t.scale.map_or(ScaleDescription::Uniform(1.0), |s| ScaleDescription::PerAxis([s.x, s.y, s.z])),
        };
        transform.validate(&field).map_err(WireError::from_scene)?;
        model_transforms.push((t.mesh_index, transform));
    }
    let quality = match c.quality {
        None => None,
        Some(q) => Some(decode_quality(q)?),
    };
    let rgbd = c.rgbd.map(|r| RgbdSettingsPatch {
        grid_step: r.grid_step,
        min_depth: r.min_depth,
        max_depth: r.max_depth,
        radiance_scale: r.radiance_scale,
        bilateral_radius: r.bilateral_radius,
        bilateral_depth_sigma: r.bilateral_depth_sigma,
        min_cosine: r.min_cosine,
    });
    let render = match c.render {
        None => None,
        Some(r) => {
            let occlusion = match r.occlusion {
                None => None,
                Some(value) => Some(match proto::Occlusion::try_from(value) {
                    Ok(proto::Occlusion::Unspecified) => None,
                    Ok(proto::Occlusion::Off) => Some(Occlusion::Off),
                    Ok(proto::Occlusion::Disks) => Some(Occlusion::Disks),
                    Err(_) => {
                        return Err(WireError::invalid("control.render.occlusion", format!("unknown value {value}")));
                    }
                }),
            };
            Some(RenderSettingsPatch { occlusion, glossy: r.glossy })
        }
    };
    Ok(ControlMessage { request_id: c.request_id, camera, light, model_transforms, quality, rgbd, render })
}

/// A camera, validated as a scene file's `camera` is, and within `max_frame_side` and
/// `max_pixels`.
fn decode_camera(c: proto::Camera, limits: &Limits) -> Result<CameraDescription, WireError> {
    let field = "control.camera";
    let camera = CameraDescription {
        position: vec3(c.position, &format!("{field}.position"))?.as_dvec3().to_array(),
        target: vec3(c.target, &format!("{field}.target"))?.as_dvec3().to_array(),
        up: c.up.map_or([0.0, 1.0, 0.0], |v| [v.x, v.y, v.z]),
        fov_y_deg: c.fov_y_deg,
        width: c.width,
        height: c.height,
    };
    limits.check_image(camera.width, camera.height, field)?;
    camera.validate(field).map_err(WireError::from_scene)?;
    Ok(camera)
}

fn decode_quality(q: proto::Quality) -> Result<StreamQuality, WireError> {
    let field = "control.quality";
    let unknown =
        |name: &str, value: i32| WireError::invalid(format!("{field}.{name}"), format!("unknown value {value}"));
    let method = match proto::Method::try_from(q.method).map_err(|_| unknown("method", q.method))? {
        proto::Method::Unspecified | proto::Method::Sparse => Method::Sparse,
        proto::Method::BruteForce => Method::BruteForce,
        proto::Method::BruteForceIsm => Method::BruteForceIsm,
    };
    let component = match proto::Component::try_from(q.component).map_err(|_| unknown("component", q.component))? {
        proto::Component::Unspecified | proto::Component::Full => Component::Full,
        proto::Component::Direct => Component::Direct,
        proto::Component::Indirect => Component::Indirect,
    };
    let format = match proto::ImageFormat::try_from(q.format).map_err(|_| unknown("format", q.format))? {
        proto::ImageFormat::Unspecified | proto::ImageFormat::Png => StreamImageFormat::Png,
        proto::ImageFormat::Rgba8 => StreamImageFormat::Rgba8,
    };
    if let Some(exposure) = q.exposure {
        crate::scene::settings::validate_exposure(exposure, &format!("{field}.exposure"))
            .map_err(WireError::from_scene)?;
    }
    Ok(StreamQuality { method, component, exposure: q.exposure, format })
}

// -------------------------------------------------------------------------------------------
// Server to client
// -------------------------------------------------------------------------------------------

/// A message from the server.
#[derive(Clone, Debug, PartialEq)]
pub enum ServerMessage {
    Frame(RenderedFrame),
    Error(WireError),
    Ack(SettingsAck),
}

/// The composited image of one processed frame.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderedFrame {
    pub frame_id: u64,
    pub timestamp: f64,
    pub width: u32,
    pub height: u32,
    pub image: FrameImage,
    /// (stage, ms), in execution order.
    pub timings: Vec<(String, f64)>,
    pub val_count: u32,
    pub dropped_frames: u64,
}

#[derive(Clone, Debug, PartialEq)]
pub enum FrameImage {
    Png(Vec<u8>),
    /// `width * height * 4` bytes, sRGB, alpha = coverage.
    Rgba8(Vec<u8>),
}

#[derive(Clone, Debug, PartialEq)]
pub struct SettingsAck {
    pub request_id: u64,
    /// Which parts the control message changed (`camera`, `light`, ...).
    pub applied: Vec<String>,
}

/// One envelope (version [`PROTOCOL_VERSION`]) holding `message`.
pub fn encode(message: ServerMessage) -> Vec<u8> {
    use proto::envelope::Body;
    let body = match message {
        ServerMessage::Frame(f) => Body::RenderedFrame(proto::RenderedFrame {
            frame_id: f.frame_id,
            timestamp: f.timestamp,
            width: f.width,
            height: f.height,
            image: Some(match f.image {
                FrameImage::Png(png) => proto::rendered_frame::Image::Png(png),
                FrameImage::Rgba8(rgba) => proto::rendered_frame::Image::Rgba8(rgba),
            }),
            timings: f.timings.into_iter().map(|(stage, ms)| proto::StageTiming { stage, ms }).collect(),
            val_count: f.val_count,
            dropped_frames: f.dropped_frames,
        }),
        ServerMessage::Error(e) => Body::Error(proto::Error {
            code: e.code as i32,
            message: e.message,
            field: e.field.unwrap_or_default(),
            limit: e.limit.unwrap_or_default().to_owned(),
            frame_id: e.frame_id,
            request_id: e.request_id,
        }),
        ServerMessage::Ack(a) => Body::SettingsAck(proto::SettingsAck { request_id: a.request_id, applied: a.applied }),
    };
    proto::Envelope { version: PROTOCOL_VERSION, body: Some(body) }.encode_to_vec()
}

/// The client's encoding of a frame (raw RGB8 colour, f32 metres depth, column-major pose
/// matrix with the translation also in f64, `translation_f64`): what a Rust client sends, and
/// what the tests round-trip through [`decode`].
pub fn encode_rgbd_frame(frame_id: u64, frame: &RgbdFrame) -> Vec<u8> {
    let i = frame.intrinsics;
    let t = frame.camera_to_world.translation;
    let body = proto::envelope::Body::RgbdFrame(proto::RgbdFrame {
        frame_id,
        timestamp: frame.timestamp,
        intrinsics: Some(proto::Intrinsics {
            width: i.width,
            height: i.height,
            fx: i.fx,
            fy: i.fy,
            cx: i.cx,
            cy: i.cy,
        }),
        color: Some(proto::Color { data: Some(proto::color::Data::Rgb8(frame.color.concat())) }),
        depth: Some(proto::Depth {
            data: Some(proto::depth::Data::F32Metres(frame.depth.iter().flat_map(|d| d.to_le_bytes()).collect())),
        }),
        camera_to_world: Some(proto::Pose {
            transform: Some(proto::pose::Transform::Matrix(proto::Matrix4 {
                column_major: glam::DMat4::from(frame.camera_to_world).as_mat4().to_cols_array().to_vec(),
            })),
            translation_f64: Some(proto::DVec3 { x: t.x, y: t.y, z: t.z }),
        }),
    });
    proto::Envelope { version: PROTOCOL_VERSION, body: Some(body) }.encode_to_vec()
}

#[cfg(test)]
mod tests {
    use super::proto::envelope::Body;
    use super::*;

    fn limits() -> Limits {
        Limits::default()
    }

    /// A 4 x 3 frame: colour (x, y, 7), depth 1 + x / 10 m, camera 2 m up the z axis.
    fn frame() -> proto::RgbdFrame {
        let (w, h) = (4u32, 3u32);
        let mut rgb = Vec::new();
        let mut depth = Vec::new();
        for y in 0..h {
            for x in 0..w {
                rgb.extend_from_slice(&[x as u8, y as u8, 7]);
                depth.extend_from_slice(&(1000 + 100 * x as u16).to_le_bytes());
            }
        }
        proto::RgbdFrame {
            frame_id: 42,
            timestamp: 1.5,
            intrinsics: Some(proto::Intrinsics { width: w, height: h, fx: 5.0, fy: 5.0, cx: 1.5, cy: 1.0 }),
            color: Some(proto::Color { data: Some(proto::color::Data::Rgb8(rgb)) }),
            depth: Some(proto::Depth {
                data: Some(proto::depth::Data::U16(proto::DepthU16 { data: depth, units_per_metre: 1000.0 })),
            }),
            camera_to_world: Some(proto::Pose {
                transform: Some(proto::pose::Transform::TranslationRotation(proto::TranslationRotation {
                    translation: Some(proto::Vec3 { x: 0.0, y: 0.0, z: 2.0 }),
                    rotation: Some(proto::Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }),
                })),
                translation_f64: None,
            }),
        }
    }

    fn envelope(body: Body) -> Vec<u8> {
        proto::Envelope { version: PROTOCOL_VERSION, body: Some(body) }.encode_to_vec()
    }

    fn decode_frame_err(edit: impl FnOnce(&mut proto::RgbdFrame)) -> WireError {
        let mut f = frame();
        edit(&mut f);
        decode(&envelope(Body::RgbdFrame(f)), &limits()).expect_err("refused")
    }

    #[test]
    fn a_valid_frame_decodes_to_metres_and_a_pose() {
        let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(frame())), &limits()).expect("valid") else {
            panic!("not a frame");
        };
        assert_eq!(m.frame_id, 42);
        assert_eq!(m.frame.timestamp, 1.5);
        assert_eq!(m.frame.intrinsics, Intrinsics { width: 4, height: 3, fx: 5.0, fy: 5.0, cx: 1.5, cy: 1.0 });
        assert_eq!(m.frame.color[4 + 2], [2, 1, 7]);
        assert_eq!(m.frame.depth.len(), 12);
        assert!((m.frame.depth[3] - 1.3).abs() < 1e-6, "{}", m.frame.depth[3]);
        assert!(m.frame.camera_to_world.translation.abs_diff_eq(DVec3::new(0.0, 0.0, 2.0), 0.0));
    }

    #[test]
    fn encoded_frames_decode_to_the_same_frame() {
        let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(frame())), &limits()).expect("valid") else {
            panic!("not a frame");
        };
        let mut original = m.frame;
        original.depth[0] = f32::NAN;
        original.depth[1] = 0.0;
        // 100 km out with a sub-millimetre part: the f64 translation comes back exactly.
        original.camera_to_world = DAffine3::from_rotation_translation(
            glam::DQuat::from_rotation_y(0.7),
            DVec3::new(100e3 + 1e-4, 2.0, -70e3 - 3e-4),
        );
        let ClientMessage::Frame(again) = decode(&encode_rgbd_frame(9, &original), &limits()).expect("valid") else {
            panic!("not a frame");
        };
        assert_eq!(again.frame_id, 9);
        assert_eq!(again.frame.color, original.color);
        assert!(again.frame.depth[0].is_nan());
        assert_eq!(again.frame.depth[1..], original.depth[1..]);
        assert!(again.frame.camera_to_world.matrix3.abs_diff_eq(original.camera_to_world.matrix3, 1e-6));
        assert_eq!(again.frame.camera_to_world.translation, original.camera_to_world.translation);
    }

    #[test]
    fn byte_lengths_are_checked_against_the_intrinsics() {
        let e = decode_frame_err(|f| {
            if let Some(proto::color::Data::Rgb8(rgb)) = &mut f.color.as_mut().unwrap().data {
                rgb.pop();
            }
        });
        assert_eq!(e.code, ErrorCode::InvalidField);
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.color.rgb8"));
        assert_eq!(e.frame_id, Some(42));
        assert!(e.message.contains("expected 4 x 3 x 3 = 36 bytes"), "{}", e.message);

        let e = decode_frame_err(|f| {
            f.depth = Some(proto::Depth { data: Some(proto::depth::Data::F32Metres(vec![0; 47])) });
        });
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.depth.f32_metres"));
        let e = decode_frame_err(|f| {
            if let Some(proto::depth::Data::U16(d)) = &mut f.depth.as_mut().unwrap().data {
                d.units_per_metre = 0.0;
            }
        });
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.depth.u16.units_per_metre"));
        let e = decode_frame_err(|f| f.color = None);
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.color"));
    }

    #[test]
    fn f32_depth_keeps_nan_and_maps_infinities_to_missing() {
        let mut f = frame();
        let values = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -1.0, 0.0, 2.5];
        let bytes: Vec<u8> = (0..12).flat_map(|i| values[i % values.len()].to_le_bytes()).collect();
        f.depth = Some(proto::Depth { data: Some(proto::depth::Data::F32Metres(bytes)) });
        let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("valid") else {
            panic!("not a frame");
        };
        assert!(m.frame.depth[..3].iter().all(|d| d.is_nan()));
        assert_eq!(m.frame.depth[3..6], [-1.0, 0.0, 2.5]);
    }

    #[test]
    fn png_colour_must_have_the_intrinsics_size() {
        let png = |w: u32, h: u32| {
            let mut bytes = Vec::new();
            image::RgbImage::from_fn(w, h, |x, y| image::Rgb([x as u8, y as u8, 9]))
                .write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png)
                .expect("encode");
            bytes
        };
        let mut f = frame();
        f.color = Some(proto::Color { data: Some(proto::color::Data::Png(png(4, 3))) });
        let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("valid") else {
            panic!("not a frame");
        };
        assert_eq!(m.frame.color[4 + 3], [3, 1, 9]);
        let e = decode_frame_err(|f| f.color = Some(proto::Color { data: Some(proto::color::Data::Png(png(3, 4))) }));
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.color.png"));
        assert!(e.message.contains("3 x 4"), "{}", e.message);
        let e = decode_frame_err(|f| f.color = Some(proto::Color { data: Some(proto::color::Data::Png(vec![1, 2])) }));
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.color.png"));
    }

    #[test]
    fn poses_must_be_finite_unit_and_rigid() {
        let tr = |x: f32, w: f32| proto::Pose {
            transform: Some(proto::pose::Transform::TranslationRotation(proto::TranslationRotation {
                translation: Some(proto::Vec3 { x: 0.0, y: 0.0, z: 0.0 }),
                rotation: Some(proto::Quaternion { x, y: 0.0, z: 0.0, w }),
            })),
            translation_f64: None,
        };
        let field = "rgbd_frame.camera_to_world.translation_rotation.rotation";
        let e = decode_frame_err(|f| f.camera_to_world = Some(tr(f32::NAN, 1.0)));
        assert_eq!(e.field.as_deref(), Some(field));
        let e = decode_frame_err(|f| f.camera_to_world = Some(tr(0.0, 1.1)));
        assert_eq!(e.field.as_deref(), Some(field));
        assert!(e.message.contains("unit quaternion"), "{}", e.message);
        // Within the tolerance: renormalised.
        let mut f = frame();
        f.camera_to_world = Some(tr(0.0, 1.0005));
        decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("nearly unit is fine");

        let matrix = |m: Mat4| proto::Pose {
            transform: Some(proto::pose::Transform::Matrix(proto::Matrix4 {
                column_major: m.to_cols_array().to_vec(),
            })),
            translation_f64: None,
        };
        let field = "rgbd_frame.camera_to_world.matrix.column_major";
        for bad in [
            Mat4::from_scale(Vec3::splat(2.0)),
            Mat4::from_scale(Vec3::new(1.0, 1.0, -1.0)),
            Mat4::from_cols_array(&[1.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]),
        ] {
            let e = decode_frame_err(|f| f.camera_to_world = Some(matrix(bad)));
            assert_eq!(e.field.as_deref(), Some(field), "{bad}");
            assert!(e.message.contains("rigid"), "{}", e.message);
        }
        let e = decode_frame_err(|f| {
            f.camera_to_world = Some(proto::Pose {
                transform: Some(proto::pose::Transform::Matrix(proto::Matrix4 { column_major: vec![1.0; 12] })),
                translation_f64: None,
            })
        });
        assert!(e.message.contains("16 numbers"), "{}", e.message);
        let mut nan = Mat4::IDENTITY.to_cols_array();
        nan[13] = f32::NAN;
        let e = decode_frame_err(|f| f.camera_to_world = Some(matrix(Mat4::from_cols_array(&nan))));
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.camera_to_world.matrix.column_major[13]"));
        let mut f = frame();
        f.camera_to_world = Some(matrix(Mat4::from_rotation_translation(Quat::from_rotation_x(1.0), Vec3::ONE)));
        decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("a rigid matrix");
    }

    #[test]
    fn a_double_translation_replaces_the_float_one() {
        let far = DVec3::new(100e3 + 2e-4, -3.0, 70e3 - 1e-4);
        let mut f = frame();
        f.camera_to_world.as_mut().unwrap().translation_f64 = Some(proto::DVec3 { x: far.x, y: far.y, z: far.z });
        let ClientMessage::Frame(m) = decode(&envelope(Body::RgbdFrame(f)), &limits()).expect("valid") else {
            panic!("not a frame");
        };
        assert_eq!(m.frame.camera_to_world.translation, far);
        let bad = [
            (proto::DVec3 { x: f64::NAN, y: 0.0, z: 0.0 }, "x"),
            (proto::DVec3 { x: 0.0, y: 2e7, z: 0.0 }, "y"),
            (proto::DVec3 { x: 0.0, y: 0.0, z: f64::NEG_INFINITY }, "z"),
        ];
        for (t, axis) in bad {
            let e = decode_frame_err(|f| f.camera_to_world.as_mut().unwrap().translation_f64 = Some(t));
            assert_eq!(e.field.as_deref(), Some(format!("rgbd_frame.camera_to_world.translation_f64.{axis}").as_str()));
        }
        // The transform is still required and checked.
        let e = decode_frame_err(|f| f.camera_to_world.as_mut().unwrap().transform = None);
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.camera_to_world"));
    }

    #[test]
    fn intrinsics_and_limits_name_the_field_and_setting() {
        let e = decode_frame_err(|f| f.intrinsics.as_mut().unwrap().fx = f32::INFINITY);
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.intrinsics.fx"));
        let e = decode_frame_err(|f| f.intrinsics.as_mut().unwrap().cy = f32::NAN);
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.intrinsics.cy"));
        let e = decode_frame_err(|f| f.intrinsics.as_mut().unwrap().width = 5000);
        assert_eq!(e.code, ErrorCode::LimitExceeded);
        assert_eq!(e.limit, Some(limit::MAX_FRAME_SIDE));
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.intrinsics.width"));
        let e = decode_frame_err(|f| f.timestamp = f64::NAN);
        assert_eq!(e.field.as_deref(), Some("rgbd_frame.timestamp"));

        let small = Limits { max_message_bytes: 10, ..limits() };
        let e = decode(&envelope(Body::RgbdFrame(frame())), &small).expect_err("too big");
        assert_eq!((e.code, e.limit), (ErrorCode::LimitExceeded, Some(limit::MAX_MESSAGE_BYTES)));

        let tum = Intrinsics::TUM;
        let settings = RgbdSettings::default();
        check_frame_vals(&tum, &settings, &limits()).expect("80 x 60 VALs");
        let few = Limits { max_vals: 4799, ..limits() };
        let e = check_frame_vals(&tum, &settings, &few).expect_err("4800 > 4799");
        assert_eq!(e.limit, Some(limit::MAX_VALS));
    }

    #[test]
    fn envelopes_are_checked_before_bodies() {
        let e = decode(&[0xff, 0xff, 0xff], &limits()).expect_err("garbage");
        assert_eq!(e.code, ErrorCode::Malformed);
        let e = decode(&[], &limits()).expect_err("empty");
        assert_eq!((e.code, e.field.as_deref()), (ErrorCode::Malformed, None));
        let e =
            decode(&proto::Envelope { version: 0, body: Some(Body::RgbdFrame(frame())) }.encode_to_vec(), &limits())
                .expect_err("version 0");
        assert_eq!((e.code, e.field.as_deref()), (ErrorCode::UnsupportedVersion, Some("version")));
        let e = decode(&proto::Envelope { version: 1, body: None }.encode_to_vec(), &limits()).expect_err("no body");
        assert_eq!((e.code, e.field.as_deref()), (ErrorCode::Malformed, Some("body")));
        let bytes = proto::Envelope { version: 2, body: Some(Body::RgbdFrame(frame())) }.encode_to_vec();
        assert_eq!(decode(&bytes, &limits()).expect_err("v2").code, ErrorCode::UnsupportedVersion);
        let bytes = envelope(Body::SettingsAck(proto::SettingsAck::default()));
        assert_eq!(decode(&bytes, &limits()).expect_err("server body").code, ErrorCode::UnexpectedMessage);
    }

    /// The bytes the viewer's encoder (protobuf.js in src/service/viewer/proto.js) writes for
    /// one Control; tests/e2e/viewer.test.mjs checks that the page writes exactly these.
    const VIEWER_CONTROL: [u8; 23] = [8, 1, 26, 19, 8, 172, 2, 42, 4, 16, 3, 32, 1, 50, 2, 8, 12, 58, 4, 8, 2, 16, 0];
    /// Another: a request id of 0 and `Quality.component` left out (no presence, default
    /// value), floats, and `glossy` alone; also checked by tests/e2e/viewer.test.mjs.
    const VIEWER_CONTROL_FLOATS: [u8; 28] =
        [8, 1, 26, 24, 42, 9, 16, 1, 29, 0, 0, 0, 63, 32, 2, 50, 7, 8, 4, 37, 0, 0, 32, 64, 58, 2, 16, 1];

    #[test]
    fn the_viewers_control_bytes_are_prosts_and_decode() {
        let control = proto::Control {
            request_id: 300,
            quality: Some(proto::Quality { component: 3, format: 1, ..Default::default() }),
            rgbd: Some(proto::RgbdSettings { grid_step: Some(12), ..Default::default() }),
            render: Some(proto::RenderSettings { occlusion: Some(2), glossy: Some(false) }),
            ..Default::default()
        };
        assert_eq!(envelope(Body::Control(control.clone())), VIEWER_CONTROL);
        let floats = proto::Control {
            request_id: 0,
            quality: Some(proto::Quality { component: 1, exposure: Some(0.5), format: 2, ..Default::default() }),
            rgbd: Some(proto::RgbdSettings { grid_step: Some(4), radiance_scale: Some(2.5), ..Default::default() }),
            render: Some(proto::RenderSettings { occlusion: None, glossy: Some(true) }),
            ..Default::default()
        };
        assert_eq!(envelope(Body::Control(floats)), VIEWER_CONTROL_FLOATS);
        let ClientMessage::Control(c) = decode(&VIEWER_CONTROL, &limits()).expect("valid") else { panic!("control") };
        assert_eq!(c.request_id, 300);
        assert_eq!(c.quality.expect("quality").component, Component::Indirect);
        assert_eq!(c.rgbd.expect("rgbd").grid_step, Some(12));
        assert_eq!(
            c.render,
            Some(RenderSettingsPatch { occlusion: Some(Some(Occlusion::Disks)), glossy: Some(false) })
        );

        let unset = proto::Control {
            render: Some(proto::RenderSettings { occlusion: Some(0), glossy: None }),
            ..control.clone()
        };
        let ClientMessage::Control(c) = decode(&envelope(Body::Control(unset)), &limits()).expect("valid") else {
            panic!("control")
        };
        assert_eq!(c.render, Some(RenderSettingsPatch { occlusion: Some(None), glossy: None }), "0: the scene's");
        let bad =
            proto::Control { render: Some(proto::RenderSettings { occlusion: Some(7), glossy: None }), ..control };
        let e = decode(&envelope(Body::Control(bad)), &limits()).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("control.render.occlusion"));
    }

    #[test]
    fn control_messages_validate_each_part() {
        let control = |edit: &dyn Fn(&mut proto::Control)| {
            let mut c = proto::Control { request_id: 7, ..Default::default() };
            edit(&mut c);
            decode(&envelope(Body::Control(c)), &limits())
        };
        let camera = proto::Camera {
            position: Some(proto::Vec3 { x: 0.0, y: 1.0, z: 3.0 }),
            target: Some(proto::Vec3 { x: 0.0, y: 1.0, z: 0.0 }),
            up: None,
            fov_y_deg: 40.0,
            width: 64,
            height: 48,
        };
        let ok = control(&|c| {
            c.camera = Some(camera);
            c.model_transforms = vec![proto::ModelTransform {
                mesh_index: 1,
                translation: Some(proto::Vec3 { x: 1.0, y: 0.0, z: 0.0 }),
                rotation_deg: Some(proto::Vec3 { x: 0.0, y: 90.0, z: 0.0 }),
                scale: None,
            }];
            c.quality = Some(proto::Quality { method: 2, component: 3, exposure: Some(2.0), format: 2 });
            c.rgbd = Some(proto::RgbdSettings { grid_step: Some(4), ..Default::default() });
        })
        .expect("valid");
        let ClientMessage::Control(ok) = ok else { panic!("not a control") };
        assert_eq!(ok.request_id, 7);
        assert_eq!(ok.camera.expect("camera").up, [0.0, 1.0, 0.0]);
        assert_eq!(ok.model_transforms[0].0, 1);
        let quality = ok.quality.expect("quality");
        assert_eq!((quality.method, quality.component), (Method::BruteForce, Component::Indirect));
        assert_eq!(quality.format, StreamImageFormat::Rgba8);
        let rgbd = ok.rgbd.expect("rgbd").apply(&RgbdSettings::default(), "control.rgbd").expect("valid");
        assert_eq!(rgbd.grid_step, 4);

        let e = control(&|c| c.camera = Some(proto::Camera { fov_y_deg: f32::NAN, ..camera })).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("control.camera.fov_y_deg"));
        assert_eq!(e.request_id, Some(7));
        let e = control(&|c| c.camera = Some(proto::Camera { width: 100_000, ..camera })).unwrap_err();
        assert_eq!(e.limit, Some(limit::MAX_FRAME_SIDE));
        let e = control(&|c| c.camera = Some(proto::Camera { target: None, ..camera })).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("control.camera.target"));
        let e = control(&|c| {
            c.model_transforms = vec![proto::ModelTransform {
                mesh_index: 0,
                translation: Some(proto::Vec3::default()),
                rotation_deg: Some(proto::Vec3::default()),
                scale: Some(proto::Vec3 { x: 1.0, y: 0.0, z: 1.0 }),
            }]
        })
        .unwrap_err();
        assert_eq!(e.field.as_deref(), Some("control.model_transforms[0].scale[1]"));
        let ism = control(&|c| c.quality = Some(proto::Quality { method: 3, ..Default::default() })).expect("valid");
        let ClientMessage::Control(ism) = ism else { panic!("not a control") };
        assert_eq!(ism.quality.expect("quality").method, Method::BruteForceIsm);
        let e = control(&|c| c.quality = Some(proto::Quality { method: 9, ..Default::default() })).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("control.quality.method"));
        let e = RgbdSettingsPatch { min_depth: Some(20.0), ..Default::default() }
            .apply(&RgbdSettings::default(), "control.rgbd")
            .unwrap_err();
        assert_eq!(e.field.as_deref(), Some("control.rgbd.max_depth"));
        // The scene file's bounds: a grid step of 100 is refused, as in a scene file.
        let e = RgbdSettingsPatch { grid_step: Some(100), ..Default::default() }
            .apply(&RgbdSettings::default(), "control.rgbd")
            .unwrap_err();
        assert_eq!((e.code, e.field.as_deref()), (ErrorCode::InvalidField, Some("control.rgbd.grid_step")));
        assert_eq!(e.message, "control.rgbd.grid_step: must be in 1..=64, got 100");
        let e = RgbdSettingsPatch { min_depth: Some(0.0), ..Default::default() }
            .apply(&RgbdSettings::default(), "control.rgbd")
            .unwrap_err();
        assert_eq!(e.field.as_deref(), Some("control.rgbd.min_depth"));
    }

    #[test]
    fn server_messages_encode_as_version_1_envelopes() {
        let frame = RenderedFrame {
            frame_id: 3,
            timestamp: 0.25,
            width: 2,
            height: 1,
            image: FrameImage::Rgba8(vec![1; 8]),
            timings: vec![("gather".to_owned(), 1.5)],
            val_count: 100,
            dropped_frames: 2,
        };
        let envelope = proto::Envelope::decode(encode(ServerMessage::Frame(frame)).as_slice()).expect("decodes");
        assert_eq!(envelope.version, PROTOCOL_VERSION);
        let Some(Body::RenderedFrame(f)) = envelope.body else { panic!("not a frame") };
        assert_eq!((f.frame_id, f.width, f.val_count, f.dropped_frames), (3, 2, 100, 2));
        assert_eq!(f.timings[0].stage, "gather");
        assert_eq!(f.image, Some(proto::rendered_frame::Image::Rgba8(vec![1; 8])));

        let error =
            WireError::limit(limit::MAX_VALS, Some("rgbd_frame.intrinsics".to_owned()), "too many").with_frame(5);
        let envelope = proto::Envelope::decode(encode(ServerMessage::Error(error)).as_slice()).expect("decodes");
        let Some(Body::Error(e)) = envelope.body else { panic!("not an error") };
        assert_eq!(e.code(), ErrorCode::LimitExceeded);
        assert_eq!((e.limit.as_str(), e.field.as_str()), ("max_vals", "rgbd_frame.intrinsics"));
        assert_eq!((e.frame_id, e.request_id), (Some(5), None));

        let ack = SettingsAck { request_id: 8, applied: vec!["camera".to_owned()] };
        let envelope = proto::Envelope::decode(encode(ServerMessage::Ack(ack)).as_slice()).expect("decodes");
        let Some(Body::SettingsAck(a)) = envelope.body else { panic!("not an ack") };
        assert_eq!((a.request_id, a.applied), (8, vec!["camera".to_owned()]));
    }
}
