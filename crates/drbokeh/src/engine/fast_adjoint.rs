//! The adjoint on the fast engine's schedule (`render_with_tape_on(.., Engine::Fast, ..)`):
//! forward with tape and backward, visiting only the source-receiver pairs that can matter.
//! Same chain rule and model functions as the exact adjoint (`engine/adjoint.rs`), same
//! gather formulation: every output element is computed by one task in a fixed order, so
//! results are identical bytes for any thread count (no atomics).
//!
//! **Forward with tape.** The fast engine's render (`fast::render_recording`), bit for bit
//! the output of `render(.., Engine::Fast, ..)`, which also records per layer and pixel
//! the sums `W`, `B = C / (W + 1e-8)` and `o`. The recorded `W` and `C` also hold the ring
//! of taps out to the backward's longer reach (below), summed apart from the rendered ones.
//!
//! **Reach.** A tap `y -> x` matters only when `dist < r + tail`, with `r` the radius of
//! the soft step it evaluates: `r(y)` for the scatter term, the receiver's `r_c(x)` for the
//! soft-disc coverage. The backward keeps `tail = 4.5 + 1.5 = 6` px
//! ([`BACKWARD_EXTRA_TAIL_PX`]; the render's [`model::SCATTER_TAIL_PX`] plus 1.5): gradient
//! sums cancel (`sum_y c(y,x) (Ilin(y) - B(x)) = 0`), so a tail is relatively larger in
//! them than in the render; at 6 px the dropped mass is `e^{-4.5} = 1/90` of the render's.
//! Zero-alpha sources are *not* skipped where their gradient is needed: `dc/da = S O / r^2`
//! does not vanish with alpha, and neither does the soft disc's `do/da = S / Z`.
//!
//! **Refinements before the chain rule** (per layer, receivers x):
//! - the soft-disc coverage is summed again over the backward's reach, with its
//!   derivative `do/dr(x)` and weight `Z(x)` (used by passes A and C), and replaces the
//!   recorded `o`;
//! - where the recorded `W(x) < 1e-2` ([`REFINE_WEIGHT_BELOW`]) and the receiver's window
//!   holds a source with alpha > 0, `W`, `B` (and the soft-disc `o`) are summed over the
//!   whole window: there `W` can be of the order of the dropped tail and of the `1e-8`
//!   regulariser, so `B` (and `o / W`) are set by the tail. The render hides this
//!   (`o(x) ~ 0` there) but `dL/do = dL/dU (B - U_behind)` does not;
//! - the display transfer's derivative is evaluated at the composite of these sums, not
//!   at the rendered value: its curvature for dark pixels would pass the render's own
//!   tail error on to every gradient.
//!
//! **Passes** (per layer; `gc = dL/dC . Ilin(y) + dL/dW`):
//! - A, receivers in 32x16 tiles bounded by the largest radius among sources with
//!   alpha > 0 in the tile's window (as the render): the gradient reaching `d(x)` and K
//!   through `O` and `e(x)` (only where `e(x) >= 1e-9`; below it the render takes `O = 1`),
//!   and through the soft disc's radius;
//! - B, padded sources in 32x16 tiles bounded by the largest radius in the tile (every
//!   alpha), receivers clipped to the image: `dL/dIlin(y)`, `dL/da(y)`, `dL/dd(y)` and K;
//!   runs along receiver rows, 8-lane vectorised (AVX2 when present) in four variants:
//!   with/without occlusion (no receiver in the tile's reach with `e >= 1e-9`: `O = 1`, one
//!   `exp` per tap) and full/alpha-only (a zero-alpha source needs only `sum gc S O`);
//! - C, the coverage's gradient to alpha: the paper's box through one summed-area table
//!   (f64) per half-size that occurs; the soft disc as a gather bounded by the largest
//!   `r_c` within the window of each source tile.
//!
//! Padded gradients are folded onto the pixels they mirror in a fixed order. Kernel
//! apertures use the model's scalar scatter term inside the same bounds.
//!
//! **Agreement.** Within 1e-5 of the largest exact gradient of each kind and layer (f64,
//! derived from the dropped tail in `tests/fast_adjoint.rs`; measured at most 1.9e-6),
//! and in f32 within that plus twice the exact adjoint's own f32 rounding.
//!
//! **Where the time goes** (`drbokeh bench --quick --only adjoint`, 512x512, 2 layers,
//! K 30, L 71, f32, 2 cores shared with other jobs (load average about 8 during the
//! profile), `perf record`): of the whole run (render, forward with tape, backward),
//! 52 % is the two fast forwards (the tape's adds the 1.5 px ring), 31 % pass B, 6 % the
//! full-window refinement of small-`W` receivers (the front layer's empty surround within
//! `R` of its disc; scalar), and the rest (compositing backward, pass A, box coverage by
//! summed-area tables, folds) a few percent. Pass B is the backward: about 600 taps per
//! padded source for both layers (zero-alpha sources included, for their alpha gradient),
//! each one `exp` (two where a receiver is in focus) and about 20 flops. Measured in the
//! same runs: forward 1.0 s, backward 2.2-2.5 s (load average 4-6), 2.1-2.4x the
//! forward; the exact threaded backward took 296 s (load average about 8; 62 s quoted on
//! an idle machine in issue 6).

use super::adjoint::{
    check_grad_output, focus_gradient, layer_gradients, receiver_gradients, sign,
    source_derivatives, Gradients, ReceiverGrads, Saved,
};
use super::fast::{self, WindowTables, FOCUS_WEIGHT_CUTOFF, LANES, ROW_BLOCK, TILE, TILE_ROWS};
use super::Progress;
use crate::aperture::ApertureEval;
use crate::image::Image;
use crate::model;
use crate::presets::{Coverage, RenderSettings, ScatterStep};
use crate::stack::LayerStack;
use crate::Real;
use rayon::prelude::*;

/// The fast schedule's tape: the inputs, and per layer and pixel the sums the fast forward
/// composited.
pub(crate) struct FastTape<T> {
    settings: RenderSettings,
    stack: LayerStack<T>,
    /// Per layer, per pixel (sums out to the backward's reach).
    saved: Vec<Vec<Saved<T>>>,
}

/// Renders with the fast engine (identical bytes to `render(.., Engine::Fast, ..)`) and
/// records the tape. The caller has validated the inputs and started `progress`.
pub(super) fn render_with_tape<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> (Image<T>, FastTape<T>) {
    let (img, _, rec) = fast::render_recording(stack, settings, progress, true);
    let rec = rec.unwrap_or_else(|| unreachable!("render_recording records when asked"));
    (
        img,
        FastTape {
            settings: settings.clone(),
            stack: stack.clone(),
            saved: rec.saved,
        },
    )
}

/// One layer's source terms, reflection-padded by `pad` on every side (struct of arrays).
struct Sources<T> {
    pad: usize,
    stride: usize,
    rows: usize,
    red: Vec<T>,
    green: Vec<T>,
    blue: Vec<T>,
    alpha: Vec<T>,
    rel_disp: Vec<T>,
    radius: Vec<T>,
    inv_area: Vec<T>,
    /// The scatter step's shape.
    step: ScatterStep,
    /// The image pixel each padded pixel mirrors.
    source: Vec<usize>,
}

/// One layer's receiver terms and upstream gradients, image-sized.
struct Receivers<T> {
    width: usize,
    height: usize,
    /// `dL/dC(x)` per channel and `dL/dW(x)`.
    g_red: Vec<T>,
    g_green: Vec<T>,
    g_blue: Vec<T>,
    g_weight: Vec<T>,
    /// `dL/do(x)`.
    g_coverage: Vec<T>,
    /// `e(x)`, set to 0 where it is below [`FOCUS_WEIGHT_CUTOFF`] (there the fast engine
    /// takes `O = 1`).
    focus_weight: Vec<T>,
    rel_disp: Vec<T>,
    radius: Vec<T>,
}

