//! Images: linear float RGB in memory, EXR and tonemapped sRGB PNG on disk (each written to
//! a temporary name and renamed, so a reader never sees half a file), and the image error
//! of docs/ALGORITHM.md section 3 that every comparison quotes.

use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// Linear RGB radiance, row by row from the top-left pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 3]>,
}

/// Rec. 709 luminance.
pub fn luminance(p: [f32; 3]) -> f64 {
    0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64
}

pub use crate::files::write_atomically;

/// `text` as EXR text, which holds Latin-1 only: every character outside printable ASCII
/// (and the backslash) becomes `\u{hex}` (`\\`), so that a scene path in any script, or an
/// adapter's name, can be written (the EXR writer panics on anything else) and read back
/// without loss (a newline too: newlines separate the `key=value` lines).
pub fn exr_text(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            ' '..='~' => out.push(c),
            _ => out.push_str(&format!("\\u{{{:x}}}", c as u32)),
        }
    }
    out
}

impl Image {
    pub fn new(width: u32, height: u32, pixels: Vec<[f32; 3]>) -> Self {
        assert_eq!(pixels.len(), width as usize * height as usize);
        Image { width, height, pixels }
    }

    pub fn at(&self, x: u32, y: u32) -> [f32; 3] {
        self.pixels[(y * self.width + x) as usize]
    }

    /// The EXR file (float32 R, G, B) as bytes; `attributes` become one text attribute,
    /// `firstshot`, of `key=value` lines (one attribute, because the EXR writer keeps
    /// attributes in a hash map whose order changes from run to run, and the same render
    /// must give the same bytes).
    pub fn exr_bytes(&self, attributes: &[(&str, String)]) -> Result<Vec<u8>> {
        use exr::prelude::*;
        let w = self.width as usize;
        let channels = SpecificChannels::rgb(|pos: Vec2<usize>| {
            let p = self.pixels[pos.y() * w + pos.x()];
            (p[0], p[1], p[2])
        });
        let mut image = exr::image::Image::from_channels((w, self.height as usize), channels);
        if !attributes.is_empty() {
            let text: String = attributes.iter().map(|(k, v)| exr_text(&format!("{k}={v}")) + "\n").collect();
            let text = Text::new_or_none(text.as_str()).ok_or_else(|| crate::Error::Image {
                path: PathBuf::from("<exr>"),
                message: "the attributes are not Latin-1 text".into(),
            })?;
            image.attributes.other.insert(Text::from("firstshot"), AttributeValue::Text(text));
        }
        let mut bytes = std::io::Cursor::new(Vec::new());
        image
            .write()
            .non_parallel()
            .to_buffered(&mut bytes)
            .map_err(|e| crate::Error::Image { path: PathBuf::from("<exr>"), message: e.to_string() })?;
        Ok(bytes.into_inner())
    }

    pub fn write_exr(&self, path: &Path, attributes: &[(&str, String)]) -> Result<()> {
        write_atomically(path, &self.exr_bytes(attributes)?)
    }

