//! The image payloads of an MCAP recording: checked when the file is opened, converted to
//! colour and depth when a frame is asked for.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::msg;
use crate::rgbd::Intrinsics;
use crate::rgbd::reader::RecordingError;

/// The image payloads of one frame, as recorded (a colour image may serve two frames).
#[derive(Clone, Debug)]
pub struct FrameImages {
    pub(super) colour: Arc<ImagePayload>,
    pub(super) depth: Arc<ImagePayload>,
}

/// One `sensor_msgs/msg/Image` with the name of its record, its layout checked at open.
#[derive(Clone, Debug)]
pub(super) struct ImagePayload {
    pub(super) record: String,
    pub(super) frame_id: String,
    width: u32,
    height: u32,
    encoding: String,
    is_bigendian: bool,
    step: usize,
    pub(super) data: Vec<u8>,
    /// Depth units per metre (integer depth only).
    depth_scale: f32,
}

/// Pixel layouts read: bytes per pixel.
fn bytes_per_pixel(encoding: &str) -> Option<usize> {
    Some(match encoding {
        "mono8" => 1,
        "rgb8" | "bgr8" => 3,
        "rgba8" | "bgra8" | "32FC1" => 4,
        "16UC1" | "mono16" => 2,
        _ => return None,
    })
}

const COLOUR_ENCODINGS: [&str; 5] = ["rgb8", "bgr8", "rgba8", "bgra8", "mono8"];
const DEPTH_ENCODINGS: [&str; 3] = ["16UC1", "mono16", "32FC1"];

/// A decoded image's layout checked (`encoding` one relume reads, `step` and `data` long enough),
/// its pixels copied; with its stamp (s).
pub(super) fn image_payload(
    record: &str,
    image: msg::Image,
    is_depth: bool,
    depth_scale: f32,
) -> Result<(f64, ImagePayload), String> {
    let encodings: &[&str] = if is_depth { &DEPTH_ENCODINGS } else { &COLOUR_ENCODINGS };
    if !encodings.contains(&image.encoding.as_str()) {
        let what = if is_depth { "depth" } else { "colour" };
        return Err(format!(
            "field `encoding`: `{}` is not a {what} encoding relume reads ({encodings:?})",
            image.encoding
        ));
    }
    let bpp =
        bytes_per_pixel(&image.encoding).ok_or_else(|| format!("field `encoding`: `{}` unknown", image.encoding))?;
    if image.width == 0 || image.height == 0 {
        return Err(format!("fields `width`, `height`: image is {}x{}", image.width, image.height));
    }
    let row = image.width as usize * bpp;
    let step = image.step as usize;
    if step < row {
        return Err(format!("field `step`: {step} bytes per row, fewer than width {} x {bpp} bytes", image.width));
    }
    let needed = step * (image.height as usize - 1) + row;
    if image.data.len() < needed {
        return Err(format!(
            "field `data`: {} bytes, fewer than the {needed} of {} rows of {step} bytes",
            image.data.len(),
            image.height
        ));
    }
    if image.is_bigendian > 1 {
        return Err(format!("field `is_bigendian`: must be 0 or 1, got {}", image.is_bigendian));
    }
    let stamp = image.header.stamp;
    if stamp.nanosec >= 1_000_000_000 {
        return Err(format!("field `header.stamp.nanosec`: {} is not below 1e9", stamp.nanosec));
    }
    Ok((
        stamp.seconds(),
        ImagePayload {
            record: record.to_owned(),
            frame_id: image.header.frame_id,
            width: image.width,
            height: image.height,
            encoding: image.encoding,
            is_bigendian: image.is_bigendian == 1,
            step,
            data: image.data.into_owned(),
            depth_scale,
        },
    ))
}

/// Colour (sRGB, row-major) and depth (m) of a frame's images, checked against `intrinsics`.
pub(in crate::rgbd) fn decode_frame(
    file: &Path,
    images: &FrameImages,
    intrinsics: &Intrinsics,
) -> Result<(Vec<[u8; 3]>, Vec<f32>), RecordingError> {
    for image in [&images.colour, &images.depth] {
        check_size(file, image, intrinsics)?;
    }
    Ok((colour_pixels(&images.colour), depth_metres(&images.depth)))
}

/// The image's size against the intrinsics; the error names the file and the record.
pub(super) fn check_size(file: &Path, image: &ImagePayload, intrinsics: &Intrinsics) -> Result<(), RecordingError> {
    if (image.width, image.height) == (intrinsics.width, intrinsics.height) {
        return Ok(());
    }
    Err(RecordingError::ImageSize {
        file: PathBuf::from(format!("{}: {}", file.display(), image.record)),
        width: image.width,
        height: image.height,
        expected_width: intrinsics.width,
        expected_height: intrinsics.height,
    })
}

/// The rows of an image, `step` apart, each `width * bpp` bytes (the layout was checked).
fn rows(image: &ImagePayload, bpp: usize) -> impl Iterator<Item = &[u8]> {
    let row = image.width as usize * bpp;
    (0..image.height as usize).map(move |y| &image.data[y * image.step..y * image.step + row])
}

fn colour_pixels(image: &ImagePayload) -> Vec<[u8; 3]> {
    let bpp = bytes_per_pixel(&image.encoding).unwrap_or(3);
    let mut pixels = Vec::with_capacity((image.width * image.height) as usize);
    for row in rows(image, bpp) {
        pixels.extend(row.chunks_exact(bpp).map(|p| match image.encoding.as_str() {
            "mono8" => [p[0]; 3],
            "bgr8" | "bgra8" => [p[2], p[1], p[0]],
            _ => [p[0], p[1], p[2]],
        }));
    }
    pixels
}

fn depth_metres(image: &ImagePayload) -> Vec<f32> {
    let float = image.encoding == "32FC1";
    let bpp = if float { 4 } else { 2 };
    let mut depth = Vec::with_capacity((image.width * image.height) as usize);
    for row in rows(image, bpp) {
        depth.extend(row.chunks_exact(bpp).map(|p| {
            if float {
                let bytes = [p[0], p[1], p[2], p[3]];
                let d = if image.is_bigendian { f32::from_be_bytes(bytes) } else { f32::from_le_bytes(bytes) };
                if d.is_finite() && d > 0.0 { d } else { 0.0 }
            } else {
                let raw = if image.is_bigendian {
                    u16::from_be_bytes([p[0], p[1]])
                } else {
                    u16::from_le_bytes([p[0], p[1]])
                };
                f32::from(raw) / image.depth_scale
            }
        }));
    }
    depth
}
