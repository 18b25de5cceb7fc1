//! Procedural billboard content, deterministic from a seed (no downloaded data).
//!
//! - [`ProceduralKind::Background`]: an opaque textured backdrop (gradient, value noise,
//!   panels with lit windows) with many small bright highlights (linear values drawn
//!   uniformly from a [`HighlightRange`], by default 2 to 10) that turn into bokeh balls.
//! - [`ProceduralKind::Foliage`]: leaves with soft edges, holes and thin stems, dew-drop
//!   highlights.
//! - [`ProceduralKind::Strands`]: hair- or grass-like fine strands with partial coverage.
//! - [`ProceduralKind::Fence`]: a mesh of bars with rounded holes and specular glints.
//! - [`ProceduralKind::Fluff`]: a blob with a furry, noise-modulated soft fringe, holes and
//!   specular spots.
//!
//! Shapes are laid out in texture-relative units, so the content is the same at any
//! resolution; thin features are anti-aliased by their area coverage.

use super::sampling::{hash_words, Rng};
use super::texture::Texture;
use serde::{Deserialize, Serialize};

/// The kinds of procedural content.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProceduralKind {
    /// Opaque textured background with small bright highlights.
    Background,
    /// Leaves and stems with soft edges and holes.
    Foliage,
    /// Fine hair/grass strands.
    Strands,
    /// A fence/mesh with holes.
    Fence,
    /// A furry blob with a soft fringe and holes.
    Fluff,
}

impl ProceduralKind {
    /// The foreground kinds (everything but the background).
    pub const FOREGROUNDS: [ProceduralKind; 4] = [
        ProceduralKind::Foliage,
        ProceduralKind::Strands,
        ProceduralKind::Fence,
        ProceduralKind::Fluff,
    ];
}

/// Smooth value noise in [0, 1] on a lattice of unit spacing.
fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let (xi, yi) = (x.floor(), y.floor());
    let (fx, fy) = (x - xi, y - yi);
    let (xi, yi) = (xi as i64 as u64, yi as i64 as u64);
    let h = |a: u64, b: u64| (hash_words(&[seed, a, b]) >> 11) as f64 / (1u64 << 53) as f64;
    let s = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (s(fx), s(fy));
    let top = h(xi, yi) + (h(xi.wrapping_add(1), yi) - h(xi, yi)) * sx;
    let bot = h(xi, yi.wrapping_add(1))
        + (h(xi.wrapping_add(1), yi.wrapping_add(1)) - h(xi, yi.wrapping_add(1))) * sx;
    top + (bot - top) * sy
}

/// Four octaves of value noise, in [0, 1].
fn fbm(x: f64, y: f64, seed: u64) -> f64 {
    let (mut sum, mut amp, mut freq, mut norm) = (0.0, 0.5, 1.0, 0.0);
    for o in 0..4 {
        sum += amp * value_noise(x * freq, y * freq, seed.wrapping_add(o));
        norm += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / norm
}

/// Coverage of a shape from its signed distance in texels (negative inside) with an edge
/// of `soft` texels.
fn coverage(signed_distance: f64, soft: f64) -> f64 {
    (0.5 - signed_distance / soft.max(1e-6)).clamp(0.0, 1.0)
}

/// Distance from p to the segment a-b.
fn segment_distance(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (vx, vy) = (b.0 - a.0, b.1 - a.1);
    let len2 = vx * vx + vy * vy;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * vx + (p.1 - a.1) * vy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((p.0 - a.0 - t * vx).powi(2) + (p.1 - a.1 - t * vy).powi(2)).sqrt()
}

/// The range of linear intensities (gains on a near-white tint) of the small bright
/// highlights painted on every kind of content; drawn uniformly in `[lo, hi]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HighlightRange {
    /// Smallest gain.
    pub lo: f64,
    /// Largest gain.
    pub hi: f64,
}

impl Default for HighlightRange {
    /// 2 to 10: the benchmark's standard range.
    fn default() -> Self {
        HighlightRange { lo: 2.0, hi: 10.0 }
    }
}

