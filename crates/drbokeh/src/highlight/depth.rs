//! The depth of a photo's clipped lights (docs/highlights.md, "Lights at depth edges").
//!
//! A depth map gives each pixel the depth of its most visible surface. Where a light shines
//! past or through the edge of a nearer object (between strands, through a fence's holes,
//! behind a thin rim), the pixels that mix the two carry the light's brightness but the
//! nearer object's depth. Decomposed and rendered, their light then spreads with the
//! nearer object's blur: a ball or ring of light around a source that the lens shows
//! sharp, or the reverse. A clipped region is one source, so it is given one depth: the
//! farthest its pixels show, when enough of them show it (a specular on a near object
//! whose anti-aliased rim touches a few background pixels stays on the near object).

use super::{clipped_regions, largest_channel};
use crate::image::Image;
use crate::Real;

/// A pixel is part of a light's region where its largest encoded channel is at least this
/// (the threshold of [`super::HighlightEstimate::DEFAULT`]).
pub const LIGHT_REGION_LEVEL: f64 = 0.9;
/// Disparities within this fraction of the map's range of a region's farthest value count
/// as that depth.
pub const SAME_DEPTH_FRACTION: f64 = 0.02;
/// A region moves to its farthest depth only if at least this share of its pixels lies
/// there already.
pub const MIN_FARTHEST_SHARE: f64 = 0.25;
/// Only regions of at most this many point areas ([`super::point_area_px`]) are lights; a
/// larger clipped area (a white wall, an overexposed sky) keeps its depth map.
pub const MAX_LIGHT_POINT_AREAS: f64 = 16.0;

/// The disparity map with each clipped light region of `rgb_encoded` (bright pixels,
/// largest channel `>= LIGHT_REGION_LEVEL`, 8-connected, with at least one clipped pixel,
/// at most [`MAX_LIGHT_POINT_AREAS`] point areas) moved to the farthest disparity among
/// its pixels, where at least [`MIN_FARTHEST_SHARE`] of them lie at that depth (within
/// [`SAME_DEPTH_FRACTION`] of the map's range); `None` where no pixel moves (or where
/// every pixel of each light already lies at its farthest depth, so a second pass over
/// its own output changes nothing). Shapes must agree (the caller checked them).
pub fn lights_at_farthest_depth<T: Real>(
    rgb_encoded: &Image<T>,
    disparity: &Image<T>,
) -> Option<Image<T>> {
    let (w, h) = (rgb_encoded.width, rgb_encoded.height);
    let value = largest_channel(rgb_encoded);
    let (lo, hi) = disparity
        .data
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), d| {
            (lo.min(d.f64()), hi.max(d.f64()))
        });
    let same = SAME_DEPTH_FRACTION * (hi - lo).max(0.0);
    let max_area = MAX_LIGHT_POINT_AREAS * super::point_area_px(w, h);
    let mut out: Option<Image<T>> = None;
    for region in clipped_regions(w, h, &value, LIGHT_REGION_LEVEL) {
        if region.len() as f64 > max_area {
            continue;
        }
        let farthest = region
            .iter()
            .map(|&i| disparity.data[i].f64())
            .fold(f64::MAX, f64::min);
        let at_farthest = region
            .iter()
            .filter(|&&i| disparity.data[i].f64() <= farthest + same)
            .count();
        if at_farthest == region.len()
            || (at_farthest as f64) < MIN_FARTHEST_SHARE * region.len() as f64
        {
            continue;
        }
        let moved = out.get_or_insert_with(|| disparity.clone());
        for &i in &region {
            if disparity.data[i].f64() > farthest + same {
                moved.data[i] = T::c(farthest);
            }
        }
    }
    out
}