/// Shared read-only state of the passes over one layer.
struct Ctx<'a, T> {
    settings: &'a RenderSettings,
    tables: &'a WindowTables<T>,
    /// `gauge_flip[ddy + R][ddx + R]`: the gauge of the tap from source y to receiver
    /// `x = y + (ddx, ddy)`, i.e. of the offset `y - x = (-ddx, -ddy)`.
    gauge_flip: &'a [Vec<T>],
    aperture: &'a ApertureEval<T>,
    src: &'a Sources<T>,
    rcv: &'a Receivers<T>,
    /// Per receiver, the soft-disc coverage sums with derivatives (empty for the box).
    discs: &'a [model::DiscCoverage<T>],
    k: T,
}

impl<T: Real> FastTape<T> {
    pub(super) fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// Back-propagates `grad_output` on the fast schedule. Deterministic for any thread
    /// count: every output element is computed by one task, in a fixed order.
    pub(super) fn backward(
        &self,
        grad_output: &Image<T>,
        progress: &dyn Progress,
    ) -> crate::Result<Gradients<T>> {
        let (w, h) = (self.stack.width, self.stack.height);
        check_grad_output(grad_output, w, h)?;
        let n_layers = self.stack.layers.len();
        let settings = &self.settings;
        progress.start((n_layers * 3) as u64 + 1);
        let tables = WindowTables::<T>::new(settings);
        let big_r = tables.big_r;
        let aperture = ApertureEval::<T>::new(&settings.aperture);
        let k = T::c(settings.camera.blur_k);
        let prepared: Vec<model::PreparedLayer<T>> = self
            .stack
            .layers
            .iter()
            .map(|l| model::prepare_layer(l, settings))
            .collect();
        let sources: Vec<Sources<T>> = prepared
            .iter()
            .map(|p| Sources::new(p, big_r, settings.model().step))
            .collect();
        // The soft-disc coverage with its derivative, over the backward's longer reach; its
        // value replaces the recorded one (whose shorter tail weighs up to 1.5e-5 of Z at
        // r_c ~ 0), so that o and do/dr come from the same sums.
        let discs: Vec<Vec<model::DiscCoverage<T>>> = sources
            .iter()
            .map(|src| {
                if settings.model().coverage != Coverage::SoftDisc {
                    return Vec::new();
                }
                (0..w * h)
                    .into_par_iter()
                    .map(|i| {
                        let xi = (i / w + big_r) * src.stride + i % w + big_r;
                        disc_coverage_with_derivative(src, &tables, &aperture, settings, xi)
                    })
                    .collect()
            })
            .collect();
        let saved: Vec<Vec<Saved<T>>> = self
            .saved
            .iter()
            .zip(&discs)
            .map(|(saved, discs)| {
                let mut saved = saved.clone();
                for (s, d) in saved.iter_mut().zip(discs) {
                    s.coverage = d.value();
                }
                saved
            })
            .collect();
        // Receivers whose weight sum is of the order of the dropped tail: their layer colour
        // B = C / (W + 1e-8) is set by the tail (the output hides it, o(x) ~ 0 there, but
        // dL/do does not), so C and W are summed again over the whole window.
        let saved: Vec<Vec<Saved<T>>> = saved
            .iter()
            .zip(&sources)
            .map(|(saved, src)| refine_small_weights(saved, src, &tables, &aperture, settings))
            .collect();
        // The composite of the refined sums: the display transfer's derivative is steep for
        // dark pixels, and evaluating it at the rendered value would pass the render's own
        // tail error (<= 1e-5) on to every gradient through the transfer's curvature.
        let linear: Vec<[T; 3]> = (0..w * h)
            .into_par_iter()
            .map(|i| {
                model::composite((0..n_layers).map(|l| (saved[l][i].colour, saved[l][i].coverage)))
            })
            .collect();
        let receivers = receiver_gradients(
            n_layers,
            |i, l| saved[l][i],
            &linear,
            grad_output,
            &settings.tone(),
        );
        drop(saved);
        progress.advance(1);
        let (dlin_dencoded, dlin_ddisp) = source_derivatives(&self.stack, settings);
        let gauge_flip: Vec<Vec<T>> = (0..=2 * big_r)
            .map(|row| {
                tables.gauge[2 * big_r - row]
                    .iter()
                    .rev()
                    .copied()
                    .collect()
            })
            .collect();
        let mut blur_k = 0.0;
        let mut layers_out = Vec::with_capacity(n_layers);
        for (l, (rg, (prepared, src))) in receivers
            .into_iter()
            .zip(prepared.into_iter().zip(sources))
            .enumerate()
        {
            let rcv = Receivers::new(prepared, rg, k);
            let ctx = Ctx {
                settings,
                tables: &tables,
                gauge_flip: &gauge_flip,
                aperture: &aperture,
                src: &src,
                rcv: &rcv,
                discs: &discs[l],
                k,
            };
            let (g_disp_receiver, share, k_a) = pass_receivers(&ctx);
            progress.advance(1);
            let (g_lin, g_alpha_scatter, g_disp_source, k_b) = pass_sources(&ctx);
            progress.advance(1);
            let g_alpha_cov = match settings.model().coverage {
                Coverage::PaperBox => pass_coverage_box(&ctx),
                Coverage::SoftDisc => pass_coverage_disc(&ctx, &share),
            };
            progress.advance(1);
            blur_k += k_a + k_b;
            layers_out.push(layer_gradients(
                (w, h),
                &g_lin,
                |i| g_alpha_scatter[i] + g_alpha_cov[i],
                |i| g_disp_receiver[i] + g_disp_source[i],
                &dlin_dencoded[l],
                &dlin_ddisp[l],
            ));
        }
        let focus = focus_gradient(&layers_out);
        Ok(Gradients {
            layers: layers_out,
            blur_k,
            focus,
        })
    }
}

/// Recorded weight sums below this are recomputed over the whole window before the
/// backward pass ([`refine_small_weights`]). The dropped tail weighs at most about 6e-6 per
/// unit alpha (`model::SCATTER_TAIL_PX`), so above this B is within 6e-4 of the exact
/// value even in the worst case (measured: ~1e-8 on the test scenes), and below it the
/// exact sums are cheap enough: such receivers lie in a layer's (nearly) empty regions.
pub(super) const REFINE_WEIGHT_BELOW: f64 = 1e-2;