impl HighlightRange {
    /// Checks `0 < lo <= hi <= 10000` (finite); the message names `highlight_range`.
    pub fn validate(&self) -> crate::Result<()> {
        let HighlightRange { lo, hi } = *self;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi && hi <= 10_000.0) {
            return Err(crate::Error::param(
                "highlight_range",
                format!("expected 0 < LO <= HI <= 10000, got {lo}:{hi}"),
            ));
        }
        Ok(())
    }

    /// Parses `LO:HI` (e.g. `2:10`, `5:50`).
    pub fn parse(s: &str) -> crate::Result<Self> {
        let bad = || {
            crate::Error::param(
                "highlight_range",
                format!("expected LO:HI with 0 < LO <= HI (e.g. 2:10), got '{s}'"),
            )
        };
        let (lo, hi) = s.split_once(':').ok_or_else(bad)?;
        let r = HighlightRange {
            lo: lo.trim().parse().map_err(|_| bad())?,
            hi: hi.trim().parse().map_err(|_| bad())?,
        };
        r.validate()?;
        Ok(r)
    }
}

/// Checks a background detail strength ([`generate_with`]): finite, in [0, 1]; the message
/// names `background_detail`.
pub fn validate_background_detail(detail: f64) -> crate::Result<()> {
    if !(detail.is_finite() && (0.0..=1.0).contains(&detail)) {
        return Err(crate::Error::param(
            "background_detail",
            format!("expected a strength in [0, 1], got {detail}"),
        ));
    }
    Ok(())
}

/// A texture being painted, in texel coordinates.
struct Canvas {
    tex: Texture,
    highlights: HighlightRange,
}

impl Canvas {
    fn new(w: usize, h: usize, highlights: HighlightRange) -> Self {
        Canvas {
            tex: Texture::transparent(w, h),
            highlights,
        }
    }

    fn scale(&self) -> f64 {
        self.tex.width.min(self.tex.height) as f64
    }

    /// Composites a shape "over" the canvas inside the box [x0, x1) x [y0, y1) (texels);
    /// `shade` returns (linear colour, coverage) at a texel centre.
    fn paint(
        &mut self,
        bbox: (f64, f64, f64, f64),
        mut shade: impl FnMut(f64, f64) -> Option<([f64; 3], f64)>,
    ) {
        let (w, h) = (self.tex.width as f64, self.tex.height as f64);
        let x0 = bbox.0.floor().clamp(0.0, w) as usize;
        let x1 = bbox.1.ceil().clamp(0.0, w) as usize;
        let y0 = bbox.2.floor().clamp(0.0, h) as usize;
        let y1 = bbox.3.ceil().clamp(0.0, h) as usize;
        for y in y0..y1 {
            for x in x0..x1 {
                if let Some((c, a)) = shade(x as f64 + 0.5, y as f64 + 0.5) {
                    if a <= 0.0 {
                        continue;
                    }
                    let a = a.min(1.0);
                    let t = &mut self.tex.data[y * self.tex.width + x];
                    let keep = (1.0 - a) as f32;
                    for ch in 0..3 {
                        t[ch] = (c[ch] * a) as f32 + t[ch] * keep;
                    }
                    t[3] = a as f32 + t[3] * keep;
                }
            }
        }
    }

    /// Paints small bright discs (highlights) of linear intensity above 1.
    fn highlights(&mut self, rng: &mut Rng, count: usize, mask_alpha: bool, warm: bool) {
        let s = self.scale();
        let (w, h) = (self.tex.width as f64, self.tex.height as f64);
        for _ in 0..count {
            let (cx, cy) = (rng.range(0.0, w), rng.range(0.0, h));
            if mask_alpha {
                let t = self.tex.data[(cy as usize).min(self.tex.height - 1) * self.tex.width
                    + (cx as usize).min(self.tex.width - 1)];
                if t[3] < 0.9 {
                    continue;
                }
            }
            let r = (s * rng.range(0.002, 0.007)).max(0.7);
            let gain = rng.range(self.highlights.lo, self.highlights.hi);
            let tint = if warm && rng.uniform() < 0.6 {
                [1.0, 0.75, 0.45]
            } else if rng.uniform() < 0.3 {
                [0.6, 0.8, 1.0]
            } else {
                [1.0, 1.0, 0.95]
            };
            let col = [tint[0] * gain, tint[1] * gain, tint[2] * gain];
            self.paint(
                (cx - r - 1.0, cx + r + 1.0, cy - r - 1.0, cy + r + 1.0),
                |x, y| {
                    let d = ((x - cx).powi(2) + (y - cy).powi(2)).sqrt() - r;
                    Some((col, coverage(d, 1.0)))
                },
            );
        }
    }
}

