//! The refinement's runs and lanes against the scalar whole-window sums.

use super::*;
use crate::aperture::Aperture;
use crate::camera::Window;
use crate::stack::Layer;

/// Whether a source with alpha > 0 lies in the window's bounding square of receiver
/// `(x, y)`, block by block.
fn occupied_square<T: Real>(ctx: &RefineCtx<'_, T>, x: usize, y: usize) -> bool {
    let (stride, big_r) = (ctx.src.stride, ctx.tables.big_r);
    let mut occupied = false;
    for b in y / ROW_BLOCK..=(y + 2 * big_r) / ROW_BLOCK {
        let from = b * stride + x;
        for m in &ctx.block_max[from..from + 2 * big_r + 1] {
            occupied |= *m > f64::NEG_INFINITY;
        }
    }
    occupied
}

/// The scalar whole-window sums, tap by tap in the window's row-major order with the
/// model's own terms ([`model::masked_tap_weight`]): what [`refine_row`] must agree
/// with.
fn reference_row<T: Real>(
    ctx: &RefineCtx<'_, T>,
    row: &[LayerAtPixel<T>],
    y: usize,
) -> Vec<LayerAtPixel<T>> {
    let (src, tables, aperture) = (ctx.src, ctx.tables, ctx.aperture);
    let big_r = tables.big_r as isize;
    let stride = src.stride;
    let cutoff = T::c(FOCUS_WEIGHT_CUTOFF);
    let eps = T::c(model::WEIGHT_EPSILON);
    let below = T::c(REFINE_WEIGHT_BELOW);
    let mut out = Vec::with_capacity(row.len());
    for (x, s) in row.iter().enumerate() {
        if s.weight >= below || !occupied_square(ctx, x, y) {
            out.push(*s);
            continue;
        }
        let xi = src.index(x, y);
        let d_x = src.rel_disp[xi];
        let e_x = match src.focus_weight[xi] {
            e if e < cutoff => T::zero(),
            e => e,
        };
        let mut acc = model::Accumulator::<T>::default();
        let mut disc = model::DiscCoverage::<T>::default();
        let (r_c, _) =
            model::coverage_radius_px(src.radius[xi], ctx.coverage_radius, ctx.footprint);
        for dy in -big_r..=big_r {
            let Some(hw) = ctx.widths[(dy + big_r) as usize] else {
                continue;
            };
            let hw = hw as isize;
            for dx in -hw..=hw {
                let yi = (xi as isize + dy * stride as isize + dx) as usize;
                let a = src.alpha[yi];
                let (sc, _) = tables.scatter_at::<false>(src.step, aperture, (dx, dy), r_c);
                disc.add(sc, a);
                if a == T::zero() {
                    continue;
                }
                let (dist, gauge) = tables.geometry(dx, dy);
                let c = model::masked_tap_weight(
                    src.step,
                    aperture,
                    (dx, dy),
                    dist,
                    gauge,
                    (a, src.radius[yi], src.rel_disp[yi]),
                    (e_x, d_x),
                );
                acc.add(src.rgb(yi), c);
            }
        }
        let inv = T::one() / (acc.weight + eps);
        out.push(LayerAtPixel {
            weight: acc.weight,
            colour: acc.colour.map(|c| c * inv),
            coverage: match ctx.coverage {
                Coverage::PaperBox => s.coverage,
                Coverage::SoftDisc => disc.value(),
            },
        });
    }
    out
}

/// A 64x48 layer: a disc of alpha with a soft edge, holes of one to a few pixels and
/// a 20-pixel gap (longer than [`GAP`]) across it; disparities from 0.1 to 0.9 (focus
/// 0.5: a band of receivers in focus); the recorded weights all 0 but for a stripe.
fn scene<T: Real>() -> (Layer<T>, Vec<LayerAtPixel<T>>) {
    let (w, h) = (64, 48);
    let mut layer = Layer::<T>::constant(w, h, [0.3, 0.6, 0.9], 0.0, 0.5);
    let mut saved = vec![LayerAtPixel::<T>::default(); w * h];
    for y in 0..h {
        for x in 0..w {
            let r = ((x as f64 - 30.0).powi(2) + (y as f64 - 22.0).powi(2)).sqrt();
            let mut a = (0.5 - (r - 12.0) / 3.0).clamp(0.0, 1.0);
            if (x * 7 + y * 3) % 11 == 0 || (20..40).contains(&x) && y % 9 == 4 {
                a = 0.0;
            }
            *layer.alpha.at_mut(x, y, 0) = T::c(a);
            *layer.disparity.at_mut(x, y, 0) = T::c(0.1 + 0.8 * x as f64 / w as f64);
            for c in 0..3 {
                *layer.rgb_encoded.at_mut(x, y, c) = T::c(((x + 2 * y + c) % 5) as f64 / 4.0);
            }
            saved[y * w + x] = LayerAtPixel {
                weight: T::c(if y == 10 { 0.5 } else { 0.0 }),
                colour: [T::zero(); 3],
                coverage: T::c(0.25),
            };
        }
    }
    (layer, saved)
}

