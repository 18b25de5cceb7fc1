//! Fast-marching inpainting after A. Telea, "An image inpainting technique based on the
//! fast marching method" (J. Graphics Tools, 2004), written from the paper's description.
//!
//! The hole is filled from its boundary inward, in order of increasing distance `T` to the
//! known region (the arrival time of a front moving at unit speed, found by the fast
//! marching method, which solves `|grad T| = 1`). When the front first reaches a pixel
//! `p`, its colour is set from the already-valued pixels `q` within radius `eps`:
//!
//! ```text
//! I(p) = sum_q w(p,q) [I(q) + grad I(q) . (p - q)] / sum_q w(p,q)
//! w    = dir * dst * lev
//! dir  = |(p - q) . N(p)| / |p - q|     (N = grad T / |grad T|: favour the front's normal)
//! dst  = 1 / |p - q|^2                  (favour near samples)
//! lev  = 1 / (1 + |T(p) - T(q)|)        (favour samples on the same level set)
//! ```
//!
//! The first-order term `grad I(q) . (p - q)` continues smooth gradients into the hole;
//! each result is clamped to the range of the samples it was made from, so the fill never
//! overshoots (and never creates a value no sample had in that channel).
//!
//! Only pixels marked [`Region::Known`] (and pixels already filled) are ever read, so
//! nothing from [`Region::Skip`] pixels (for example a foreground) can leak into the fill.
//! The order of processing is fixed (ties broken by pixel index): output is deterministic.

use crate::image::Image;
use crate::Real;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// The role of each pixel in an inpainting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Region {
    /// A trusted pixel: kept, and read by the fill.
    Known,
    /// A pixel to fill (the hole).
    Fill,
    /// A pixel neither read nor filled (kept as is; the front does not cross it).
    Skip,
}

/// Parameters of [`inpaint_telea`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TeleaOptions {
    /// Radius `eps` (pixels) of the neighbourhood each filled pixel is computed from.
    pub radius: f64,
    /// Fill only hole pixels within this distance of the known region (others stay as
    /// they were and are reported unfilled). `f64::INFINITY` fills the whole hole.
    pub max_distance: f64,
    /// Use the first-order (gradient) term of Telea's estimate.
    pub gradient_term: bool,
}

impl Default for TeleaOptions {
    fn default() -> Self {
        TeleaOptions {
            radius: 4.0,
            max_distance: f64::INFINITY,
            gradient_term: true,
        }
    }
}

/// The result of [`inpaint_telea`].
#[derive(Clone, Debug)]
pub struct Inpainted<T> {
    /// The image with its hole filled (other pixels unchanged).
    pub image: Image<T>,
    /// True where a [`Region::Fill`] pixel received a value.
    pub filled: Vec<bool>,
    /// Distance (fast-marching arrival time) to the known region; 0 on known pixels,
    /// infinite where the front did not arrive.
    pub distance: Vec<f32>,
}

const KNOWN: u8 = 0;
const BAND: u8 = 1;
const INSIDE: u8 = 2;
const SKIP: u8 = 3;