fn random_colour(rng: &mut Rng, lo: f64, hi: f64) -> [f64; 3] {
    [rng.range(lo, hi), rng.range(lo, hi), rng.range(lo, hi)]
}

/// Generates `kind` at `width x height` texels from `seed`, highlights in the default
/// range.
pub fn generate(kind: ProceduralKind, seed: u64, width: usize, height: usize) -> Texture {
    generate_with_highlights(kind, seed, width, height, HighlightRange::default())
}

/// Generates `kind` at `width x height` texels from `seed`, with highlight gains drawn
/// from `highlights` (the same layout and random draws whatever the range).
pub fn generate_with_highlights(
    kind: ProceduralKind,
    seed: u64,
    width: usize,
    height: usize,
    highlights: HighlightRange,
) -> Texture {
    generate_with(kind, seed, width, height, highlights, 0.0)
}

/// [`generate_with_highlights`] with fine detail of strength `background_detail` (in
/// [0, 1], 0 none) on the background's surfaces: its sky gradient and panels are
/// multiplied by `1 + detail (2 n - 1)`, `n` in [0, 1] four octaves of value noise whose
/// coarsest period is 1/56 of the texture's shorter side (on the benchmark's background,
/// about 3.7 px, then 1.8, 0.9 and 0.5 px). The layout and the random draws are those of
/// the scene without detail.
pub fn generate_with(
    kind: ProceduralKind,
    seed: u64,
    width: usize,
    height: usize,
    highlights: HighlightRange,
    background_detail: f64,
) -> Texture {
    let mut rng = Rng::from_words(&[seed, kind as u64, 0x7E47]);
    let mut canvas = Canvas::new(width.max(1), height.max(1), highlights);
    match kind {
        ProceduralKind::Background => background(&mut canvas, &mut rng, seed, background_detail),
        ProceduralKind::Foliage => foliage(&mut canvas, &mut rng, seed),
        ProceduralKind::Strands => strands(&mut canvas, &mut rng),
        ProceduralKind::Fence => fence(&mut canvas, &mut rng),
        ProceduralKind::Fluff => fluff(&mut canvas, &mut rng, seed),
    }
    canvas.tex
}

fn background(c: &mut Canvas, rng: &mut Rng, seed: u64, detail: f64) {
    let s = c.scale();
    let (w, h) = (c.tex.width as f64, c.tex.height as f64);
    let top = random_colour(rng, 0.05, 0.5);
    let bottom = random_colour(rng, 0.02, 0.3);
    let freq = rng.range(4.0, 10.0) / s;
    let nseed = seed ^ 0xB6;
    // Fine detail (no random draws: the layout stays that of the scene without it).
    let fine = 56.0 / s;
    let dseed = seed ^ 0xD7;
    let texture = |x: f64, y: f64| 1.0 + detail * (2.0 * fbm(x * fine, y * fine, dseed) - 1.0);
    c.paint((0.0, w, 0.0, h), |x, y| {
        let t = y / h;
        let n = (0.6 + 0.8 * fbm(x * freq, y * freq, nseed)) * texture(x, y);
        let col = [0, 1, 2].map(|i| (top[i] * (1.0 - t) + bottom[i] * t) * n);
        Some((col, 1.0))
    });
    // Panels (buildings, shelves) with lit windows.
    for _ in 0..rng.below(10) + 6 {
        let (pw, ph) = (s * rng.range(0.08, 0.3), s * rng.range(0.1, 0.5));
        let (px, py) = (rng.range(-0.1 * w, w), rng.range(0.2 * h, h));
        let col = random_colour(rng, 0.02, 0.35);
        let stripe = rng.range(0.01, 0.04) * s;
        c.paint((px, px + pw, py, py + ph), |x, y| {
            let d = (px - x).max(x - px - pw).max(py - y).max(y - py - ph);
            let k = if ((x - px) / stripe).floor() as i64 % 3 == 0 {
                0.7
            } else {
                1.0
            };
            let k = k * texture(x, y);
            Some((col.map(|v| v * k), coverage(d, 1.0)))
        });
        let win = rng.range(0.008, 0.02) * s;
        let lit = rng.uniform() * 0.5;
        let mut y = py + win;
        while y + win < py + ph {
            let mut x = px + win;
            while x + win < px + pw {
                if rng.uniform() < lit {
                    let g = rng.range(0.8, 4.0);
                    let (wx, wy) = (x, y);
                    c.paint((wx, wx + win, wy, wy + win), |xx, yy| {
                        let d = (wx - xx).max(xx - wx - win).max(wy - yy).max(yy - wy - win);
                        Some(([g, 0.8 * g, 0.5 * g], coverage(d, 1.0)))
                    });
                }
                x += 2.0 * win;
            }
            y += 2.0 * win;
        }
    }
    let n = rng.below(60) + 40;
    c.highlights(rng, n, false, true);
}

