//! From an image, a disparity map and a matte to a layer stack.
//!
//! With a matte this is the paper's two-layer recipe: the foreground layer is the image
//! with alpha = matte and its disparity extended outward beyond the matte; the background
//! layer is the image with the region under the (dilated) matte filled in, colour and
//! disparity, from the visible background around it. The fill here is a push-pull
//! (mean-pyramid) interpolation: smooth, fast, and it only ever reads known pixels.

mod fill;

pub use fill::push_pull_fill;

use crate::image::Image;
use crate::stack::{Layer, LayerStack};
use crate::{Error, Real, Result};

/// Matte values at or above this count as foreground when extending its disparity.
pub const FOREGROUND_THRESHOLD: f64 = 0.5;
/// Pixels within this distance of any matte value above zero are filled in the background.
pub const BACKGROUND_DILATION_PX: usize = 2;

/// Builds a two-layer stack (foreground, background) from an image, its disparity and an
/// alpha matte, all of the same size. An empty matte gives a single opaque layer.
pub fn two_layers_from_matte<T: Real>(
    rgb_encoded: &Image<T>,
    disparity: &Image<T>,
    matte: &Image<T>,
) -> Result<LayerStack<T>> {
    let (w, h) = (rgb_encoded.width, rgb_encoded.height);
    for (name, img) in [("disparity map", disparity), ("alpha matte", matte)] {
        if img.width != w || img.height != h {
            return Err(Error::input(
                name,
                format!("is {}x{}, but the image is {w}x{h}", img.width, img.height),
            ));
        }
    }
    let fg_known: Vec<bool> = matte
        .data
        .iter()
        .map(|a| a.f64() >= FOREGROUND_THRESHOLD)
        .collect();
    if !fg_known.iter().any(|k| *k) {
        return LayerStack::single(rgb_encoded.clone(), disparity.clone());
    }
    // Background is known where no matte value > 0 lies within the dilation radius.
    let any_matte: Vec<bool> = matte.data.iter().map(|a| a.f64() > 0.0).collect();
    let under = dilate(&any_matte, w, h, BACKGROUND_DILATION_PX);
    let bg_known: Vec<bool> = under.iter().map(|u| !u).collect();

    let fg_disp = push_pull_fill(disparity, &fg_known);
    let (bg_rgb, bg_disp) = if bg_known.iter().any(|k| *k) {
        (
            push_pull_fill(rgb_encoded, &bg_known),
            push_pull_fill(disparity, &bg_known),
        )
    } else {
        (rgb_encoded.clone(), disparity.clone())
    };
    let ones = Image::from_vec(w, h, 1, vec![T::one(); w * h])?;
    LayerStack::new(vec![
        Layer {
            rgb_encoded: rgb_encoded.clone(),
            alpha: matte.clone(),
            disparity: fg_disp,
        },
        Layer {
            rgb_encoded: bg_rgb,
            alpha: ones,
            disparity: bg_disp,
        },
    ])
}

/// Square dilation of a mask by `radius` pixels.
fn dilate(mask: &[bool], w: usize, h: usize, radius: usize) -> Vec<bool> {
    let r = radius as isize;
    let mut rows = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            rows[y * w + x] = (-r..=r).any(|d| {
                let xx = x as isize + d;
                xx >= 0 && (xx as usize) < w && mask[y * w + xx as usize]
            });
        }
    }
    let mut out = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            out[y * w + x] = (-r..=r).any(|d| {
                let yy = y as isize + d;
                yy >= 0 && (yy as usize) < h && rows[yy as usize * w + x]
            });
        }
    }
    out
}