#[derive(Clone, Copy, PartialEq)]
struct Entry {
    t: f32,
    i: u32,
}
impl Eq for Entry {}
impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        // Min-heap on (t, i).
        o.t.total_cmp(&self.t).then(o.i.cmp(&self.i))
    }
}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// Fills the [`Region::Fill`] pixels of `image` (any channel count) by fast-marching
/// inpainting from the [`Region::Known`] ones. `region` has one entry per pixel. Fill
/// pixels the front cannot reach (cut off by `Skip` pixels, beyond `max_distance`, or no
/// known pixel at all) are left unchanged and reported unfilled.
///
/// # Panics
/// If `region.len()` differs from the pixel count (a programming error, not user input).
pub fn inpaint_telea<T: Real>(
    image: &Image<T>,
    region: &[Region],
    opts: &TeleaOptions,
) -> Inpainted<T> {
    let (w, h, ch) = (image.width, image.height, image.channels);
    assert_eq!(region.len(), w * h, "region mask size");
    let n = w * h;
    let mut val: Vec<f32> = image.data.iter().map(|v| v.f64() as f32).collect();
    let mut flag: Vec<u8> = region
        .iter()
        .map(|r| match r {
            Region::Known => KNOWN,
            Region::Fill => INSIDE,
            Region::Skip => SKIP,
        })
        .collect();
    let mut t = vec![f32::INFINITY; n];
    let mut heap = BinaryHeap::new();
    for i in 0..n {
        if flag[i] != KNOWN {
            continue;
        }
        t[i] = 0.0;
        let (x, y) = (i % w, i / w);
        let touches_hole = (x > 0 && flag[i - 1] == INSIDE)
            || (x + 1 < w && flag[i + 1] == INSIDE)
            || (y > 0 && flag[i - w] == INSIDE)
            || (y + 1 < h && flag[i + w] == INSIDE);
        if touches_hole {
            flag[i] = BAND;
            heap.push(Entry {
                t: 0.0,
                i: i as u32,
            });
        }
    }
    let radius = opts.radius.max(1.0);
    let r_int = radius.floor() as isize;
    let offsets: Vec<(isize, isize)> = (-r_int..=r_int)
        .flat_map(|dy| (-r_int..=r_int).map(move |dx| (dx, dy)))
        .filter(|&(dx, dy)| (dx != 0 || dy != 0) && ((dx * dx + dy * dy) as f64) <= radius * radius)
        .collect();
    let max_t = opts.max_distance as f32;
    let mut scratch = Scratch::new(ch);
    while let Some(Entry { t: te, i }) = heap.pop() {
        let i = i as usize;
        if flag[i] == KNOWN || te > t[i] {
            continue; // stale entry
        }
        if te > max_t {
            break;
        }
        flag[i] = KNOWN;
        let (x, y) = (i % w, i / w);
        let neighbours = [
            (x > 0).then(|| i - 1),
            (x + 1 < w).then(|| i + 1),
            (y > 0).then(|| i - w),
            (y + 1 < h).then(|| i + w),
        ];
        for k in neighbours.into_iter().flatten() {
            if flag[k] == KNOWN || flag[k] == SKIP {
                continue;
            }
            let tk = solve_eikonal(&flag, &t, w, h, k);
            let first = flag[k] == INSIDE;
            let improved = tk < t[k];
            if improved {
                t[k] = tk;
            }
            if !first && !improved {
                continue;
            }
            if first {
                // Still INSIDE while inpainted: its own stale value is never read.
                inpaint_pixel(
                    &mut val,
                    &flag,
                    &t,
                    w,
                    h,
                    ch,
                    k,
                    &offsets,
                    opts.gradient_term,
                    &mut scratch,
                );
                flag[k] = BAND;
            }
            heap.push(Entry {
                t: t[k],
                i: k as u32,
            });
        }
    }
    let mut out = image.clone();
    let mut filled = vec![false; n];
    for i in 0..n {
        if region[i] == Region::Fill && flag[i] != INSIDE && t[i] <= max_t {
            filled[i] = true;
            for c in 0..ch {
                out.data[i * ch + c] = T::c(val[i * ch + c] as f64);
            }
        } else if region[i] == Region::Fill {
            t[i] = f32::INFINITY;
        }
    }
    Inpainted {
        image: out,
        filled,
        distance: t,
    }
}

/// Telea's eikonal update: the smallest arrival time at `k` consistent with its settled
/// (KNOWN) 4-neighbours, over the four quadrants.
fn solve_eikonal(flag: &[u8], t: &[f32], w: usize, h: usize, k: usize) -> f32 {
    let (x, y) = (k % w, k / w);
    let known = |j: Option<usize>| j.filter(|&j| flag[j] == KNOWN).map(|j| t[j]);
    let xs = [(x > 0).then(|| k - 1), (x + 1 < w).then(|| k + 1)];
    let ys = [(y > 0).then(|| k - w), (y + 1 < h).then(|| k + w)];
    let mut best = f32::INFINITY;
    for &a in &xs {
        for &b in &ys {
            let s = match (known(a), known(b)) {
                (Some(t1), Some(t2)) => {
                    let d = t1 - t2;
                    if d.abs() >= 1.0 {
                        1.0 + t1.min(t2)
                    } else {
                        let r = (2.0 - d * d).sqrt();
                        (t1 + t2 + r) * 0.5
                    }
                }
                (Some(t1), None) => 1.0 + t1,
                (None, Some(t2)) => 1.0 + t2,
                (None, None) => f32::INFINITY,
            };
            best = best.min(s);
        }
    }
    best
}