fn foliage(c: &mut Canvas, rng: &mut Rng, seed: u64) {
    let s = c.scale();
    let (w, h) = (c.tex.width as f64, c.tex.height as f64);
    let root = (rng.range(0.0, w), h);
    let hue = random_colour(rng, 0.02, 0.12);
    let leaves = rng.below(12) + 8;
    for i in 0..leaves {
        let (cx, cy) = (rng.range(0.15 * w, 0.85 * w), rng.range(0.1 * h, 0.8 * h));
        // Stem to the root: thin, sometimes sub-texel.
        let stem_w = rng.range(0.3, 2.0);
        let stem_col = [0.05, 0.04, 0.02];
        let (ax, ay) = root;
        c.paint(
            (
                cx.min(ax) - 3.0,
                cx.max(ax) + 3.0,
                cy.min(ay) - 3.0,
                cy.max(ay) + 3.0,
            ),
            |x, y| {
                let d = segment_distance((x, y), (cx, cy), (ax, ay));
                let a = if stem_w < 1.0 {
                    stem_w * coverage(d - 0.5, 1.0)
                } else {
                    coverage(d - 0.5 * stem_w, 1.0)
                };
                Some((stem_col, a))
            },
        );
        let (a_ax, b_ax) = (s * rng.range(0.05, 0.14), s * rng.range(0.02, 0.05));
        let ang = rng.range(0.0, std::f64::consts::PI);
        let (ca, sa) = (ang.cos(), ang.sin());
        let soft = rng.range(1.0, 3.5);
        let col = [
            hue[0] + rng.range(0.0, 0.1),
            hue[1] + rng.range(0.1, 0.35),
            hue[2] + rng.range(0.0, 0.05),
        ];
        let hole = if rng.uniform() < 0.4 {
            Some((
                rng.range(-0.4, 0.4) * a_ax,
                0.0,
                rng.range(0.15, 0.35) * b_ax,
            ))
        } else {
            None
        };
        let vseed = seed ^ (i as u64 * 7919);
        c.paint(
            (
                cx - a_ax - 4.0,
                cx + a_ax + 4.0,
                cy - a_ax - 4.0,
                cy + a_ax + 4.0,
            ),
            |x, y| {
                let (dx, dy) = (x - cx, y - cy);
                let (u, v) = (dx * ca + dy * sa, -dx * sa + dy * ca);
                let q = ((u / a_ax).powi(2) + (v / b_ax).powi(2)).sqrt();
                let d = (q - 1.0) * b_ax;
                let mut a = coverage(d, soft);
                if let Some((hx, hy, hr)) = hole {
                    let dh = ((u - hx).powi(2) + (v - hy).powi(2)).sqrt() - hr;
                    a *= 1.0 - coverage(dh, 1.5);
                }
                let vein = if v.abs() < 0.8 { 1.4 } else { 1.0 };
                let n = 0.7 + 0.6 * fbm(u * 0.05, v * 0.05, vseed);
                Some((col.map(|k| k * n * vein), a))
            },
        );
    }
    let n = rng.below(8) + 3;
    c.highlights(rng, n, true, false);
}