/// The recorded sums of one layer, with `W` and `B` recomputed over every window tap
/// (no reach bound) where `W < REFINE_WEIGHT_BELOW` and some source with alpha > 0 lies in
/// the receiver's window (elsewhere `W = 0` exactly in both schedules).
fn refine_small_weights<T: Real>(
    saved: &[Saved<T>],
    src: &Sources<T>,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    settings: &RenderSettings,
) -> Vec<Saved<T>> {
    let big_r = tables.big_r;
    let (w, stride) = (src.stride - 2 * big_r, src.stride);
    let block_max = source_block_max(src, |i| src.alpha[i] > T::zero());
    let k = T::c(settings.camera.blur_k);
    let cutoff = T::c(FOCUS_WEIGHT_CUTOFF);
    let eps = T::c(model::WEIGHT_EPSILON);
    let below = T::c(REFINE_WEIGHT_BELOW);
    let opts = settings.model();
    let footprint = T::c(opts.footprint.px());
    let window = tables.big_r as f64;
    let widths: Vec<Option<usize>> = (-(big_r as isize)..=big_r as isize)
        .map(|dy| tables.half_width(dy, window))
        .collect();
    saved
        .par_chunks(w)
        .enumerate()
        .flat_map_iter(|(y, row)| {
            // Any source with alpha > 0 in the window of this row's receivers?
            let blocks = y / ROW_BLOCK..=(y + 2 * big_r) / ROW_BLOCK;
            let occupied: Vec<bool> = (0..w)
                .map(|x| {
                    blocks.clone().any(|b| {
                        block_max[b * stride + x..b * stride + x + 2 * big_r + 1]
                            .iter()
                            .any(|m| *m > f64::NEG_INFINITY)
                    })
                })
                .collect();
            let widths = &widths;
            row.iter().enumerate().map(move |(x, s)| {
                if s.weight >= below || !occupied[x] {
                    return *s;
                }
                let xi = (y + big_r) * stride + x + big_r;
                let d_x = src.rel_disp[xi];
                let e_x = model::focus_weight(k, d_x);
                let mut acc = model::Accumulator::<T>::default();
                for dy in -(big_r as isize)..=big_r as isize {
                    let t = (dy + big_r as isize) as usize;
                    let Some(hw) = widths[t] else {
                        continue;
                    };
                    for dx in -(hw as isize)..=hw as isize {
                        let yi = (xi as isize + dy * stride as isize + dx) as usize;
                        let a = src.alpha[yi];
                        if a == T::zero() {
                            continue;
                        }
                        let g0 = (dx + big_r as isize) as usize;
                        let sc = model::scatter_term(
                            src.step,
                            aperture,
                            dx,
                            dy,
                            T::c(tables.dist[t][g0]),
                            tables.gauge[t][g0],
                            src.radius[yi],
                        );
                        let o = if (dx, dy) == (0, 0) || e_x < cutoff {
                            T::one()
                        } else {
                            model::occlusion(e_x, src.rel_disp[yi], d_x)
                        };
                        acc.add(
                            [src.red[yi], src.green[yi], src.blue[yi]],
                            model::tap_weight(src.step, a, sc, src.radius[yi], o),
                        );
                    }
                }
                let inv = T::one() / (acc.weight + eps);
                // The soft-disc coverage has a tail as well, and dL/dC = dL/dB o / (W + eps)
                // is a ratio of the two tails there.
                let coverage = match opts.coverage {
                    Coverage::PaperBox => s.coverage,
                    Coverage::SoftDisc => {
                        let (r_c, _) = model::coverage_radius_px(
                            src.radius[xi],
                            opts.coverage_radius,
                            footprint,
                        );
                        let mut disc = model::DiscCoverage::<T>::default();
                        for dy in -(big_r as isize)..=big_r as isize {
                            let t = (dy + big_r as isize) as usize;
                            let Some(hw) = widths[t] else {
                                continue;
                            };
                            for dx in -(hw as isize)..=hw as isize {
                                let yi = (xi as isize + dy * stride as isize + dx) as usize;
                                let g0 = (dx + big_r as isize) as usize;
                                let sc = model::scatter_term(
                                    src.step,
                                    aperture,
                                    dx,
                                    dy,
                                    T::c(tables.dist[t][g0]),
                                    tables.gauge[t][g0],
                                    r_c,
                                );
                                disc.add(sc, src.alpha[yi]);
                            }
                        }
                        disc.value()
                    }
                };
                Saved {
                    weight: acc.weight,
                    colour: acc.colour.map(|c| c * inv),
                    coverage,
                }
            })
        })
        .collect()
}

impl<T: Real> Sources<T> {
    fn new(layer: &model::PreparedLayer<T>, pad: usize, step: ScatterStep) -> Self {
        let (w, h) = (layer.width, layer.height);
        let (stride, rows) = (w + 2 * pad, h + 2 * pad);
        let source: Vec<usize> = (0..rows)
            .flat_map(|py| {
                let sy = model::reflect(py as isize - pad as isize, h);
                (0..stride).map(move |px| sy * w + model::reflect(px as isize - pad as isize, w))
            })
            .collect();
        let gather = |plane: &[T]| source.par_iter().map(|&i| plane[i]).collect::<Vec<T>>();
        let channel = |c: usize| {
            source
                .par_iter()
                .map(|&i| layer.rgb_linear[3 * i + c])
                .collect::<Vec<T>>()
        };
        let radius = gather(&layer.radius_px);
        Sources {
            pad,
            stride,
            rows,
            red: channel(0),
            green: channel(1),
            blue: channel(2),
            alpha: gather(&layer.alpha),
            rel_disp: gather(&layer.rel_disp),
            inv_area: radius
                .par_iter()
                .map(|&r| T::one() / model::source_area(step, r))
                .collect(),
            step,
            radius,
            source,
        }
    }
}

impl<T: Real> Receivers<T> {
    fn new(layer: model::PreparedLayer<T>, rg: ReceiverGrads<T>, k: T) -> Self {
        let cutoff = T::c(FOCUS_WEIGHT_CUTOFF);
        let e: Vec<T> = layer
            .rel_disp
            .iter()
            .map(|&d| {
                let e = model::focus_weight(k, d);
                if e >= cutoff {
                    e
                } else {
                    T::zero()
                }
            })
            .collect();
        Receivers {
            width: layer.width,
            height: layer.height,
            g_red: rg.d_colour_sum.iter().map(|g| g[0]).collect(),
            g_green: rg.d_colour_sum.iter().map(|g| g[1]).collect(),
            g_blue: rg.d_colour_sum.iter().map(|g| g[2]).collect(),
            g_weight: rg.d_weight_sum,
            g_coverage: rg.d_coverage,
            focus_weight: e,
            rel_disp: layer.rel_disp,
            radius: layer.radius_px,
        }
    }
}

/// How much further than the forward ([`model::SCATTER_TAIL_PX`]) the backward passes keep
/// the soft step's tail: gradient sums cancel (`sum_y c(y,x) (Ilin(y) - B(x)) = 0`), so
/// the tail matters more to them, relative to their size, than to the render. With
/// `4.5 + 1.5 = 6` px the dropped kernel mass shrinks by `e^{-4.5} = 1/90`.
pub(super) const BACKWARD_EXTRA_TAIL_PX: f64 = super::fast::RECORD_EXTRA_TAIL_PX;

/// The backward passes' reach of a source (or disc) of radius `r`.
#[inline(always)]
fn backward_reach<T: Real>(aperture: &ApertureEval<T>, r: f64) -> f64 {
    aperture.reach_px(r) + BACKWARD_EXTRA_TAIL_PX
}

/// Sums of `LANES` partial sums, in lane order.
#[inline(always)]
fn lane_sum<T: Real>(v: &[T; LANES]) -> T {
    v.iter().fold(T::zero(), |a, &b| a + b)
}

/// Calls `$f(args)` compiled for AVX2 when the CPU has it (same arithmetic, same bytes on
/// one machine), else for the baseline target: defines the wrapper `$name`.
macro_rules! avx2_dispatch {
    ($name:ident, $avx:ident, $f:ident, ($($arg:ident : $ty:ty),*) -> $ret:ty) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        unsafe fn $avx<T: Real>($($arg: $ty),*) -> $ret {
            $f($($arg),*)
        }
        fn $name<T: Real>($($arg: $ty),*) -> $ret {
            #[cfg(target_arch = "x86_64")]
            {
                if std::arch::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU supports AVX2 (checked just above).
                    return unsafe { $avx($($arg),*) };
                }
            }
            $f($($arg),*)
        }
    };
}

// ---------------------------------------------------------------------------------------
// Pass A: receivers. The gradient reaching d(x) (and K) through O and e, and through the
// soft-disc coverage's radius r(x); also each receiver's disc weight Z(x).
// ---------------------------------------------------------------------------------------