    /// Reads the first RGB(A) layer of an EXR file (a regular file: `files::read_input`).
    /// Every failure is an `Error::Input` naming the file.
    pub fn read_exr(path: &Path) -> Result<Image> {
        use exr::prelude::*;
        let bytes = crate::files::read_named_input(path)?;
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .rgba_channels(
                |resolution, _| self::Image {
                    width: resolution.width() as u32,
                    height: resolution.height() as u32,
                    pixels: vec![[0.0; 3]; resolution.width() * resolution.height()],
                },
                |img: &mut self::Image, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                    let w = img.width as usize;
                    img.pixels[pos.y() * w + pos.x()] = [r, g, b];
                },
            )
            .first_valid_layer()
            .all_attributes()
            .from_buffered(std::io::Cursor::new(bytes))
            // What was read is no EXR this reader takes: the input's fault (exit status 2).
            .map_err(|e| crate::Error::Input {
                path: path.to_path_buf(),
                message: format!("not a readable EXR image ({e})"),
            })?;
        Ok(image.layer_data.channel_data.pixels)
    }

    /// Exposure that maps the 97th percentile of luminance to 0.8, so that a few bright
    /// pixels (lights, highlights) clip instead of darkening the whole picture.
    pub fn auto_exposure(&self) -> f32 {
        let mut lum: Vec<f64> = self.pixels.iter().map(|&p| luminance(p)).filter(|l| l.is_finite()).collect();
        if lum.is_empty() {
            return 1.0;
        }
        let k = ((lum.len() - 1) as f64 * 0.97) as usize;
        let (_, p97, _) = lum.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
        if *p97 > 0.0 { (0.8 / *p97) as f32 } else { 1.0 }
    }

    /// The tonemapped image, 8-bit sRGB R, G, B per pixel, row by row: the image scaled by
    /// `exposure` and clipped. The PNG holds these bytes, and the viewer shows them.
    pub fn srgb8(&self, exposure: f32) -> Vec<u8> {
        fn srgb(v: f32) -> u8 {
            let v = if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 };
            let s = if v <= 0.003_130_8 { 12.92 * v } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
            (s * 255.0 + 0.5) as u8
        }
        self.pixels.iter().flat_map(|p| p.map(|c| srgb(c * exposure))).collect()
    }

    /// 8-bit sRGB PNG bytes of the image scaled by `exposure` and clipped (`srgb8`).
    pub fn png_bytes(&self, exposure: f32) -> Result<Vec<u8>> {
        let data = self.srgb8(exposure);
        let mut bytes = Vec::new();
        {
            let mut encoder = png::Encoder::new(&mut bytes, self.width, self.height);
            encoder.set_color(png::ColorType::Rgb);
            encoder.set_depth(png::BitDepth::Eight);
            // The fast deflate: the PNG is the preview beside the EXR, and every render writes
            // it (256 x 256 Sierpinski: 14 -> 4 ms for the EXR and PNG, the PNG 12 % larger).
            encoder.set_compression(png::Compression::Fast);
            let err =
                |e: png::EncodingError| crate::Error::Image { path: PathBuf::from("<png>"), message: e.to_string() };
            let mut writer = encoder.write_header().map_err(err)?;
            writer.write_image_data(&data).map_err(err)?;
        }
        Ok(bytes)
    }

    pub fn write_png(&self, path: &Path, exposure: f32) -> Result<()> {
        write_atomically(path, &self.png_bytes(exposure)?)
    }

    /// 2 x 2 box downsample (an odd last row or column is dropped).
    pub fn downsample2(&self) -> Image {
        let (w, h) = (self.width / 2, self.height / 2);
        let mut pixels = Vec::with_capacity((w * h) as usize);
        for y in 0..h {
            for x in 0..w {
                let mut s = [0.0f32; 3];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let p = self.at(2 * x + dx, 2 * y + dy);
                    for c in 0..3 {
                        s[c] += 0.25 * p[c];
                    }
                }
                pixels.push(s);
            }
        }
        Image { width: w, height: h, pixels }
    }

    /// Per-channel means.
    pub fn mean(&self) -> [f64; 3] {
        let mut m = [0.0f64; 3];
        for p in &self.pixels {
            for c in 0..3 {
                m[c] += p[c] as f64;
            }
        }
        m.map(|v| v / self.pixels.len().max(1) as f64)
    }
}

/// The image error of docs/ALGORITHM.md section 3 of `image` against `reference`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ImageError {
    /// sqrt(sum (a - b)^2 / sum b^2) over the counted pixels and channels.
    pub relative_rmse: f64,
    /// mean(a) / mean(b) per channel over the counted pixels.
    pub mean_ratio: [f64; 3],
    /// Pixels counted (after the 2 x 2 downsample).
    pub pixels: usize,
    /// Per-channel means over all pixels of each image (not downsampled, nothing left out).
    pub mean: [f64; 3],
    pub reference_mean: [f64; 3],
}