fn strands(c: &mut Canvas, rng: &mut Rng) {
    let s = c.scale();
    let (w, h) = (c.tex.width as f64, c.tex.height as f64);
    let base_col = random_colour(rng, 0.03, 0.5);
    let count = rng.below(150) + 120;
    let mut cov = vec![0.0f64; c.tex.width * c.tex.height];
    let mut touched: Vec<usize> = Vec::new();
    let from_bottom = rng.uniform() < 0.6;
    for _ in 0..count {
        // A quadratic Bezier from a root to a tip.
        let p0 = if from_bottom {
            (rng.range(0.1 * w, 0.9 * w), h)
        } else {
            (0.0, rng.range(0.1 * h, 0.9 * h))
        };
        let len = s * rng.range(0.3, 0.8);
        let ang: f64 = if from_bottom {
            -std::f64::consts::FRAC_PI_2 + rng.range(-0.5, 0.5)
        } else {
            rng.range(-0.5, 0.5)
        };
        let p2 = (p0.0 + len * ang.cos(), p0.1 + len * ang.sin());
        let bend = rng.range(-0.3, 0.3) * len;
        let p1 = (
            0.5 * (p0.0 + p2.0) - bend * ang.sin(),
            0.5 * (p0.1 + p2.1) + bend * ang.cos(),
        );
        let width = rng.range(0.3, 1.8);
        let opacity = rng.range(0.5, 0.95);
        let col = base_col.map(|k| k * rng.range(0.6, 1.6));
        let pts: Vec<(f64, f64)> = (0..=10)
            .map(|k| {
                let t = k as f64 / 10.0;
                let m = 1.0 - t;
                (
                    m * m * p0.0 + 2.0 * m * t * p1.0 + t * t * p2.0,
                    m * m * p0.1 + 2.0 * m * t * p1.1 + t * t * p2.1,
                )
            })
            .collect();
        for seg in pts.windows(2) {
            let (a, b) = (seg[0], seg[1]);
            let x0 = (a.0.min(b.0) - 3.0).floor().max(0.0) as usize;
            let x1 = ((a.0.max(b.0) + 3.0).ceil().max(0.0) as usize).min(c.tex.width);
            let y0 = (a.1.min(b.1) - 3.0).floor().max(0.0) as usize;
            let y1 = ((a.1.max(b.1) + 3.0).ceil().max(0.0) as usize).min(c.tex.height);
            for y in y0..y1 {
                for x in x0..x1 {
                    let d = segment_distance((x as f64 + 0.5, y as f64 + 0.5), a, b);
                    let k = if width < 1.0 {
                        width * coverage(d - 0.5, 1.0)
                    } else {
                        coverage(d - 0.5 * width, 1.0)
                    } * opacity;
                    let i = y * c.tex.width + x;
                    if k > cov[i] {
                        if cov[i] == 0.0 {
                            touched.push(i);
                        }
                        cov[i] = k;
                    }
                }
            }
        }
        for &i in &touched {
            let a = cov[i];
            let t = &mut c.tex.data[i];
            let keep = (1.0 - a) as f32;
            for ch in 0..3 {
                t[ch] = (col[ch] * a) as f32 + t[ch] * keep;
            }
            t[3] = a as f32 + t[3] * keep;
            cov[i] = 0.0;
        }
        touched.clear();
    }
}

