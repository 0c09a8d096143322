//! Linear HDR images, their tone mapping and output, and the error metrics that compare them.
//!
//! Tone mapping is deliberately simple and documented: multiply by the exposure, clip to
//! [0, 1], encode as sRGB. Auto exposure maps the 99th-percentile luminance of covered pixels
//! to 1.

use glam::Vec3;
use std::path::Path;

/// Luminance of a linear RGB triple (Rec. 709 weights).
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// Errors writing images.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("writing {path}: {source}")]
    Write { path: String, source: ::image::ImageError },
    #[error("encoding a PNG: {0}")]
    Encode(::image::ImageError),
    #[error("{pixels} pixels for a {width}x{height} image")]
    Size { pixels: usize, width: u32, height: u32 },
}

/// Linear radiance (W/(m² sr)) per pixel, row-major from the top; alpha is coverage (1 where
/// geometry was hit, 0 for background).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 4]>,
}

impl LinearImage {
    pub fn rgb(&self, i: usize) -> Vec3 {
        let p = self.pixels[i];
        Vec3::new(p[0], p[1], p[2])
    }

    pub fn covered(&self, i: usize) -> bool {
        self.pixels[i][3] > 0.0
    }

    /// Number of covered pixels.
    pub fn coverage(&self) -> usize {
        (0..self.pixels.len()).filter(|&i| self.covered(i)).count()
    }

    /// Pixel-wise sum (coverage is the union).
    pub fn add(&self, other: &LinearImage) -> LinearImage {
        let pixels = self
            .pixels
            .iter()
            .zip(&other.pixels)
            .map(|(a, b)| [a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3].max(b[3])])
            .collect();
        LinearImage { width: self.width, height: self.height, pixels }
    }

    /// Sum and largest value of the covered pixels' luminance.
    pub fn luminance_sum_and_peak(&self) -> (f64, f64) {
        (0..self.pixels.len())
            .filter(|&i| self.covered(i))
            .map(|i| luminance(self.rgb(i)) as f64)
            .fold((0.0, 0.0), |(sum, peak), y| (sum + y, f64::max(peak, y)))
    }

    /// Exposure that maps the 99th-percentile luminance of covered pixels to 1 (1 if dark).
    pub fn auto_exposure(&self) -> f32 {
        let mut y: Vec<f32> =
            (0..self.pixels.len()).filter(|&i| self.covered(i)).map(|i| luminance(self.rgb(i))).collect();
        if y.is_empty() {
            return 1.0;
        }
        y.sort_by(f32::total_cmp);
        let p99 = y[((y.len() - 1) as f32 * 0.99) as usize];
        if p99 > 0.0 && p99.is_finite() { 1.0 / p99 } else { 1.0 }
    }

    /// 8-bit sRGB after `exposure` and clipping.
    pub fn tone_map(&self, exposure: f32) -> ::image::RgbImage {
        let mut out = ::image::RgbImage::new(self.width, self.height);
        for (i, px) in out.pixels_mut().enumerate() {
            let c = self.rgb(i) * exposure;
            *px = ::image::Rgb([encode_srgb(c.x), encode_srgb(c.y), encode_srgb(c.z)]);
        }
        out
    }

    pub fn write_png(&self, path: &Path, exposure: f32) -> Result<(), ImageError> {
        self.tone_map(exposure)
            .save(path)
            .map_err(|source| ImageError::Write { path: path.display().to_string(), source })
    }

    /// The PNG file [`LinearImage::write_png`] would write, in memory.
    pub fn encode_png(&self, exposure: f32) -> Result<Vec<u8>, ImageError> {
        png_bytes(&self.tone_map(exposure))
    }

    /// 8-bit sRGB after `exposure` and clipping, with alpha = coverage (255 where geometry
    /// was hit): `width * height * 4` bytes, rows from the top.
    pub fn tone_map_rgba8(&self, exposure: f32) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.pixels.len() * 4);
        for p in &self.pixels {
            let c = Vec3::new(p[0], p[1], p[2]) * exposure;
            let alpha = if p[3] > 0.0 { 255 } else { 0 };
            out.extend_from_slice(&[encode_srgb(c.x), encode_srgb(c.y), encode_srgb(c.z), alpha]);
        }
        out
    }

    /// Linear float radiance as OpenEXR (RGBA f32; alpha = coverage).
    pub fn write_exr(&self, path: &Path) -> Result<(), ImageError> {
        let data: Vec<f32> = self.pixels.iter().flatten().copied().collect();
        let img =
            ::image::Rgba32FImage::from_raw(self.width, self.height, data).expect("pixel count matches dimensions");
        img.save(path).map_err(|source| ImageError::Write { path: path.display().to_string(), source })
    }
}

/// Linear [0, 1] to 8-bit sRGB (values outside are clipped).
pub fn encode_srgb(linear: f32) -> u8 {
    let c = if linear.is_finite() { linear.clamp(0.0, 1.0) } else { 0.0 };
    let s = if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5) as u8
}