/// Per receiver: the gradient to `d(x)`, `dL/do(x) / Z(x)` (soft-disc coverage only, else
/// empty) and K's total.
fn pass_receivers<T: Real>(ctx: &Ctx<'_, T>) -> (Vec<T>, Vec<T>, f64) {
    let (w, h) = (ctx.rcv.width, ctx.rcv.height);
    let block_max = source_block_max(ctx.src, |i| ctx.src.alpha[i] > T::zero());
    let disc = ctx.settings.model().coverage == Coverage::SoftDisc;
    let tiles: Vec<(Vec<T>, Vec<T>, f64)> = (0..h)
        .step_by(TILE_ROWS)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|y0| receivers_tile_row_dispatch(ctx, &block_max, y0))
        .collect();
    let mut g_d = Vec::with_capacity(w * h);
    let mut share = Vec::with_capacity(if disc { w * h } else { 0 });
    let mut k_total = 0.0;
    for (g, s, k) in tiles {
        g_d.extend(g);
        share.extend(s);
        k_total += k;
    }
    (g_d, share, k_total)
}

/// Per block of [`ROW_BLOCK`] padded rows and per padded column, the largest source radius
/// among the pixels that `keep`.
fn source_block_max<T: Real>(src: &Sources<T>, keep: impl Fn(usize) -> bool + Sync) -> Vec<f64> {
    let blocks = src.rows.div_ceil(ROW_BLOCK);
    (0..blocks)
        .into_par_iter()
        .flat_map_iter(|b| {
            let keep = &keep;
            (0..src.stride).map(move |px| {
                let mut m = f64::NEG_INFINITY;
                for py in b * ROW_BLOCK..((b + 1) * ROW_BLOCK).min(src.rows) {
                    let i = py * src.stride + px;
                    if keep(i) {
                        m = m.max(src.radius[i].f64());
                    }
                }
                m
            })
        })
        .collect()
}