struct Scratch {
    sum: Vec<f64>,
    lo: Vec<f32>,
    hi: Vec<f32>,
}

impl Scratch {
    fn new(ch: usize) -> Self {
        Scratch {
            sum: vec![0.0; ch],
            lo: vec![0.0; ch],
            hi: vec![0.0; ch],
        }
    }
}

/// One-sided or central difference of `f` along an axis, using only valued pixels.
#[inline(always)]
fn diff(has_m: bool, has_p: bool, m: f32, c: f32, p: f32) -> f32 {
    match (has_m, has_p) {
        (true, true) => 0.5 * (p - m),
        (false, true) => p - c,
        (true, false) => c - m,
        (false, false) => 0.0,
    }
}

#[allow(clippy::too_many_arguments)]
fn inpaint_pixel(
    val: &mut [f32],
    flag: &[u8],
    t: &[f32],
    w: usize,
    h: usize,
    ch: usize,
    p: usize,
    offsets: &[(isize, isize)],
    gradient_term: bool,
    s: &mut Scratch,
) {
    let valued = |j: usize| flag[j] == KNOWN || flag[j] == BAND;
    let (px, py) = ((p % w) as isize, (p / w) as isize);
    // Normal of the front at p: grad T over valued neighbours.
    let (gx, gy) = {
        let l = px > 0 && valued(p - 1);
        let r = (px as usize) + 1 < w && valued(p + 1);
        let u = py > 0 && valued(p - w);
        let d = (py as usize) + 1 < h && valued(p + w);
        let get = |ok: bool, j: usize| if ok { t[j] } else { 0.0 };
        let gx = diff(l, r, get(l, p.wrapping_sub(1)), t[p], get(r, p + 1));
        let gy = diff(u, d, get(u, p.wrapping_sub(w)), t[p], get(d, p + w));
        let n = (gx * gx + gy * gy).sqrt();
        if n > 1e-12 && n.is_finite() {
            (gx / n, gy / n)
        } else {
            (0.0, 0.0)
        }
    };
    s.sum.iter_mut().for_each(|v| *v = 0.0);
    s.lo.iter_mut().for_each(|v| *v = f32::INFINITY);
    s.hi.iter_mut().for_each(|v| *v = f32::NEG_INFINITY);
    let mut wsum = 0.0f64;
    for &(dx, dy) in offsets {
        let (qx, qy) = (px + dx, py + dy);
        if qx < 0 || qy < 0 || qx as usize >= w || qy as usize >= h {
            continue;
        }
        let q = qy as usize * w + qx as usize;
        if !valued(q) {
            continue;
        }
        // r = p - q
        let (rx, ry) = (-dx as f32, -dy as f32);
        let len2 = rx * rx + ry * ry;
        let len = len2.sqrt();
        let dir = if gx == 0.0 && gy == 0.0 {
            1.0
        } else {
            ((rx * gx + ry * gy).abs() / len).max(1e-6)
        };
        let dst = 1.0 / len2;
        let lev = 1.0 / (1.0 + (t[p] - t[q]).abs());
        let wt = (dir * dst * lev) as f64;
        // Neighbours of q that carry values, for grad I(q).
        let (ql, qr, qu, qd) = if gradient_term {
            (
                qx > 0 && valued(q - 1),
                (qx as usize) + 1 < w && valued(q + 1),
                qy > 0 && valued(q - w),
                (qy as usize) + 1 < h && valued(q + w),
            )
        } else {
            (false, false, false, false)
        };
        for c in 0..ch {
            let vq = val[q * ch + c];
            let mut est = vq;
            if gradient_term {
                let at = |ok: bool, j: usize| if ok { val[j * ch + c] } else { 0.0 };
                let gix = diff(ql, qr, at(ql, q.wrapping_sub(1)), vq, at(qr, q + 1));
                let giy = diff(qu, qd, at(qu, q.wrapping_sub(w)), vq, at(qd, q + w));
                est += gix * rx + giy * ry;
            }
            s.sum[c] += wt * est as f64;
            s.lo[c] = s.lo[c].min(vq);
            s.hi[c] = s.hi[c].max(vq);
        }
        wsum += wt;
    }
    if wsum > 0.0 {
        for c in 0..ch {
            val[p * ch + c] = ((s.sum[c] / wsum) as f32).clamp(s.lo[c], s.hi[c]);
        }
    }
}
