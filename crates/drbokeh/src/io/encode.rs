//! Row-fed encoders for rendered images: PNG (8/16-bit, RGB or grey) and EXR (linear float
//! RGB) written from the engine's float image one row (PNG) or one block (EXR) at a time,
//! converting values as they are written. No whole-image copy in the file's sample type
//! (or the PNG encoder's filtered copy) is made, so writing an image needs only its own
//! buffer plus a row (docs/limits.md).

use crate::image::Image;
use crate::{Error, Real, Result};
use std::io::{Seek, Write};
use std::path::Path;

/// An encoded value in [0, 1] as an 8-bit sample: `round(clamp(v, 0, 1) x 255)`.
pub(crate) fn quantize_u8(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// An encoded value in [0, 1] as a 16-bit sample: `round(clamp(v, 0, 1) x 65535)`.
pub(crate) fn quantize_u16(v: f64) -> u16 {
    (v.clamp(0.0, 1.0) * 65535.0).round() as u16
}

/// The zlib level of written PNGs (1 fastest .. 9 smallest).
const PNG_LEVEL: u8 = 3;

/// Bytes of compressed data per PNG `IDAT` chunk.
const PNG_CHUNK_BYTES: usize = 1 << 18;

/// Writes `image` (1 or 3 channels) as PNG to `out`, row by row: each value `v` becomes
/// `round(clamp(v, 0, 1) x 255)` (or x 65535 for 16 bits). Adaptive filters, zlib level
/// [`PNG_LEVEL`].
pub(crate) fn png_rows<T: Real, W: Write>(
    path: &Path,
    out: W,
    image: &Image<T>,
    sixteen: bool,
) -> Result<()> {
    let fail = |e: png::EncodingError| Error::file(path, format!("write failed: {e}"));
    let mut enc = png::Encoder::new(out, image.width as u32, image.height as u32);
    enc.set_color(match image.channels {
        1 => png::ColorType::Grayscale,
        3 => png::ColorType::Rgb,
        c => {
            return Err(Error::file(
                path,
                format!("cannot write {c} channels as PNG"),
            ))
        }
    });
    enc.set_depth(if sixteen {
        png::BitDepth::Sixteen
    } else {
        png::BitDepth::Eight
    });
    // zlib level 3 with adaptive filters: about 10% larger files than the `image` crate's
    // default (level 6), in a fraction of its time, which is serial after the render (level
    // 6 took about 0.17 s per megapixel of RGB on the issue 18 workloads).
    enc.set_deflate_compression(png::DeflateCompression::Level(PNG_LEVEL));
    enc.set_filter(png::Filter::Adaptive);
    let mut writer = enc.write_header().map_err(fail)?;
    let mut stream = writer
        .stream_writer_with_size(PNG_CHUNK_BYTES)
        .map_err(fail)?;
    let row_values = image.width * image.channels;
    let mut row = Vec::with_capacity(row_values * if sixteen { 2 } else { 1 });
    let io_fail = |e: std::io::Error| Error::file(path, format!("write failed: {e}"));
    for values in image.data.chunks_exact(row_values.max(1)) {
        row.clear();
        for &v in values {
            if sixteen {
                row.extend_from_slice(&quantize_u16(v.f64()).to_be_bytes());
            } else {
                row.push(quantize_u8(v.f64()));
            }
        }
        stream.write_all(&row).map_err(io_fail)?;
    }
    stream.finish().map_err(fail)?;
    writer.finish().map_err(fail)
}

/// Writes `image` (1 or 3 channels; grey goes to all three) as an RGB float EXR to `out`,
/// each value passed through `to_linear` as the encoder asks for it.
pub(crate) fn exr_rows<T: Real, W: Write + Seek>(
    path: &Path,
    out: W,
    image: &Image<T>,
    to_linear: impl Fn(f64) -> f64 + Sync,
) -> Result<()> {
    use exr::prelude::{Image as ExrImage, SpecificChannels, Vec2, WritableImage};
    let (w, h, ch) = (image.width, image.height, image.channels);
    if ch != 1 && ch != 3 {
        return Err(Error::file(
            path,
            format!("cannot write {ch} channels as EXR"),
        ));
    }
    let data = &image.data;
    let value = |i: usize| to_linear(data[i].f64()) as f32;
    let pixels = SpecificChannels::rgb(|p: Vec2<usize>| {
        let i = (p.y() * w + p.x()) * ch;
        if ch == 1 {
            let g = value(i);
            (g, g, g)
        } else {
            (value(i), value(i + 1), value(i + 2))
        }
    });
    let mut out = out;
    ExrImage::from_channels((w, h), pixels)
        .write()
        .to_buffered(&mut out)
        .map_err(|e| Error::file(path, format!("write failed: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 5x3 image whose values cover the clip range, both rounding directions and the ends.
    fn sample(channels: usize) -> Image<f32> {
        let data = (0..5 * 3 * channels)
            .map(|i| (i as f32 * 0.0731 - 0.1) * if i % 7 == 0 { 1.3 } else { 1.0 })
            .collect();
        Image::from_vec(5, 3, channels, data).unwrap()
    }

    #[test]
    fn png_rows_decode_to_the_rounded_clipped_values() {
        for channels in [1, 3] {
            for sixteen in [false, true] {
                let img = sample(channels);
                let mut bytes = Vec::new();
                png_rows(Path::new("t.png"), &mut bytes, &img, sixteen).unwrap();
                let decoded = image::load_from_memory(&bytes).unwrap();
                assert_eq!((decoded.width(), decoded.height()), (5, 3));
                let scale = if sixteen { 65535.0 } else { 255.0 };
                let want: Vec<u16> = img
                    .data
                    .iter()
                    .map(|&v| (v.clamp(0.0, 1.0) as f64 * scale).round() as u16)
                    .collect();
                let got: Vec<u16> = match (channels, sixteen) {
                    (1, false) => decoded.to_luma8().iter().map(|&v| v as u16).collect(),
                    (1, true) => decoded.to_luma16().into_raw(),
                    (_, false) => decoded.to_rgb8().iter().map(|&v| v as u16).collect(),
                    (_, true) => decoded.to_rgb16().into_raw(),
                };
                assert_eq!(got, want, "{channels} channel(s), 16 bits: {sixteen}");
            }
        }
    }

    #[test]
    fn exr_rows_hold_the_linearised_values() {
        for channels in [1, 3] {
            let img = sample(channels);
            let mut bytes = std::io::Cursor::new(Vec::new());
            exr_rows(Path::new("t.exr"), &mut bytes, &img, |v| 2.0 * v).unwrap();
            let decoded = image::load_from_memory(bytes.get_ref())
                .unwrap()
                .to_rgb32f();
            let got = decoded.into_raw();
            let want: Vec<f32> = img
                .data
                .iter()
                .flat_map(|&v| vec![2.0 * v; 4 - channels])
                .collect();
            assert_eq!(got, want, "{channels} channel(s)");
        }
    }
}