avx2_dispatch!(
    receivers_tile_row_dispatch,
    receivers_tile_row_avx2,
    receivers_tile_row,
    (ctx: &Ctx<'_, T>, block_max: &[f64], y0: usize) -> (Vec<T>, Vec<T>, f64)
);

/// Pass A over the receiver rows `y0 .. y0 + TILE_ROWS`, tile by tile.
#[inline(always)]
fn receivers_tile_row<T: Real>(
    ctx: &Ctx<'_, T>,
    block_max: &[f64],
    y0: usize,
) -> (Vec<T>, Vec<T>, f64) {
    let (src, rcv, tables) = (ctx.src, ctx.rcv, ctx.tables);
    let (w, h, big_r, stride) = (rcv.width, rcv.height, tables.big_r, src.stride);
    let y1 = (y0 + TILE_ROWS).min(h);
    let k = ctx.k;
    let model_opts = ctx.settings.model();
    let disc = model_opts.coverage == Coverage::SoftDisc;
    let mut g_d = vec![T::zero(); (y1 - y0) * w];
    let mut share = vec![T::zero(); if disc { (y1 - y0) * w } else { 0 }];
    let mut k_rows = vec![0.0f64; (y1 - y0) * w];
    for x0 in (0..w).step_by(TILE) {
        let x1 = (x0 + TILE).min(w);
        // Largest radius among sources with alpha > 0 in the tile's window (padded coords:
        // receiver (x, y) sits at (x + R, y + R); its window spans x .. x + 2R).
        let mut max_r = f64::NEG_INFINITY;
        for block in y0 / ROW_BLOCK..=(y1 - 1 + 2 * big_r) / ROW_BLOCK {
            let row = &block_max[block * stride..(block + 1) * stride];
            max_r = row[x0..x1 + 2 * big_r]
                .iter()
                .copied()
                .fold(max_r, f64::max);
        }
        let widths: Vec<Option<usize>> = if max_r > f64::NEG_INFINITY {
            let reach = backward_reach(ctx.aperture, max_r);
            (-(big_r as isize)..=big_r as isize)
                .map(|dy| tables.half_width(dy, reach))
                .collect()
        } else {
            Vec::new()
        };
        for y in y0..y1 {
            for x in x0..x1 {
                let i = y * w + x;
                let o = (y - y0) * w + x;
                let xi = (y + big_r) * stride + x + big_r;
                let (d_x, e_x) = (rcv.rel_disp[i], rcv.focus_weight[i]);
                let (mut gd, mut gk) = (T::zero(), T::zero());
                if e_x > T::zero() && !widths.is_empty() {
                    // sum over y != x of base = gc a S / A, times s'(D) and (s(D) - 1).
                    let gc = [rcv.g_red[i], rcv.g_green[i], rcv.g_blue[i], rcv.g_weight[i]];
                    let (mut p1, mut p2) = (T::zero(), T::zero());
                    for dy in -(big_r as isize)..=big_r as isize {
                        let t = (dy + big_r as isize) as usize;
                        let Some(hw) = widths[t] else {
                            continue;
                        };
                        let row = (xi as isize + dy * stride as isize) as usize;
                        let g0 = big_r - hw;
                        let n = 2 * hw + 1;
                        let gauge = &tables.gauge[t][g0..g0 + n];
                        // The centre tap has O(x, x) = 1: no dependence on d(x).
                        let segments = if dy == 0 {
                            [(0, hw), (hw + 1, n)]
                        } else {
                            [(0, n), (n, n)]
                        };
                        for (start, end) in segments {
                            if start >= end {
                                continue;
                            }
                            let (a, b) = match ctx.aperture {
                                ApertureEval::Gauge => occlusion_run(
                                    src,
                                    row - hw + start,
                                    &gauge[start..end],
                                    gc,
                                    d_x,
                                ),
                                ApertureEval::Kernel(..) => occlusion_run_kernel(
                                    ctx,
                                    row - hw,
                                    (start, end, hw, dy),
                                    gc,
                                    d_x,
                                ),
                            };
                            p1 = p1 + a;
                            p2 = p2 + b;
                        }
                    }
                    let (de_dd, de_dk) = model::focus_weight_derivatives(k, d_x, e_x);
                    // dO/dd_x|_e = -e s', dO/de = s - 1.
                    gd = -e_x * p1 + de_dd * p2;
                    gk = de_dk * p2;
                }
                if disc {
                    let cov = &ctx.discs[i];
                    let g_r = rcv.g_coverage[i] * cov.derivative_radius();
                    gd = gd + g_r * k * sign(d_x);
                    gk = gk + g_r * d_x.abs();
                    share[o] = rcv.g_coverage[i] / cov.weight;
                }
                g_d[o] = gd;
                k_rows[o] = gk.f64();
            }
        }
    }
    (g_d, share, k_rows.iter().sum())
}

/// Pass A's run over sources `lo .. lo + gauge.len()` (padded) for one receiver:
/// `(sum base s'(D), sum base (s(D) - 1))` with `base = gc a S / A`,
/// `gc = dL/dC . Ilin(y) + dL/dW`, `D = d(y) - d(x)`.
#[inline(always)]
fn occlusion_run<T: Real>(src: &Sources<T>, lo: usize, gauge: &[T], gc: [T; 4], d_x: T) -> (T, T) {
    let n = gauge.len();
    let (red, green, blue) = (
        &src.red[lo..lo + n],
        &src.green[lo..lo + n],
        &src.blue[lo..lo + n],
    );
    let (alpha, radius, inv_area, disp) = (
        &src.alpha[lo..lo + n],
        &src.radius[lo..lo + n],
        &src.inv_area[lo..lo + n],
        &src.rel_disp[lo..lo + n],
    );
    let (mut l1, mut l2) = ([T::zero(); LANES], [T::zero(); LANES]);
    let (mut t1, mut t2) = ([T::zero(); CHUNK], [T::zero(); CHUNK]);
    let mut start = 0;
    while start < n {
        let m = (n - start).min(CHUNK);
        for j in 0..m {
            let i = start + j;
            let s = model::scatter_step_fast(src.step, radius[i] - gauge[i]);
            let g = gc[0] * red[i] + gc[1] * green[i] + gc[2] * blue[i] + gc[3];
            let base = g * alpha[i] * s * inv_area[i];
            let ds = model::depth_step_fast(disp[i] - d_x);
            t1[j] = base * model::depth_step_derivative_from_value(ds);
            t2[j] = base * (ds - T::one());
        }
        let full = m / LANES * LANES;
        for base in (0..full).step_by(LANES) {
            for l in 0..LANES {
                l1[l] = l1[l] + t1[base + l];
                l2[l] = l2[l] + t2[base + l];
            }
        }
        for j in full..m {
            l1[j - full] = l1[j - full] + t1[j];
            l2[j - full] = l2[j - full] + t2[j];
        }
        start += m;
    }
    (lane_sum(&l1), lane_sum(&l2))
}

/// [`occlusion_run`] for kernel apertures (the model's scalar scatter term): taps
/// `start .. end` of the row `dy` of half-width `hw` starting at padded index `lo`.
fn occlusion_run_kernel<T: Real>(
    ctx: &Ctx<'_, T>,
    lo: usize,
    (start, end, hw, dy): (usize, usize, usize, isize),
    gc: [T; 4],
    d_x: T,
) -> (T, T) {
    let (src, tables) = (ctx.src, ctx.tables);
    let t = (dy + tables.big_r as isize) as usize;
    let (mut p1, mut p2) = (T::zero(), T::zero());
    for j in start..end {
        let yi = lo + j;
        let a = src.alpha[yi];
        if a == T::zero() {
            continue;
        }
        let dx = j as isize - hw as isize;
        let g0 = (dx + tables.big_r as isize) as usize;
        let s = model::scatter_term(
            src.step,
            ctx.aperture,
            dx,
            dy,
            T::c(tables.dist[t][g0]),
            tables.gauge[t][g0],
            src.radius[yi],
        );
        let g = gc[0] * src.red[yi] + gc[1] * src.green[yi] + gc[2] * src.blue[yi] + gc[3];
        let base = g * a * s * src.inv_area[yi];
        let ds = model::depth_step_fast(src.rel_disp[yi] - d_x);
        p1 = p1 + base * model::depth_step_derivative_from_value(ds);
        p2 = p2 + base * (ds - T::one());
    }
    (p1, p2)
}

/// The soft-disc coverage sums at padded receiver `xi` with their derivatives with respect
/// to `r(x)` (times `dr_c/dr(x)`), over the taps within the receiver's reach `r_c + tail`.
#[inline(always)]
fn disc_coverage_with_derivative<T: Real>(
    src: &Sources<T>,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    settings: &RenderSettings,
    xi: usize,
) -> model::DiscCoverage<T> {
    let big_r = tables.big_r as isize;
    let opts = settings.model();
    let footprint = T::c(opts.footprint.px());
    let (r_x, dr) = model::coverage_radius_px(src.radius[xi], opts.coverage_radius, footprint);
    let reach = backward_reach(aperture, r_x.f64());
    let mut disc = model::DiscCoverage::<T>::default();
    for dy in -big_r..=big_r {
        let Some(hw) = tables.half_width(dy, reach) else {
            continue;
        };
        let row = (xi as isize + dy * src.stride as isize) as usize;
        let t = (dy + big_r) as usize;
        let g0 = tables.big_r - hw;
        let n = 2 * hw + 1;
        let alpha = &src.alpha[row - hw..row - hw + n];
        let gauge = &tables.gauge[t][g0..g0 + n];
        match aperture {
            ApertureEval::Gauge => {
                let mut lanes = [[T::zero(); LANES]; 4];
                for i in 0..n {
                    let s = model::scatter_step_fast(src.step, r_x - gauge[i]);
                    let ds = model::scatter_step_derivative(src.step, s) * dr;
                    let l = i % LANES;
                    lanes[0][l] = lanes[0][l] + s * alpha[i];
                    lanes[1][l] = lanes[1][l] + s;
                    lanes[2][l] = lanes[2][l] + ds * alpha[i];
                    lanes[3][l] = lanes[3][l] + ds;
                }
                disc.alpha_sum = disc.alpha_sum + lane_sum(&lanes[0]);
                disc.weight = disc.weight + lane_sum(&lanes[1]);
                disc.d_alpha_sum = disc.d_alpha_sum + lane_sum(&lanes[2]);
                disc.d_weight = disc.d_weight + lane_sum(&lanes[3]);
            }
            ApertureEval::Kernel(..) => {
                let dist = &tables.dist[t][g0..g0 + n];
                for i in 0..n {
                    let dx = i as isize - hw as isize;
                    let (s, ds) = model::scatter_term_with_derivative(
                        src.step,
                        aperture,
                        dx,
                        dy,
                        T::c(dist[i]),
                        gauge[i],
                        r_x,
                    );
                    disc.add_with_derivative(s, ds * dr, alpha[i]);
                }
            }
        }
    }
    disc
}

// ---------------------------------------------------------------------------------------
// Pass B: sources. Over padded source pixels y: the gradients reaching Ilin(y), a(y), d(y)
// (through S, A and O) and K (through r(y)), gathered from the receivers within the
// source's reach. Zero-alpha sources still get their alpha gradient.
// ---------------------------------------------------------------------------------------

/// Gradients per image pixel: linear colour, alpha (scatter part), disparity (source
/// part), and K's total.
#[allow(clippy::type_complexity)]
fn pass_sources<T: Real>(ctx: &Ctx<'_, T>) -> (Vec<[T; 3]>, Vec<T>, Vec<T>, f64) {
    let src = ctx.src;
    let occluding = occluding_table(ctx);
    let tiles: Vec<(Vec<[T; 5]>, f64)> = (0..src.rows)
        .step_by(TILE_ROWS)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|y0| sources_tile_row_dispatch(ctx, &occluding, y0))
        .collect();
    let n = ctx.rcv.width * ctx.rcv.height;
    let (mut g_lin, mut g_a, mut g_d) = (
        vec![[T::zero(); 3]; n],
        vec![T::zero(); n],
        vec![T::zero(); n],
    );
    let mut k_total = 0.0;
    let mut p = 0;
    for (tile, k) in tiles {
        k_total += k;
        for v in tile {
            let s = src.source[p];
            for c in 0..3 {
                g_lin[s][c] = g_lin[s][c] + v[c];
            }
            g_a[s] = g_a[s] + v[3];
            g_d[s] = g_d[s] + v[4];
            p += 1;
        }
    }
    (g_lin, g_a, g_d, k_total)
}

/// Summed-area table (padded coordinates, `(rows + 1) x (stride + 1)`) of the receivers
/// whose occlusion term is evaluated (`e(x) > 0` after the cutoff).
fn occluding_table<T: Real>(ctx: &Ctx<'_, T>) -> Vec<u32> {
    let (src, rcv) = (ctx.src, ctx.rcv);
    let s1 = src.stride + 1;
    let mut sat = vec![0u32; (src.rows + 1) * s1];
    for py in 0..src.rows {
        let mut run = 0u32;
        for px in 0..src.stride {
            let (y, x) = (
                py as isize - src.pad as isize,
                px as isize - src.pad as isize,
            );
            if y >= 0
                && x >= 0
                && (y as usize) < rcv.height
                && (x as usize) < rcv.width
                && rcv.focus_weight[y as usize * rcv.width + x as usize] > T::zero()
            {
                run += 1;
            }
            sat[(py + 1) * s1 + px + 1] = sat[py * s1 + px + 1] + run;
        }
    }
    sat
}

