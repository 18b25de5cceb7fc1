//! RGBA textures for billboards: linear light, premultiplied by alpha, bilinear lookup.

use crate::{Error, Result};
use std::path::Path;

/// The display encoding used for every display-encoded value the tracer reads or writes
/// (texture colours, PNG outputs, the layer stack): the exact sRGB curve (IEC 61966-2-1),
/// as in camera photos, so the benchmark's inputs are what a user's photo would be.
/// Written once, in [`crate::model`] (the `physical` preset's transfer).
pub const DISPLAY_ENCODING: &str = "sRGB (IEC 61966-2-1)";

/// Display-encoded value to linear light (exact sRGB; negative input gives 0; values
/// above 1 continue the power segment).
#[inline]
pub fn decode_display(v: f64) -> f64 {
    crate::model::srgb_to_linear_with_derivative(v.max(0.0)).0
}

/// Linear light to a display-encoded value (exact sRGB, not clipped).
#[inline]
pub fn encode_display(v: f64) -> f64 {
    crate::model::linear_to_srgb(v.max(0.0))
}

/// A texture: `width x height` texels of premultiplied linear RGBA (`[r a, g a, b a, a]`).
/// Colour may exceed 1 (highlights brighter than white).
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
    /// Row-major premultiplied RGBA.
    pub data: Vec<[f32; 4]>,
}

impl Texture {
    /// A fully transparent texture.
    pub fn transparent(width: usize, height: usize) -> Self {
        Texture {
            width,
            height,
            data: vec![[0.0; 4]; width * height],
        }
    }

    /// A texture of one straight (not premultiplied) linear colour and alpha.
    pub fn solid(linear_rgb: [f64; 3], alpha: f64) -> Self {
        let a = alpha as f32;
        Texture {
            width: 1,
            height: 1,
            data: vec![[
                linear_rgb[0] as f32 * a,
                linear_rgb[1] as f32 * a,
                linear_rgb[2] as f32 * a,
                a,
            ]],
        }
    }

    /// Bilinear lookup at texture coordinates (`u`, `v`) in [0, 1] (texel centres at
    /// `(i + 0.5) / width`). Outside the texture everything is transparent; a 1x1 texture
    /// is constant inside [0, 1].
    #[inline]
    pub fn sample(&self, u: f64, v: f64) -> [f32; 4] {
        if !(0.0..=1.0).contains(&u) || !(0.0..=1.0).contains(&v) {
            return [0.0; 4];
        }
        if self.width == 1 && self.height == 1 {
            return self.data[0];
        }
        let x = u * self.width as f64 - 0.5;
        let y = v * self.height as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as isize, y0 as isize);
        let w = self.width as isize - 1;
        let h = self.height as isize - 1;
        // Clamp at the border: the edge texel extends to the edge of [0, 1].
        let cx = |x: isize| x.clamp(0, w) as usize;
        let cy = |y: isize| y.clamp(0, h) as usize;
        let (xa, xb, ya, yb) = (cx(x0), cx(x0 + 1), cy(y0), cy(y0 + 1));
        let t00 = self.data[ya * self.width + xa];
        let t10 = self.data[ya * self.width + xb];
        let t01 = self.data[yb * self.width + xa];
        let t11 = self.data[yb * self.width + xb];
        let mut out = [0.0f32; 4];
        for c in 0..4 {
            let top = t00[c] + (t10[c] - t00[c]) * fx;
            let bottom = t01[c] + (t11[c] - t01[c]) * fx;
            out[c] = top + (bottom - top) * fy;
        }
        out
    }

    /// The next coarser level of a mip pyramid: 2x2 box average (edge texels repeated for
    /// odd sizes). Averaging premultiplied RGBA is the correct filter for compositing.
    pub fn downsample(&self) -> Texture {
        let (w, h) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let mut acc = [0.0f32; 4];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let sx = (2 * x + dx).min(self.width - 1);
                    let sy = (2 * y + dy).min(self.height - 1);
                    let t = self.data[sy * self.width + sx];
                    for c in 0..4 {
                        acc[c] += 0.25 * t[c];
                    }
                }
                data.push(acc);
            }
        }
        Texture {
            width: w,
            height: h,
            data,
        }
    }

    /// The mip pyramid of this texture: level 0 is the texture itself, each next level half
    /// the size, down to 1x1.
    pub fn pyramid(self) -> Vec<Texture> {
        let mut levels = vec![self];
        while let Some(last) = levels.last() {
            if last.width == 1 && last.height == 1 {
                break;
            }
            let next = last.downsample();
            levels.push(next);
        }
        levels
    }

    /// Loads an image file as a texture. PNG/JPEG/TIFF are display-encoded (gamma 2.2) and
    /// decoded to linear light; EXR is taken as linear. The file's alpha channel is used if
    /// it has one (else opaque); `alpha_path`, if given, supplies the alpha instead (a grey
    /// image, or the alpha channel of an RGBA image, of the same size). `gain` scales the
    /// linear colour (use > 1 to make highlights brighter than white).
    pub fn from_files(path: &Path, alpha_path: Option<&Path>, gain: f64) -> Result<Self> {
        let img = crate::io::decode_as(path, "texture")?;
        let linear = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"));
        let (w, h) = (img.width() as usize, img.height() as usize);
        let has_alpha = img.color().has_alpha();
        let rgba = img.to_rgba32f().into_raw();
        let alpha: Option<Vec<f32>> = match alpha_path {
            Some(p) => {
                let m = crate::io::read_matte::<f32>(p)?;
                if m.width != w || m.height != h {
                    return Err(Error::file(
                        p,
                        format!(
                            "alpha matte is {}x{} but its texture {} is {w}x{h}",
                            m.width,
                            m.height,
                            path.display()
                        ),
                    ));
                }
                Some(m.data)
            }
            None => None,
        };
        let mut data = Vec::with_capacity(w * h);
        for (i, px) in rgba.chunks_exact(4).enumerate() {
            let a = match &alpha {
                Some(m) => m[i],
                None if has_alpha => px[3],
                None => 1.0,
            };
            if !px.iter().all(|v| v.is_finite()) || !(0.0..=1.0).contains(&a) {
                return Err(Error::file(
                    path,
                    "texture has non-finite or out-of-range values",
                ));
            }
            let lin = |v: f32| {
                let v = if linear {
                    v.max(0.0) as f64
                } else {
                    decode_display(v as f64)
                };
                (v * gain) as f32 * a
            };
            let texel = [lin(px[0]), lin(px[1]), lin(px[2]), a];
            if !texel.iter().all(|v| v.is_finite()) {
                return Err(Error::file(
                    path,
                    format!(
                        "texture gain {gain} makes colour values overflow (not finite in float32)"
                    ),
                ));
            }
            data.push(texel);
        }
        Ok(Texture {
            width: w,
            height: h,
            data,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_interpolates_between_texel_centres() {
        let t = Texture {
            width: 2,
            height: 1,
            data: vec![[0.0, 0.0, 0.0, 1.0], [1.0, 2.0, 3.0, 1.0]],
        };
        assert_eq!(t.sample(0.25, 0.5)[0], 0.0);
        assert_eq!(t.sample(0.75, 0.5)[2], 3.0);
        assert!((t.sample(0.5, 0.5)[1] - 1.0).abs() < 1e-6);
        assert_eq!(t.sample(1.01, 0.5), [0.0; 4]);
        assert!((encode_display(decode_display(0.3)) - 0.3).abs() < 1e-12);
    }
}