/// Runs both paths on [`scene`] under `settings`; returns the worst relative
/// difference of `W`, `B` and `o` (relative to at least `floor`), and how many
/// refined receivers were in focus.
fn compare<T: Real>(settings: &RenderSettings, floor: f64) -> (f64, usize) {
    let (layer, saved) = scene::<T>();
    let opts = settings.model();
    let prepared = model::prepare_layer(&layer, &settings.camera, &opts);
    let tables = WindowTables::<T>::new(settings);
    let src = Planes::padded(&prepared, tables.big_r, opts.step);
    let aperture = ApertureEval::<T>::new(&settings.aperture);
    let ctx = RefineCtx::new(&src, &tables, &aperture, settings);
    let w = prepared.width;
    let (mut worst, mut in_focus, mut refined) = (0.0f64, 0, 0);
    for (y, row) in saved.chunks(w).enumerate() {
        let fast = refine_row(&ctx, row, y);
        let slow = reference_row(&ctx, row, y);
        for x in 0..w {
            let (f, s) = (fast[x], slow[x]);
            if s != row[x] {
                refined += 1;
                if src.focus_weight[src.index(x, y)] >= T::c(FOCUS_WEIGHT_CUTOFF) {
                    in_focus += 1;
                }
            }
            let pairs = [
                (f.weight, s.weight),
                (f.colour[0], s.colour[0]),
                (f.colour[1], s.colour[1]),
                (f.colour[2], s.colour[2]),
                (f.coverage, s.coverage),
            ];
            for (a, b) in pairs {
                let (a, b) = (a.f64(), b.f64());
                let rel = (a - b).abs() / a.abs().max(b.abs()).max(floor);
                worst = worst.max(rel);
            }
        }
    }
    assert!(refined > 1000, "{refined} receivers refined");
    (worst, in_focus)
}

fn presets() -> Vec<RenderSettings> {
    let mut out = Vec::new();
    for base in [RenderSettings::paper(0.5), RenderSettings::physical(0.5)] {
        for aperture in [
            Aperture::Circle,
            Aperture::Polygon {
                blades: 6,
                rotation_deg: 10.0,
            },
        ] {
            let mut s = base.clone();
            s.camera.blur_k = 24.0;
            s.camera.window = Window::from_size(45).expect("odd");
            s.aperture = aperture;
            out.push(s);
        }
    }
    out
}

/// The runs and lanes give the scalar whole-window sums up to rounding: f64 (where
/// the fast forms' `exp` is the standard one) to 1e-12 relative; f32 to 1e-5
/// relative to at least 1e-20: sums below that are of terms near f32's subnormal
/// range (W ~ 1e-32 where only the far tail reaches, B = C / (W + 1e-8) ~ 1e-25),
/// whose rounding is absolute, and f32's `exp_fast` clamps its argument at 88, so
/// the sharp step keeps `S = 1 / (1 + e^88) = 6e-39` where the standard `exp`
/// gives less (at most 4000 taps of it: 3e-35 of W, 3e-27 of B). Both steps and
/// coverages, circle and polygon, receivers in focus among those refined.
#[test]
fn refine_runs_agree_with_the_scalar_sums() {
    for s in presets() {
        let (worst, in_focus) = compare::<f64>(&s, 1e-300);
        assert!(worst <= 1e-12, "f64 {:?}: {worst:e}", s.preset);
        assert!(in_focus > 50, "{in_focus} refined receivers in focus");
        let (worst, _) = compare::<f32>(&s, 1e-20);
        assert!(worst <= 1e-5, "f32 {:?}: {worst:e}", s.preset);
    }
}

/// Runs cover exactly the sources with alpha != 0, gaps of at most [`GAP`] inside.
#[test]
fn alpha_runs_cover_every_source_with_alpha() {
    let (layer, _) = scene::<f32>();
    let settings = RenderSettings::paper(0.5);
    let prepared = model::prepare_layer(&layer, &settings.camera, &settings.model());
    let src = Planes::padded(&prepared, 22, settings.model().step);
    let runs = AlphaRuns::new(&src);
    for r in 0..src.rows {
        let row = r * src.stride;
        for (from, last) in [(0, src.stride - 1), (5, 40), (17, 23), (30, 30)] {
            let mut covered = vec![false; src.stride];
            let mut at = from;
            loop {
                let (start, end) = runs.next_run(row, at, last);
                if start > last {
                    break;
                }
                assert!(start >= at && end > start && end <= last + 1);
                assert!(src.alpha[row + start] != 0.0);
                covered[start..end].fill(true);
                if end > last {
                    break;
                }
                assert!(src.alpha[row + end] == 0.0);
                at = end;
            }
            for c in from..=last {
                assert!(covered[c] || src.alpha[row + c] == 0.0, "row {r} col {c}");
            }
        }
    }
}