avx2_dispatch!(
    sources_tile_row_dispatch,
    sources_tile_row_avx2,
    sources_tile_row,
    (ctx: &Ctx<'_, T>, occluding: &[u32], y0: usize) -> (Vec<[T; 5]>, f64)
);

/// Source terms of one padded pixel, for [`source_run`].
#[derive(Clone, Copy)]
struct SourceTerms<T> {
    step: ScatterStep,
    radius: T,
    /// `A'(r) / A(r)` of the source area ([`model::source_area`]): `2 / r` for the paper.
    dlog_area: T,
    rel_disp: T,
    lin: [T; 3],
}

/// Pass B over the padded source rows `y0 .. y0 + TILE_ROWS`, tile by tile. Returns per
/// padded pixel `[g_lin r, g, b, g_alpha, g_disp]` and K's share.
#[inline(always)]
fn sources_tile_row<T: Real>(ctx: &Ctx<'_, T>, occluding: &[u32], y0: usize) -> (Vec<[T; 5]>, f64) {
    let (src, rcv, tables) = (ctx.src, ctx.rcv, ctx.tables);
    let (stride, big_r, pad) = (src.stride, tables.big_r, src.pad);
    let y1 = (y0 + TILE_ROWS).min(src.rows);
    let k = ctx.k;
    let mut out = vec![[T::zero(); 5]; (y1 - y0) * stride];
    let mut k_rows = vec![0.0f64; (y1 - y0) * stride];
    // Receivers occupy padded rows pad .. pad + h and columns pad .. pad + w.
    let (ry0, ry1, rx0, rx1) = (pad, pad + rcv.height, pad, pad + rcv.width);
    for x0 in (0..stride).step_by(TILE) {
        let x1 = (x0 + TILE).min(stride);
        let mut max_r = f64::NEG_INFINITY;
        for py in y0..y1 {
            for &r in &src.radius[py * stride + x0..py * stride + x1] {
                max_r = max_r.max(r.f64());
            }
        }
        let reach = backward_reach(ctx.aperture, max_r).min(big_r as f64);
        let reach_px = reach.ceil() as usize;
        // Receiver rectangle any source of the tile can reach, clipped to the image.
        let qy0 = y0.saturating_sub(reach_px).max(ry0);
        let qy1 = (y1 + reach_px).min(ry1);
        let qx0 = x0.saturating_sub(reach_px).max(rx0);
        let qx1 = (x1 + reach_px).min(rx1);
        if qy0 >= qy1 || qx0 >= qx1 {
            continue;
        }
        let s1 = stride + 1;
        let occ_count = occluding[qy1 * s1 + qx1] + occluding[qy0 * s1 + qx0]
            - occluding[qy0 * s1 + qx1]
            - occluding[qy1 * s1 + qx0];
        let occ = occ_count > 0;
        let widths: Vec<Option<usize>> = (-(big_r as isize)..=big_r as isize)
            .map(|dy| tables.half_width(dy, reach))
            .collect();
        for py in y0..y1 {
            for px in x0..x1 {
                let p = py * stride + px;
                let a = src.alpha[p];
                let r = src.radius[p];
                let terms = SourceTerms {
                    step: src.step,
                    radius: r,
                    dlog_area: model::source_area_derivative(src.step, r)
                        / model::source_area(src.step, r),
                    rel_disp: src.rel_disp[p],
                    lin: [src.red[p], src.green[p], src.blue[p]],
                };
                let full = a != T::zero();
                let mut acc = [T::zero(); 6];
                for ddy in -(big_r as isize)..=big_r as isize {
                    let t = (ddy + big_r as isize) as usize;
                    let Some(hw) = widths[t] else {
                        continue;
                    };
                    let qy = py as isize + ddy;
                    if qy < ry0 as isize || qy >= ry1 as isize {
                        continue;
                    }
                    // Receivers qx in [px - hw, px + hw] within the image.
                    let lo = (px as isize - hw as isize).max(rx0 as isize);
                    let hi = (px as isize + hw as isize).min(rx1 as isize - 1);
                    if lo > hi {
                        continue;
                    }
                    let row = (qy as usize - pad) * rcv.width;
                    let centre_inside = ddy == 0 && (lo..=hi).contains(&(px as isize));
                    let seg = RowSegment { row, px, pad, t };
                    if centre_inside {
                        source_row_run(ctx, seg, lo, px as isize - 1, (occ, full), terms, &mut acc);
                        source_row_run(ctx, seg, px as isize + 1, hi, (occ, full), terms, &mut acc);
                        // The centre tap: O(x, x) = 1.
                        let i = row + (px - pad);
                        let (s, ds) = centre_scatter(src.step, ctx.aperture, r);
                        let gc = rcv.g_red[i] * terms.lin[0]
                            + rcv.g_green[i] * terms.lin[1]
                            + rcv.g_blue[i] * terms.lin[2]
                            + rcv.g_weight[i];
                        acc[0] = acc[0] + rcv.g_red[i] * s;
                        acc[1] = acc[1] + rcv.g_green[i] * s;
                        acc[2] = acc[2] + rcv.g_blue[i] * s;
                        acc[3] = acc[3] + gc * s;
                        acc[4] = acc[4] + gc * (ds - s * terms.dlog_area);
                    } else {
                        source_row_run(ctx, seg, lo, hi, (occ, full), terms, &mut acc);
                    }
                }
                let inv_area = src.inv_area[p];
                let a_inv = a * inv_area;
                let g_r = acc[4] * a_inv;
                let d_y = terms.rel_disp;
                let o = (py - y0) * stride + px;
                out[o] = [
                    acc[0] * a_inv,
                    acc[1] * a_inv,
                    acc[2] * a_inv,
                    acc[3] * inv_area,
                    acc[5] * a_inv + g_r * k * sign(d_y),
                ];
                k_rows[o] = (g_r * d_y.abs()).f64();
            }
        }
    }
    (out, k_rows.iter().sum())
}

/// Where a run of receivers lies: the image index of its row's start, the source column
/// `px` and the padding (padded coordinates), and the flipped tables' row `t`.
#[derive(Clone, Copy)]
struct RowSegment {
    row: usize,
    px: usize,
    pad: usize,
    t: usize,
}

/// Pass B over the receivers in padded columns `from ..= to` of one row, added to `acc`.
#[inline(always)]
fn source_row_run<T: Real>(
    ctx: &Ctx<'_, T>,
    seg: RowSegment,
    from: isize,
    to: isize,
    (occ, full): (bool, bool),
    terms: SourceTerms<T>,
    acc: &mut [T; 6],
) {
    if from > to {
        return;
    }
    let big_r = ctx.tables.big_r as isize;
    let (i0, n) = (
        seg.row + (from as usize - seg.pad),
        (to - from + 1) as usize,
    );
    let g0 = (from - seg.px as isize + big_r) as usize;
    let rcv = ctx.rcv;
    let v = match ctx.aperture {
        ApertureEval::Gauge => {
            let gauge = &ctx.gauge_flip[seg.t][g0..g0 + n];
            match (occ, full) {
                (true, true) => source_run::<T, true, true>(rcv, i0, gauge, terms),
                (true, false) => source_run::<T, true, false>(rcv, i0, gauge, terms),
                (false, true) => source_run::<T, false, true>(rcv, i0, gauge, terms),
                (false, false) => source_run::<T, false, false>(rcv, i0, gauge, terms),
            }
        }
        ApertureEval::Kernel(..) => source_run_kernel(ctx, i0, n, (g0, seg.t), terms, full),
    };
    for (a, b) in acc.iter_mut().zip(v) {
        *a = *a + b;
    }
}

/// The scatter term of the centre tap and its derivative with respect to `r`.
#[inline(always)]
fn centre_scatter<T: Real>(step: ScatterStep, aperture: &ApertureEval<T>, r: T) -> (T, T) {
    match aperture {
        ApertureEval::Gauge => {
            let s = model::scatter_step_fast(step, r);
            (s, model::scatter_step_derivative(step, s))
        }
        ApertureEval::Kernel(..) => {
            model::scatter_term_with_derivative(step, aperture, 0, 0, T::zero(), T::zero(), r)
        }
    }
}

/// Taps per chunk of a run: per-tap terms are first computed for a chunk into scratch
/// arrays (a plain map, which the compiler vectorises), then reduced in [`LANES`] lanes.
const CHUNK: usize = 64;

/// Pass B's run over receivers `i0 .. i0 + gauge.len()` (image indices of one row) for one
/// source: `[sum gC S O (3), sum gc S O, sum gc O (S' - S A'/A), sum gc S dO/dd_y]` with
/// `gc = dL/dC . Ilin(y) + dL/dW`. `OCC = false`: every receiver has `O = 1`. `FULL =
/// false` (alpha = 0): only the alpha gradient's sum is needed.
#[inline(always)]
fn source_run<T: Real, const OCC: bool, const FULL: bool>(
    rcv: &Receivers<T>,
    i0: usize,
    gauge: &[T],
    src: SourceTerms<T>,
) -> [T; 6] {
    let n = gauge.len();
    let mut lanes = [[T::zero(); LANES]; 6];
    let (mut so, mut ga, mut rad, mut dyv) = (
        [T::zero(); CHUNK],
        [T::zero(); CHUNK],
        [T::zero(); CHUNK],
        [T::zero(); CHUNK],
    );
    let mut start = 0;
    while start < n {
        let m = (n - start).min(CHUNK);
        let s0 = i0 + start;
        let (gr, gg, gb, gw) = (
            &rcv.g_red[s0..s0 + m],
            &rcv.g_green[s0..s0 + m],
            &rcv.g_blue[s0..s0 + m],
            &rcv.g_weight[s0..s0 + m],
        );
        let (e, dx) = (&rcv.focus_weight[s0..s0 + m], &rcv.rel_disp[s0..s0 + m]);
        let g = &gauge[start..start + m];
        for i in 0..m {
            let s = model::scatter_step_fast(src.step, src.radius - g[i]);
            let (o, d_o) = if OCC {
                let ds = model::depth_step_fast(src.rel_disp - dx[i]);
                (
                    T::one() + e[i] * (ds - T::one()),
                    e[i] * model::depth_step_derivative_from_value(ds),
                )
            } else {
                (T::one(), T::zero())
            };
            let gc = gr[i] * src.lin[0] + gg[i] * src.lin[1] + gb[i] * src.lin[2] + gw[i];
            so[i] = s * o;
            ga[i] = gc * so[i];
            if FULL {
                let sd = model::scatter_step_derivative(src.step, s);
                rad[i] = gc * o * (sd - s * src.dlog_area);
                if OCC {
                    dyv[i] = gc * s * d_o;
                }
            }
        }
        // Lane l sums the taps i with i % LANES == l (CHUNK is a multiple of LANES); the
        // last chunk's remainder goes to lanes 0, 1, ...
        let full = m / LANES * LANES;
        for base in (0..full).step_by(LANES) {
            for l in 0..LANES {
                let i = base + l;
                lanes[3][l] = lanes[3][l] + ga[i];
                if FULL {
                    lanes[0][l] = lanes[0][l] + gr[i] * so[i];
                    lanes[1][l] = lanes[1][l] + gg[i] * so[i];
                    lanes[2][l] = lanes[2][l] + gb[i] * so[i];
                    lanes[4][l] = lanes[4][l] + rad[i];
                    if OCC {
                        lanes[5][l] = lanes[5][l] + dyv[i];
                    }
                }
            }
        }
        for i in full..m {
            let l = i - full;
            lanes[3][l] = lanes[3][l] + ga[i];
            if FULL {
                lanes[0][l] = lanes[0][l] + gr[i] * so[i];
                lanes[1][l] = lanes[1][l] + gg[i] * so[i];
                lanes[2][l] = lanes[2][l] + gb[i] * so[i];
                lanes[4][l] = lanes[4][l] + rad[i];
                if OCC {
                    lanes[5][l] = lanes[5][l] + dyv[i];
                }
            }
        }
        start += m;
    }
    lanes.map(|l| lane_sum(&l))
}

/// [`source_run`] for kernel apertures (the model's scalar scatter term). `g0` is the
/// first tap's column in the flipped tables, `t` their row.
fn source_run_kernel<T: Real>(
    ctx: &Ctx<'_, T>,
    i0: usize,
    n: usize,
    (g0, t): (usize, usize),
    src: SourceTerms<T>,
    full: bool,
) -> [T; 6] {
    let (rcv, tables) = (ctx.rcv, ctx.tables);
    let big_r = tables.big_r as isize;
    let mut acc = [T::zero(); 6];
    for j in 0..n {
        let i = i0 + j;
        // Receiver offset x - y = (ddx, ddy); the tap offset is y - x.
        let (ddx, ddy) = ((g0 + j) as isize - big_r, t as isize - big_r);
        let (dx, dy) = (-ddx, -ddy);
        let (tr, tc) = ((dy + big_r) as usize, (dx + big_r) as usize);
        let (s, sd) = model::scatter_term_with_derivative(
            src.step,
            ctx.aperture,
            dx,
            dy,
            T::c(tables.dist[tr][tc]),
            tables.gauge[tr][tc],
            src.radius,
        );
        let e = rcv.focus_weight[i];
        let (o, d_o) = if e > T::zero() {
            let ds = model::depth_step_fast(src.rel_disp - rcv.rel_disp[i]);
            (
                T::one() + e * (ds - T::one()),
                e * model::depth_step_derivative_from_value(ds),
            )
        } else {
            (T::one(), T::zero())
        };
        let so = s * o;
        let gc = rcv.g_red[i] * src.lin[0]
            + rcv.g_green[i] * src.lin[1]
            + rcv.g_blue[i] * src.lin[2]
            + rcv.g_weight[i];
        acc[3] = acc[3] + gc * so;
        if full {
            acc[0] = acc[0] + rcv.g_red[i] * so;
            acc[1] = acc[1] + rcv.g_green[i] * so;
            acc[2] = acc[2] + rcv.g_blue[i] * so;
            acc[4] = acc[4] + gc * o * (sd - s * src.dlog_area);
            acc[5] = acc[5] + gc * s * d_o;
        }
    }
    acc
}

// ---------------------------------------------------------------------------------------
// Pass C: the coverage's gradient to alpha.
// ---------------------------------------------------------------------------------------

/// Adds each padded pixel's value onto the image pixel it mirrors, in padded order.
fn fold<T: Real>(src: &Sources<T>, padded: Vec<T>, pixels: usize) -> Vec<T> {
    let mut out = vec![T::zero(); pixels];
    for (p, v) in padded.into_iter().enumerate() {
        let s = src.source[p];
        out[s] = out[s] + v;
    }
    out
}

/// Paper box coverage `o(x) = mean of alpha over the box of half-size h(x)`: each padded
/// pixel y gathers `dL/do(x) / n(x)` from the receivers whose box holds it, i.e. the
/// receivers with `h(x) = h` in the box of half-size `h` around y, for each `h` that occurs:
/// one summed-area table (f64) per distinct half-size.
fn pass_coverage_box<T: Real>(ctx: &Ctx<'_, T>) -> Vec<T> {
    let (src, rcv) = (ctx.src, ctx.rcv);
    let (w, h, pad, stride) = (rcv.width, rcv.height, src.pad, src.stride);
    let big_r = ctx.tables.big_r;
    let half: Vec<usize> = rcv
        .radius
        .iter()
        .map(|&r| model::coverage_half_size_px(r, big_r))
        .collect();
    let mut sizes: Vec<usize> = half.clone();
    sizes.sort_unstable();
    sizes.dedup();
    let s1 = w + 1;
    let mut padded = vec![0.0f64; src.rows * stride];
    for &hs in &sizes {
        let n = ((2 * hs + 1) * (2 * hs + 1)) as f64;
        // SAT over the image receivers of share(x) where h(x) == hs.
        let mut sat = vec![0.0f64; (h + 1) * s1];
        for y in 0..h {
            let mut run = 0.0;
            for x in 0..w {
                let i = y * w + x;
                if half[i] == hs {
                    run += rcv.g_coverage[i].f64() / n;
                }
                sat[(y + 1) * s1 + x + 1] = sat[y * s1 + x + 1] + run;
            }
        }
        let hs = hs as isize;
        padded
            .par_chunks_mut(stride)
            .enumerate()
            .for_each(|(py, row)| {
                // Receivers (image coords) within the box around y, clipped to the image.
                let y = py as isize - pad as isize;
                let (r0, r1) = ((y - hs).max(0), (y + hs + 1).min(h as isize));
                if r0 >= r1 {
                    return;
                }
                for (px, v) in row.iter_mut().enumerate() {
                    let x = px as isize - pad as isize;
                    let (c0, c1) = ((x - hs).max(0), (x + hs + 1).min(w as isize));
                    if c0 >= c1 {
                        continue;
                    }
                    let (r0, r1, c0, c1) = (r0 as usize, r1 as usize, c0 as usize, c1 as usize);
                    *v += sat[r1 * s1 + c1] - sat[r0 * s1 + c1] - sat[r1 * s1 + c0]
                        + sat[r0 * s1 + c0];
                }
            });
    }
    fold(src, padded.into_iter().map(T::c).collect(), w * h)
}

/// Soft-disc coverage `o(x) = sum_y S(r_c(x), y) a(y) / Z(x)`: each padded pixel y gathers
/// `dL/do(x) S(r_c(x), y) / Z(x)` from the receivers whose reach `r_c(x) + tail` holds it.
fn pass_coverage_disc<T: Real>(ctx: &Ctx<'_, T>, share: &[T]) -> Vec<T> {
    let (src, rcv) = (ctx.src, ctx.rcv);
    let opts = ctx.settings.model();
    let footprint = T::c(opts.footprint.px());
    let rc: Vec<T> = rcv
        .radius
        .iter()
        .map(|&r| model::coverage_radius_px(r, opts.coverage_radius, footprint).0)
        .collect();
    // Per block of ROW_BLOCK image rows and per image column, the largest r_c.
    let (w, h) = (rcv.width, rcv.height);
    let blocks = h.div_ceil(ROW_BLOCK);
    let block_max: Vec<f64> = (0..blocks * w)
        .map(|bi| {
            let (b, x) = (bi / w, bi % w);
            (b * ROW_BLOCK..((b + 1) * ROW_BLOCK).min(h))
                .map(|y| rc[y * w + x].f64())
                .fold(f64::NEG_INFINITY, f64::max)
        })
        .collect();
    let rows: Vec<Vec<T>> = (0..src.rows)
        .step_by(TILE_ROWS)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|y0| disc_tile_row_dispatch(ctx, &rc, share, &block_max, y0))
        .collect();
    fold(src, rows.into_iter().flatten().collect(), w * h)
}

