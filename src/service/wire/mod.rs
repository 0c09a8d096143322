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

use crate::renderer::estimate::ErrorEstimate;
use crate::rgbd::{Intrinsics, RgbdFrame, RgbdSettings};
use crate::scene::{
    CameraDescription, MAX_COORDINATE_M, Occlusion, Quality, ScaleDescription, SceneError, TransformDescription,
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
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderSettingsPatch {
    /// `Some(None)`: back to the scene's setting.
    pub occlusion: Option<Option<Occlusion>>,
    pub glossy: Option<bool>,
    /// `Some(None)`: back to the scene's level.
    pub quality: Option<Option<Quality>>,
    /// `Some(None)`: no budget.
    pub budget_ms: Option<Option<f32>>,
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
            let occlusion =
                r.occlusion.map(|v| proto_enum(v, "control.render.occlusion").map(occlusion_from_proto)).transpose()?;
            let quality =
                r.quality.map(|v| proto_enum(v, "control.render.quality").map(quality_from_proto)).transpose()?;
            let budget_ms = match r.budget_ms {
                None => None,
                Some(0.0) => Some(None),
                Some(ms) => {
                    crate::scene::settings::validate_budget_ms(ms, "control.render.budget_ms")
                        .map_err(WireError::from_scene)?;
                    Some(Some(ms))
                }
            };
            Some(RenderSettingsPatch { occlusion, glossy: r.glossy, quality, budget_ms })
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

/// A protobuf enum's `value`, or an error naming `field` when the enum has no such value.
fn proto_enum<E: TryFrom<i32>>(value: i32, field: &str) -> Result<E, WireError> {
    E::try_from(value).map_err(|_| WireError::invalid(field, format!("unknown value {value}")))
}

fn decode_quality(q: proto::Quality) -> Result<StreamQuality, WireError> {
    let field = "control.quality";
    let method = match proto_enum(q.method, &format!("{field}.method"))? {
        proto::Method::Unspecified | proto::Method::Sparse => Method::Sparse,
        proto::Method::BruteForce => Method::BruteForce,
        proto::Method::BruteForceIsm => Method::BruteForceIsm,
    };
    let component = match proto_enum(q.component, &format!("{field}.component"))? {
        proto::Component::Unspecified | proto::Component::Full => Component::Full,
        proto::Component::Direct => Component::Direct,
        proto::Component::Indirect => Component::Indirect,
    };
    let format = match proto_enum(q.format, &format!("{field}.format"))? {
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
    pub error_estimate: Option<ErrorEstimate>,
    /// The level the frame ran at, and its parameters (name, value).
    pub quality: Quality,
    pub parameters: Vec<(String, String)>,
    pub budget_ms: Option<f32>,
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
            error_estimate: f.error_estimate.map(|e| proto::ErrorEstimate {
                rel_rmse: e.rel_rmse,
                spread: e.spread,
                reference_noise: e.reference_noise,
                pixels: e.pixels,
                samples: e.samples,
                reference_vals: e.reference_vals,
                reference_rsm_resolution: e.reference_rsm_resolution.unwrap_or(0),
                ms: e.ms,
            }),
            quality: quality_to_proto(f.quality) as i32,
            parameters: f.parameters.into_iter().map(|(name, value)| proto::Parameter { name, value }).collect(),
            budget_ms: f.budget_ms.unwrap_or(0.0),
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

/// A stream's visibility mode (`None`: back to the scene's setting, and for a protobuf value
/// no mode of the registry is named by). The protobuf value `OCCLUSION_<NAME>` is the mode
/// named `<name>` in scene files (`gpu/visibility/settings.rs`): matched by name, so the list
/// of modes is the registry's, and `tests.rs` checks that `relume.proto` offers every one.
pub fn occlusion_from_proto(mode: proto::Occlusion) -> Option<Occlusion> {
    let name = mode.as_str_name().strip_prefix("OCCLUSION_")?.to_ascii_lowercase();
    Occlusion::from_name(&name)
}

/// The protobuf value of a visibility mode, if `relume.proto` has one.
pub fn occlusion_to_proto(mode: Occlusion) -> Option<proto::Occlusion> {
    proto::Occlusion::from_str_name(&format!("OCCLUSION_{}", mode.name().to_ascii_uppercase()))
}

/// A stream's quality level (`None`: back to the scene's).
pub fn quality_from_proto(level: proto::QualityLevel) -> Option<Quality> {
    match level {
        proto::QualityLevel::Unspecified => None,
        proto::QualityLevel::Fast => Some(Quality::Fast),
        proto::QualityLevel::Balanced => Some(Quality::Balanced),
        proto::QualityLevel::Accurate => Some(Quality::Accurate),
        proto::QualityLevel::Reference => Some(Quality::Reference),
    }
}

/// The protobuf value of every quality level: exhaustive, so a level added to the scene's
/// settings without one in `relume.proto` does not compile.
pub fn quality_to_proto(level: Quality) -> proto::QualityLevel {
    match level {
        Quality::Fast => proto::QualityLevel::Fast,
        Quality::Balanced => proto::QualityLevel::Balanced,
        Quality::Accurate => proto::QualityLevel::Accurate,
        Quality::Reference => proto::QualityLevel::Reference,
    }
}

#[cfg(test)]
mod tests;