/// Compares after a 2 x 2 box downsample of both images, over the pixels whose reference
/// luminance is at most 10 times the reference's median (directly seen lights, exact
/// anyway, would swamp the figure). Where at least half the reference is black (a dark room
/// lit by a patch of sun), that median is 0 and would leave out every lit pixel: the median
/// of the pixels that are not black is taken instead.
pub fn image_error(image: &Image, reference: &Image) -> Result<ImageError> {
    if image.width != reference.width || image.height != reference.height {
        return Err(Error::Usage(format!(
            "the images differ in size: {}x{} against {}x{}",
            image.width, image.height, reference.width, reference.height
        )));
    }
    let a = image.downsample2();
    let b = reference.downsample2();
    let median_of = |mut values: Vec<f64>| {
        if values.is_empty() {
            return 0.0;
        }
        let k = values.len() / 2;
        *values.select_nth_unstable_by(k, |x, y| x.total_cmp(y)).1
    };
    let lum: Vec<f64> = b.pixels.iter().map(|&p| luminance(p)).collect();
    let mut median = median_of(lum.clone());
    if median <= 0.0 {
        median = median_of(lum.into_iter().filter(|&l| l > 0.0).collect());
    }
    let (mut err2, mut ref2, mut count) = (0.0f64, 0.0f64, 0usize);
    let (mut sum_a, mut sum_b) = ([0.0f64; 3], [0.0f64; 3]);
    for (pa, pb) in a.pixels.iter().zip(&b.pixels) {
        if luminance(*pb) > 10.0 * median {
            continue;
        }
        count += 1;
        for c in 0..3 {
            let (va, vb) = (pa[c] as f64, pb[c] as f64);
            err2 += (va - vb) * (va - vb);
            ref2 += vb * vb;
            sum_a[c] += va;
            sum_b[c] += vb;
        }
    }
    Ok(ImageError {
        relative_rmse: if ref2 > 0.0 { (err2 / ref2).sqrt() } else { f64::NAN },
        mean_ratio: [0, 1, 2].map(|c| sum_a[c] / sum_b[c]),
        pixels: count,
        mean: image.mean(),
        reference_mean: reference.mean(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reference that is black but for a lit band (0.5) and a directly seen light (100),
    /// each a whole number of 2 x 2 blocks.
    fn mostly_black() -> Image {
        let (width, height) = (16, 16);
        let pixels = (0..width * height)
            .map(|i| match (i % width, i / width) {
                (_, 0..4) => [0.5f32; 3],
                (0..2, 4..6) => [100.0; 3],
                _ => [0.0; 3],
            })
            .collect();
        Image::new(width, height, pixels)
    }

    #[test]
    fn a_mostly_black_reference_still_counts_its_lit_pixels() {
        let reference = mostly_black();
        // 10 % too bright everywhere: relative RMSE 0.1 and ratio 1.1 over the counted
        // pixels, whatever their number, as long as the light is left out and the lit band
        // is in (with the median of all pixels, 0, nothing lit was counted: 0 / 0).
        let brighter = Image::new(
            reference.width,
            reference.height,
            reference.pixels.iter().map(|p| p.map(|v| v * 1.1)).collect(),
        );
        let e = image_error(&brighter, &reference).unwrap();
        assert!((e.relative_rmse - 0.1).abs() < 1e-6, "{e:?}");
        assert!(e.mean_ratio.iter().all(|r| (r - 1.1).abs() < 1e-6), "{e:?}");
        // 8 x 8 blocks: the light's one block left out.
        assert_eq!(e.pixels, 63, "{e:?}");
    }

    #[test]
    fn a_reference_less_than_half_black_keeps_the_median_of_all_pixels() {
        // 64 blocks of 2 x 2: 30 black, 10 at 0.1, 20 at 0.2, 3 at 1.5 and a light at 100.
        // The median of all is 0.1, so the 1.5 blocks (over 10 times it) are left out with
        // the light; the median of the lit blocks alone (0.2) would have kept them.
        let block = |b: u32| match b {
            0..30 => 0.0f32,
            30..40 => 0.1,
            40..60 => 0.2,
            60..63 => 1.5,
            _ => 100.0,
        };
        let pixels = (0..256u32).map(|i| [block((i / 16 / 2) * 8 + (i % 16) / 2); 3]).collect();
        let reference = Image::new(16, 16, pixels);
        let e = image_error(&reference, &reference).unwrap();
        assert_eq!(e.pixels, 60, "{e:?}");
        assert_eq!(e.relative_rmse, 0.0, "{e:?}");
    }
}