/// 8-bit sRGB to linear [0, 1].
pub fn decode_srgb(encoded: u8) -> f32 {
    let s = encoded as f32 / 255.0;
    if s <= 0.040_45 { s / 12.92 } else { ((s + 0.055) / 1.055).powf(2.4) }
}

/// Relative RMSE of `test` against `reference` over pixels the reference covers:
/// `sqrt(sum |t - r|^2 / sum |r|^2)` over RGB. 0 when both are black.
pub fn relative_rmse(test: &LinearImage, reference: &LinearImage) -> f64 {
    let (num, den) = squared_sums(reference, |i| f64::from((test.rgb(i) - reference.rgb(i)).length_squared()), |_| 1.0);
    ratio_sqrt(num, den)
}

/// [`relative_rmse`] with the reference's own noise taken out: `reference_variance` holds, per
/// pixel and channel, the variance of the reference's estimate (`s²`), and
/// `sqrt(max(0, sum |t - r|² - sum s²) / sum |r|²)` estimates the error against the noise-free
/// reference, since `E|t - r|² = |t - r_true|² + s²` for an unbiased `r`. Equals
/// [`relative_rmse`] when every `s²` is 0.
pub fn noise_corrected_relative_rmse(test: &LinearImage, reference: &LinearImage, reference_variance: &[Vec3]) -> f64 {
    weighted_noise_corrected_relative_rmse(test, reference, reference_variance, |_| 1.0)
}

/// [`noise_corrected_relative_rmse`] with every pixel's terms weighted by `weight(i)`: over a
/// sample of an image's pixels drawn with unequal probabilities, the inverse probabilities
/// make each sum an unbiased estimate of the whole image's (Horvitz and Thompson).
pub fn weighted_noise_corrected_relative_rmse(
    test: &LinearImage,
    reference: &LinearImage,
    reference_variance: &[Vec3],
    weight: impl Fn(usize) -> f64,
) -> f64 {
    let (num, den) =
        squared_sums(reference, |i| weight(i) * f64::from((test.rgb(i) - reference.rgb(i)).length_squared()), &weight);
    let (noise, _) = squared_sums(reference, |i| weight(i) * f64::from(reference_variance[i].element_sum()), &weight);
    ratio_sqrt((num - noise).max(0.0), den)
}

/// The reference's relative standard error: `sqrt(sum s² / sum |r|²)` over the pixels it covers,
/// on the scale of [`relative_rmse`] (an error below it cannot be told from the reference's noise).
pub fn relative_stderr(reference: &LinearImage, reference_variance: &[Vec3]) -> f64 {
    weighted_relative_stderr(reference, reference_variance, |_| 1.0)
}

/// [`relative_stderr`] with every pixel's terms weighted by `weight(i)`.
pub fn weighted_relative_stderr(
    reference: &LinearImage,
    reference_variance: &[Vec3],
    weight: impl Fn(usize) -> f64,
) -> f64 {
    let (noise, den) = squared_sums(reference, |i| weight(i) * f64::from(reference_variance[i].element_sum()), &weight);
    ratio_sqrt(noise, den)
}

/// (sum of `term(i)`, sum of `weight(i) |r_i|²`) over the pixels `reference` covers, in f64.
fn squared_sums(reference: &LinearImage, term: impl Fn(usize) -> f64, weight: impl Fn(usize) -> f64) -> (f64, f64) {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for i in (0..reference.pixels.len()).filter(|&i| reference.covered(i)) {
        num += term(i);
        den += weight(i) * f64::from(reference.rgb(i).length_squared());
    }
    (num, den)
}

/// `sqrt(num / den)`: 0 when both are 0, infinite when only `den` is.
fn ratio_sqrt(num: f64, den: f64) -> f64 {
    if den > 0.0 {
        (num / den).sqrt()
    } else if num > 0.0 {
        f64::INFINITY
    } else {
        0.0
    }
}

