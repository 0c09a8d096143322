//! Diffuse textures: decoding image files (PNG, JPEG, OpenEXR) into sRGB-encoded RGBA8, the scene's
//! texture table (one entry per file, however many materials use it), and the `map_Kd`
//! statement's options.

use std::collections::HashMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use image::{ColorType, DynamicImage, ImageReader, Limits};

use super::Texture;

/// Largest texture side, texels.
pub const MAX_TEXTURE_SIDE: u32 = 8192;

/// The scene's texture table, filled as materials that use textures are resolved.
#[derive(Debug, Default)]
pub(crate) struct Textures {
    /// The textures, in order of first use; [`super::Material::diffuse_texture`] indexes them.
    pub textures: Vec<Texture>,
    /// Canonical file path to index into `textures`.
    by_file: HashMap<PathBuf, u32>,
}

impl Textures {
    /// The index of the texture in file `path`, loading it on first use. Two paths naming the
    /// same file (after resolving `..`, `.` and links) share one texture. The error message
    /// names `path`.
    pub fn load(&mut self, path: &Path) -> Result<u32, String> {
        let canonical =
            std::fs::canonicalize(path).map_err(|e| format!("cannot read texture {}: {e}", path.display()))?;
        if let Some(&index) = self.by_file.get(&canonical) {
            return Ok(index);
        }
        let texture = decode(path).map_err(|message| format!("texture {}: {message}", path.display()))?;
        self.insert(canonical, texture)
    }

    /// The index of the texture encoded in `bytes` (an image embedded in a glTF file), which
    /// `key` names (`scene.glb#images[2]`): decoded on first use of `key`.
    pub fn load_bytes(&mut self, key: PathBuf, bytes: &[u8]) -> Result<u32, String> {
        if let Some(&index) = self.by_file.get(&key) {
            return Ok(index);
        }
        let texture = decode_bytes(bytes, &key).map_err(|message| format!("texture {}: {message}", key.display()))?;
        self.insert(key, texture)
    }

    fn insert(&mut self, key: PathBuf, texture: Texture) -> Result<u32, String> {
        let index = u32::try_from(self.textures.len()).map_err(|_| "too many textures".to_owned())?;
        self.textures.push(texture);
        self.by_file.insert(key, index);
        Ok(index)
    }
}

/// Reads and decodes one image file into an sRGB-encoded RGBA8 [`Texture`]. 8- and 16-bit
/// images keep their (sRGB) encoding; floating-point images (OpenEXR), which are linear, are
/// sRGB-encoded.
pub(crate) fn decode(path: &Path) -> Result<Texture, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
    decode_bytes(&bytes, path)
}

/// [`decode`] for an image file's bytes; `path` names it in the texture.
fn decode_bytes(bytes: &[u8], path: &Path) -> Result<Texture, String> {
    let reader = || -> Result<ImageReader<Cursor<&[u8]>>, String> {
        let reader =
            ImageReader::new(Cursor::new(bytes)).with_guessed_format().map_err(|e| format!("cannot read: {e}"))?;
        if reader.format().is_none() {
            return Err("not an image file relume can read (PNG, JPEG or OpenEXR)".to_owned());
        }
        Ok(reader)
    };
    let (width, height) = reader()?.into_dimensions().map_err(|e| format!("cannot decode: {e}"))?;
    if width == 0 || height == 0 || width > MAX_TEXTURE_SIDE || height > MAX_TEXTURE_SIDE {
        return Err(format!("is {width} x {height} texels; each side must be in 1..={MAX_TEXTURE_SIDE}"));
    }
    let mut reader = reader()?;
    // The size is bounded above; the default allocation limit would refuse a 16-bit RGBA
    // image of the largest size.
    reader.limits(Limits::no_limits());
    let image = reader.decode().map_err(|e| format!("cannot decode: {e}"))?;
    let rgba8 = if matches!(image.color(), ColorType::Rgb32F | ColorType::Rgba32F) {
        encode_linear(image)
    } else {
        image.into_rgba8().into_raw()
    };
    Ok(Texture { path: path.to_path_buf(), width, height, rgba8 })
}

/// Linear floating-point RGBA to sRGB-encoded RGBA8 (alpha stays linear).
fn encode_linear(image: DynamicImage) -> Vec<u8> {
    let to_byte = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    image
        .into_rgba32f()
        .into_raw()
        .chunks_exact(4)
        .flat_map(|p| {
            [to_byte(linear_to_srgb(p[0])), to_byte(linear_to_srgb(p[1])), to_byte(linear_to_srgb(p[2])), to_byte(p[3])]
        })
        .collect()
}