avx2_dispatch!(
    disc_tile_row_dispatch,
    disc_tile_row_avx2,
    disc_tile_row,
    (ctx: &Ctx<'_, T>, rc: &[T], share: &[T], block_max: &[f64], y0: usize) -> Vec<T>
);

/// Pass C (soft disc) over the padded source rows `y0 .. y0 + TILE_ROWS`, tile by tile.
#[inline(always)]
fn disc_tile_row<T: Real>(
    ctx: &Ctx<'_, T>,
    rc: &[T],
    share: &[T],
    block_max: &[f64],
    y0: usize,
) -> Vec<T> {
    let (src, rcv, tables) = (ctx.src, ctx.rcv, ctx.tables);
    let (stride, big_r, pad) = (src.stride, tables.big_r, src.pad);
    let (w, h) = (rcv.width, rcv.height);
    let y1 = (y0 + TILE_ROWS).min(src.rows);
    let mut out = vec![T::zero(); (y1 - y0) * stride];
    for x0 in (0..stride).step_by(TILE) {
        let x1 = (x0 + TILE).min(stride);
        // Receivers (image coords) within R of the tile.
        let qy0 = (y0 as isize - (pad + big_r) as isize).max(0) as usize;
        let qy1 = ((y1 + big_r) as isize - pad as isize).clamp(0, h as isize) as usize;
        let qx0 = (x0 as isize - (pad + big_r) as isize).max(0) as usize;
        let qx1 = ((x1 + big_r) as isize - pad as isize).clamp(0, w as isize) as usize;
        if qy0 >= qy1 || qx0 >= qx1 {
            continue;
        }
        let mut max_rc = f64::NEG_INFINITY;
        for b in qy0 / ROW_BLOCK..=(qy1 - 1) / ROW_BLOCK {
            for &m in &block_max[b * w + qx0..b * w + qx1] {
                max_rc = max_rc.max(m);
            }
        }
        let reach = backward_reach(ctx.aperture, max_rc);
        let widths: Vec<Option<usize>> = (-(big_r as isize)..=big_r as isize)
            .map(|dy| tables.half_width(dy, reach))
            .collect();
        for py in y0..y1 {
            for px in x0..x1 {
                let mut acc = T::zero();
                for ddy in -(big_r as isize)..=big_r as isize {
                    let t = (ddy + big_r as isize) as usize;
                    let Some(hw) = widths[t] else {
                        continue;
                    };
                    let qy = py as isize + ddy - pad as isize;
                    if qy < 0 || qy >= h as isize {
                        continue;
                    }
                    let x = px as isize - pad as isize;
                    let lo = (x - hw as isize).max(0);
                    let hi = (x + hw as isize).min(w as isize - 1);
                    if lo > hi {
                        continue;
                    }
                    let i0 = qy as usize * w + lo as usize;
                    let n = (hi - lo + 1) as usize;
                    let g0 = (lo - x + big_r as isize) as usize;
                    acc = acc
                        + match ctx.aperture {
                            ApertureEval::Gauge => disc_run(
                                src.step,
                                &rc[i0..i0 + n],
                                &share[i0..i0 + n],
                                &ctx.gauge_flip[t][g0..g0 + n],
                            ),
                            ApertureEval::Kernel(..) => {
                                let mut a = T::zero();
                                for j in 0..n {
                                    let (ddx, ddy) = ((g0 + j) as isize - big_r as isize, ddy);
                                    let (dx, dy) = (-ddx, -ddy);
                                    let (tr, tc) = (
                                        (dy + big_r as isize) as usize,
                                        (dx + big_r as isize) as usize,
                                    );
                                    let s = model::scatter_term(
                                        src.step,
                                        ctx.aperture,
                                        dx,
                                        dy,
                                        T::c(tables.dist[tr][tc]),
                                        tables.gauge[tr][tc],
                                        rc[i0 + j],
                                    );
                                    a = a + share[i0 + j] * s;
                                }
                                a
                            }
                        };
                }
                out[(py - y0) * stride + px] = acc;
            }
        }
    }
    out
}

/// `sum share(x) S(r_c(x) - gauge)` over one run of receivers, in lanes.
#[inline(always)]
fn disc_run<T: Real>(step: ScatterStep, rc: &[T], share: &[T], gauge: &[T]) -> T {
    let n = gauge.len();
    let mut lanes = [T::zero(); LANES];
    let full = n / LANES * LANES;
    for base in (0..full).step_by(LANES) {
        for l in 0..LANES {
            let i = base + l;
            lanes[l] = lanes[l] + share[i] * model::scatter_step_fast(step, rc[i] - gauge[i]);
        }
    }
    for i in full..n {
        lanes[i - full] =
            lanes[i - full] + share[i] * model::scatter_step_fast(step, rc[i] - gauge[i]);
    }
    lane_sum(&lanes)
}