/// Mean FLIP error (0 = identical, 1 = maximal) between the tone-mapped images, both at the
/// same `exposure`, averaged over pixels the reference covers.
pub fn flip_mean(test: &LinearImage, reference: &LinearImage, exposure: f32) -> f64 {
    let to_flip = |img: &LinearImage| {
        let rgb = img.tone_map(exposure);
        nv_flip::FlipImageRgb8::with_data(img.width, img.height, rgb.as_raw())
    };
    let error = nv_flip::flip(to_flip(reference), to_flip(test), nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec();
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (i, e) in error.iter().enumerate() {
        if reference.covered(i) {
            sum += *e as f64;
            n += 1;
        }
    }
    if n > 0 { sum / n as f64 } else { 0.0 }
}

/// An 8-bit sRGB image (row-major from the top, `width * height` pixels) encoded as PNG.
pub fn encode_rgb8_png(width: u32, height: u32, pixels: &[[u8; 3]]) -> Result<Vec<u8>, ImageError> {
    png_bytes(&rgb8_image(width, height, pixels)?)
}

/// `pixels` (row-major from the top) as an image; an error unless there are `width * height`.
pub fn rgb8_image(width: u32, height: u32, pixels: &[[u8; 3]]) -> Result<::image::RgbImage, ImageError> {
    ::image::RgbImage::from_raw(width, height, pixels.as_flattened().to_vec()).ok_or(ImageError::Size {
        pixels: pixels.len(),
        width,
        height,
    })
}

fn png_bytes(image: &::image::RgbImage) -> Result<Vec<u8>, ImageError> {
    let mut png = Vec::new();
    image.write_to(&mut std::io::Cursor::new(&mut png), ::image::ImageFormat::Png).map_err(ImageError::Encode)?;
    Ok(png)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(values: &[[f32; 4]]) -> LinearImage {
        LinearImage { width: values.len() as u32, height: 1, pixels: values.to_vec() }
    }

    #[test]
    fn srgb_round_trips() {
        for v in 0..=255u8 {
            assert_eq!(encode_srgb(decode_srgb(v)), v);
        }
        assert_eq!(encode_srgb(f32::NAN), 0);
        assert_eq!(encode_srgb(7.0), 255);
    }

    #[test]
    fn encoded_png_decodes_to_the_tone_mapped_image() {
        let img = image(&[[0.5, 0.25, 1.0, 1.0], [0.0, 0.0, 0.0, 0.0]]);
        let png = img.encode_png(2.0).expect("encodes");
        let decoded = ::image::load_from_memory(&png).expect("decodes").into_rgb8();
        assert_eq!(decoded, img.tone_map(2.0));
        let rgba = img.tone_map_rgba8(2.0);
        assert_eq!(&rgba[..4], &[255, encode_srgb(0.5), 255, 255]);
        assert_eq!(&rgba[4..], &[0, 0, 0, 0]);
    }

    /// With a noise-free reference (every variance 0) the corrected error is the raw one, to
    /// the bit; with a reference made noisy by known noise (uniform, variance a²/3), the raw error of the truth
    /// against it is the noise level while the corrected error is ~0 (within 0.03, i.e. a few
    /// standard errors of the 30,000 squared deviations), and `relative_stderr` recovers the
    /// noise level within 2 %.
    #[test]
    fn noise_corrected_error_removes_only_the_reference_noise() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let n = 10_000;
        let truth: Vec<[f32; 4]> = (0..n).map(|i| [1.0 + (i % 7) as f32 * 0.1, 0.5, 0.25, 1.0]).collect();
        let test: Vec<[f32; 4]> = truth.iter().map(|p| [p[0] * 1.1, p[1] * 0.9, p[2], 1.0]).collect();
        let (truth, test) = (image(&truth), image(&test));
        let zero = vec![Vec3::ZERO; n];
        assert_eq!(noise_corrected_relative_rmse(&test, &truth, &zero), relative_rmse(&test, &truth));
        assert_eq!(relative_stderr(&truth, &zero), 0.0);

        let a = 0.2f32;
        let mut noisy = truth.clone();
        for p in &mut noisy.pixels {
            for c in &mut p[..3] {
                *c += rng.random_range(-a..a);
            }
        }
        let variance = vec![Vec3::splat(a * a / 3.0); n];
        let level = relative_stderr(&noisy, &variance);
        assert!(
            (relative_rmse(&truth, &noisy) / level - 1.0).abs() < 0.02,
            "raw {} vs noise {level}",
            relative_rmse(&truth, &noisy)
        );
        let corrected = noise_corrected_relative_rmse(&truth, &noisy, &variance);
        assert!(corrected < 0.03, "the truth against a noisy reference: corrected {corrected}, noise {level}");
        let method = relative_rmse(&test, &truth);
        let corrected = noise_corrected_relative_rmse(&test, &noisy, &variance);
        assert!((corrected / method - 1.0).abs() < 0.05, "a method's error {method} recovered as {corrected}");
        assert!(relative_rmse(&test, &noisy) > method * 1.05, "the raw error is inflated by the noise");
    }

    #[test]
    fn relative_rmse_ignores_background_and_scales() {
        let r = image(&[[1.0, 1.0, 1.0, 1.0], [5.0, 5.0, 5.0, 0.0]]);
        let t = image(&[[1.1, 1.1, 1.1, 1.0], [0.0, 0.0, 0.0, 0.0]]);
        assert!((relative_rmse(&t, &r) - 0.1).abs() < 1e-6);
        assert_eq!(relative_rmse(&r, &r), 0.0);
    }

    #[test]
    fn flip_is_zero_for_identical_and_positive_for_different() {
        let w = 32;
        let px: Vec<[f32; 4]> = (0..w * w).map(|i| [(i % w) as f32 / w as f32, 0.5, 0.2, 1.0]).collect();
        let a = LinearImage { width: w, height: w, pixels: px.clone() };
        let b = LinearImage { width: w, height: w, pixels: px.iter().map(|p| [p[0] * 0.5, p[1], p[2], 1.0]).collect() };
        assert!(flip_mean(&a, &a, 1.0) < 1e-6);
        assert!(flip_mean(&b, &a, 1.0) > 0.01);
    }
}