/// The sRGB transfer function (IEC 61966-2-1); NaN maps to 0.
fn linear_to_srgb(x: f32) -> f32 {
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 }
}

/// The file of a `map_Kd` statement (everything after the keyword, as tobj gives it) and the
/// options before it, which relume ignores: `-s 2 2 1 -bm 0.5 wood.png` gives `wood.png` and
/// `-s 2 2 1 -bm 0.5`. Windows separators (`textures\wood.png`) become `/`.
pub(crate) fn parse_map_statement(statement: &str) -> (String, String) {
    // Each word with its byte offset in `statement`.
    let words: Vec<(usize, &str)> =
        statement.split_whitespace().map(|word| (word.as_ptr() as usize - statement.as_ptr() as usize, word)).collect();
    let mut i = 0;
    while i < words.len() {
        // (least, most) arguments of each option of the MTL specification.
        let (least, most) = match words[i].1 {
            "-blendu" | "-blendv" | "-cc" | "-clamp" | "-texres" | "-bm" | "-boost" | "-imfchan" | "-type" => (1, 1),
            "-mm" => (2, 2),
            "-o" | "-s" | "-t" => (1, 3),
            _ => break,
        };
        let mut taken = 0;
        while taken < most
            && i + 1 + taken < words.len()
            && (taken < least || words[i + 1 + taken].1.parse::<f32>().is_ok())
        {
            taken += 1;
        }
        i += 1 + taken;
    }
    let options: Vec<&str> = words[..i].iter().map(|&(_, word)| word).collect();
    // The file is the rest of the statement, inner spaces included.
    let file = words.get(i).map_or("", |&(start, _)| statement[start..].trim_end());
    let file = if std::path::MAIN_SEPARATOR == '/' { file.replace('\\', "/") } else { file.to_owned() };
    (file, options.join(" "))
}

#[cfg(test)]
mod tests {
    use super::super::test_util::TempDir;
    use super::*;

    #[test]
    fn map_statement_options_are_separated_from_the_file() {
        let cases = [
            ("wood.png", "wood.png", ""),
            ("  my wood.png ", "my wood.png", ""),
            ("-s 2 2 1 -bm 0.5 wood.png", "wood.png", "-s 2 2 1 -bm 0.5"),
            ("-o 0.5 wood.png", "wood.png", "-o 0.5"),
            ("-clamp on -mm 0 1 textures\\wood.png", "textures/wood.png", "-clamp on -mm 0 1"),
            ("-s 2", "", "-s 2"),
        ];
        for (statement, file, options) in cases {
            assert_eq!(parse_map_statement(statement), (file.to_owned(), options.to_owned()), "{statement}");
        }
    }

    #[test]
    fn srgb_encoding_matches_the_standard() {
        assert_eq!(linear_to_srgb(0.0), 0.0);
        assert!((linear_to_srgb(1.0) - 1.0).abs() < 1e-6);
        assert!((linear_to_srgb(0.2140) - 0.5).abs() < 1e-3);
        assert_eq!(linear_to_srgb(f32::NAN), 0.0);
    }

    #[test]
    fn grey_and_sixteen_bit_pngs_become_rgba8() {
        let dir = TempDir::new("texture-formats");
        let grey = dir.path().join("grey.png");
        image::GrayImage::from_raw(2, 1, vec![10, 200]).expect("buffer size").save(&grey).expect("write PNG");
        let texture = decode(&grey).expect("decodes");
        assert_eq!((texture.width, texture.height), (2, 1));
        assert_eq!(texture.rgba8, vec![10, 10, 10, 255, 200, 200, 200, 255]);

        let deep = dir.path().join("deep.png");
        image::ImageBuffer::<image::Rgb<u16>, _>::from_raw(1, 1, vec![0u16, 32896, 65535])
            .expect("buffer size")
            .save(&deep)
            .expect("write PNG");
        assert_eq!(decode(&deep).expect("decodes").rgba8, vec![0, 128, 255, 255]);

        let not_an_image = dir.write("notes.png", "hello");
        let message = decode(&not_an_image).expect_err("not an image");
        assert!(message.contains("not an image file"), "{message}");
    }

    #[test]
    fn oversized_textures_are_refused() {
        let dir = TempDir::new("texture-size");
        let wide = dir.path().join("wide.png");
        image::GrayImage::new(MAX_TEXTURE_SIDE + 1, 1).save(&wide).expect("write PNG");
        let message = decode(&wide).expect_err("too wide");
        assert!(message.contains("8193 x 1 texels"), "{message}");
        let mut textures = Textures::default();
        let message = textures.load(&wide).expect_err("too wide");
        assert!(message.contains("wide.png"), "{message}");
    }
}
