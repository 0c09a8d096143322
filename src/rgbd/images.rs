//! A recording's image files (TUM, Open3D/Redwood): decoded and checked against the
//! intrinsics, colour to RGB, depth to metres.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use image::{ColorType, DynamicImage, ImageDecoder, ImageFormat, ImageReader};

use super::Intrinsics;
use super::reader::{RecordingError, io_error};

/// The format of a recording's image file by its extension: JPEG for `.jpg`/`.jpeg`, else PNG.
fn image_format(file: &Path) -> ImageFormat {
    match file.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("jpg" | "jpeg") => ImageFormat::Jpeg,
        _ => ImageFormat::Png,
    }
}

/// Opens an image of the recording (`format`), checks its size against `intrinsics` before
/// decoding it.
fn decode_image(
    dir: &Path,
    file: &Path,
    format: ImageFormat,
    intrinsics: &Intrinsics,
    accept: impl Fn(ColorType) -> bool,
    wanted: &str,
) -> Result<DynamicImage, RecordingError> {
    let image_error = |message: String| RecordingError::Image { file: file.to_path_buf(), message };
    let name = format.extensions_str().first().map_or("image".to_owned(), |e| e.to_ascii_uppercase());
    let reader = File::open(dir.join(file)).map_err(|source| io_error(file, source))?;
    let decoder = ImageReader::with_format(BufReader::new(reader), format)
        .into_decoder()
        .map_err(|e| image_error(format!("cannot decode {name}: {e}")))?;
    let (width, height) = decoder.dimensions();
    if (width, height) != (intrinsics.width, intrinsics.height) {
        return Err(RecordingError::ImageSize {
            file: file.to_path_buf(),
            width,
            height,
            expected_width: intrinsics.width,
            expected_height: intrinsics.height,
        });
    }
    let color_type = decoder.color_type();
    if !accept(color_type) {
        return Err(image_error(format!("expected {wanted} {name}, got {color_type:?}")));
    }
    DynamicImage::from_decoder(decoder).map_err(|e| image_error(format!("cannot decode {name}: {e}")))
}

/// 8-bit RGB or RGBA PNG, or 8-bit RGB JPEG, to row-major RGB (alpha dropped).
pub(super) fn load_colour(dir: &Path, file: &Path, intrinsics: &Intrinsics) -> Result<Vec<[u8; 3]>, RecordingError> {
    let accept = |c| matches!(c, ColorType::Rgb8 | ColorType::Rgba8);
    let image = decode_image(dir, file, image_format(file), intrinsics, accept, "an 8-bit RGB or RGBA")?;
    let rgb = match image {
        DynamicImage::ImageRgb8(rgb) => rgb,
        other => other.into_rgb8(),
    };
    Ok(rgb.into_raw().chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
}

/// 16-bit grayscale PNG to row-major depth in metres (`value / depth_scale`; 0 stays 0).
pub(super) fn load_depth(
    dir: &Path,
    file: &Path,
    intrinsics: &Intrinsics,
    depth_scale: f32,
) -> Result<Vec<f32>, RecordingError> {
    let accept = |c| c == ColorType::L16;
    let image = decode_image(dir, file, ImageFormat::Png, intrinsics, accept, "a 16-bit grayscale")?;
    let DynamicImage::ImageLuma16(depth) = image else {
        return Err(RecordingError::Image { file: file.to_path_buf(), message: "decoded as non-16-bit".to_owned() });
    };
    Ok(depth.into_raw().into_iter().map(|v| f32::from(v) / depth_scale).collect())
}