fn fence(c: &mut Canvas, rng: &mut Rng) {
    let s = c.scale();
    let (w, h) = (c.tex.width as f64, c.tex.height as f64);
    let cell = s * rng.range(0.05, 0.12);
    let bar = cell * rng.range(0.12, 0.35);
    let corner = rng.range(0.0, 0.5) * (cell - bar);
    let col = random_colour(rng, 0.05, 0.5);
    let (ox, oy) = (rng.range(0.0, cell), rng.range(0.0, cell));
    // Overall outline: a rounded rectangle inset from the texture edge.
    let (mx, my) = (rng.range(0.0, 0.15) * w, rng.range(0.0, 0.15) * h);
    let outline_r = s * 0.05;
    c.paint((0.0, w, 0.0, h), |x, y| {
        // Hole: a rounded square inside each cell.
        let (fx, fy) = ((x - ox).rem_euclid(cell), (y - oy).rem_euclid(cell));
        let half = 0.5 * (cell - bar);
        let (qx, qy) = (
            (fx - 0.5 * cell).abs() - (half - corner),
            (fy - 0.5 * cell).abs() - (half - corner),
        );
        let hole_d =
            (qx.max(0.0).powi(2) + qy.max(0.0).powi(2)).sqrt() + qx.max(qy).min(0.0) - corner;
        let a_mesh = 1.0 - coverage(hole_d, 1.2);
        let (ex, ey) = (
            (x - 0.5 * w).abs() - (0.5 * w - mx - outline_r),
            (y - 0.5 * h).abs() - (0.5 * h - my - outline_r),
        );
        let out_d =
            (ex.max(0.0).powi(2) + ey.max(0.0).powi(2)).sqrt() + ex.max(ey).min(0.0) - outline_r;
        let a = a_mesh * coverage(out_d, 2.0);
        let shade = 0.6 + 0.4 * ((fx / cell) * std::f64::consts::PI).sin();
        Some((col.map(|k| k * shade), a))
    });
    let n = rng.below(20) + 10;
    c.highlights(rng, n, true, false);
}

fn fluff(c: &mut Canvas, rng: &mut Rng, seed: u64) {
    let s = c.scale();
    let (w, h) = (c.tex.width as f64, c.tex.height as f64);
    let (cx, cy) = (0.5 * w, 0.5 * h);
    let radius = 0.35 * s;
    let fringe = s * rng.range(0.01, 0.04);
    let col = random_colour(rng, 0.1, 0.7);
    let holes: Vec<(f64, f64, f64)> = (0..rng.below(4) + 1)
        .map(|_| {
            let a = rng.range(0.0, std::f64::consts::TAU);
            let r = rng.range(0.0, 0.6) * radius;
            (
                cx + r * a.cos(),
                cy + r * a.sin(),
                rng.range(0.04, 0.12) * s,
            )
        })
        .collect();
    let nseed = seed ^ 0xF1;
    c.paint((0.0, w, 0.0, h), |x, y| {
        let (dx, dy) = (x - cx, y - cy);
        let r = (dx * dx + dy * dy).sqrt();
        let theta = dy.atan2(dx);
        // Outline wobble plus fine angular "hairs" in the fringe.
        let wobble =
            1.0 + 0.15 * (fbm(theta.cos() * 2.0 + 5.0, theta.sin() * 2.0 + 5.0, nseed) - 0.5);
        let hair = fbm(theta * 40.0, r * 0.02, nseed ^ 3);
        let d = r - radius * wobble - fringe * (hair - 0.5) * 2.0;
        let mut a = coverage(d, fringe);
        for &(hx, hy, hr) in &holes {
            let dh = ((x - hx).powi(2) + (y - hy).powi(2)).sqrt() - hr;
            a *= 1.0 - coverage(dh, 2.0);
        }
        let shade = 0.5 + 0.7 * fbm(x * 8.0 / s, y * 8.0 / s, nseed ^ 9);
        Some((col.map(|k| k * shade), a))
    });
    let n = rng.below(10) + 4;
    c.highlights(rng, n, true, false);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn content_is_deterministic_and_has_required_features() {
        let bg = generate(ProceduralKind::Background, 3, 160, 160);
        assert_eq!(bg, generate(ProceduralKind::Background, 3, 160, 160));
        assert_ne!(bg, generate(ProceduralKind::Background, 4, 160, 160));
        assert!(
            bg.data.iter().all(|t| (t[3] - 1.0).abs() < 1e-5),
            "background must be opaque"
        );
        assert!(
            bg.data.iter().any(|t| t[0] > 1.0),
            "background needs highlights above 1"
        );
        for kind in ProceduralKind::FOREGROUNDS {
            let t = generate(kind, 11, 200, 200);
            let soft = t.data.iter().filter(|t| t[3] > 0.02 && t[3] < 0.98).count();
            let empty = t.data.iter().filter(|t| t[3] < 0.02).count();
            assert!(
                soft > 100,
                "{kind:?} needs soft alpha, has {soft} partial texels"
            );
            assert!(empty > 1000, "{kind:?} needs transparent regions");
            assert!(t
                .data
                .iter()
                .all(|t| (0.0..=1.0).contains(&t[3]) && t[0] >= 0.0));
        }
    }
}
