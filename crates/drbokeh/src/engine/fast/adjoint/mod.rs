//! The adjoint on the fast engine's schedule (`render_with_tape_on(.., Engine::Fast, ..)`):
//! forward with tape and backward, visiting only the source-receiver pairs that can matter.
//! Same chain rule and model functions as the exact adjoint (`engine/threaded/adjoint.rs`, around the shared driver `engine/backward.rs`), same
//! gather formulation: every output element is computed by one task in a fixed order, so
//! results are identical bytes for any thread count (no atomics).
//!
//! **Forward with tape.** The fast engine's render (`fast/forward.rs`, `render_recording`), bit for bit
//! the output of `render(.., Engine::Fast, ..)`, which also records per layer and pixel
//! the sums `W`, `B = C / (W + 1e-8)` and `o`. The recorded `W` and `C` also hold the ring
//! of taps out to the backward's longer reach (below), summed apart from the rendered ones.
//!
//! **Reach.** A tap `y -> x` matters only when `dist < r + tail`, with `r` the radius of
//! the soft step it evaluates: `r(y)` for the scatter term, the receiver's `r_c(x)` for the
//! soft-disc coverage. The backward keeps `tail = 4.5 + 1.5 = 6` px
//! (`BACKWARD_EXTRA_TAIL_PX`; the render's [`crate::model::SCATTER_TAIL_PX`] plus 1.5): gradient
//! sums cancel (`sum_y c(y,x) (Ilin(y) - B(x)) = 0`), so a tail is relatively larger in
//! them than in the render; at 6 px the dropped mass is `e^{-4.5} = 1/90` of the render's.
//! Zero-alpha sources are *not* skipped where their gradient is needed: `dc/da = S O / r^2`
//! does not vanish with alpha, and neither does the soft disc's `do/da = S / Z`.
//!
//! **Refinements before the chain rule** (per layer, receivers x):
//! - the soft-disc coverage is summed again over the backward's reach, with its
//!   derivative `do/dr(x)` and weight `Z(x)` (used by passes A and C), and replaces the
//!   recorded `o`;
//! - where the recorded `W(x) < 1e-2` ([`refine::REFINE_WEIGHT_BELOW`]) and the receiver's window
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
//! `R` of its disc), and the rest (compositing backward, pass A, box coverage by
//! summed-area tables, folds) a few percent. Pass B is the backward: about 600 taps per
//! padded source for both layers (zero-alpha sources included, for their alpha gradient),
//! each one `exp` (two where a receiver is in focus) and about 20 flops. Measured in the
//! same runs: forward 1.0 s, backward 2.2-2.5 s (load average 4-6), 2.1-2.4x the
//! forward; the exact threaded backward took 296 s (load average about 8; 62 s quoted on
//! an idle machine in issue 6).

mod context;
mod coverage;
mod receivers;
mod refine;
mod sources;
pub(in crate::engine) use refine::REFINE_WEIGHT_BELOW;
pub(in crate::engine) use sources::{gather_source_terms, pass_sources, SourceTerms};

use crate::engine::backward::{self, LayerPartials};
use crate::engine::fast::forward::render_recording;
use crate::engine::fast::runs::{disc_sums, LaneReduction};
use crate::engine::fast::tiles::{backward_reach, WindowTables};
use crate::engine::planes::Planes;
use crate::engine::tape::{Backward, Gradients};
use crate::image::Image;
use crate::model::{self, ApertureEval, Coverage, DiscCoverage, LayerAtPixel, PreparedLayer};
use crate::presets::RenderSettings;
use crate::progress::Progress;
use crate::stack::LayerStack;
use crate::{Real, Result};
pub(in crate::engine) use context::Ctx;
pub(in crate::engine) use context::Receivers;
use rayon::prelude::*;
use std::borrow::Cow;

/// The fast schedule's tape: the inputs, and per layer and pixel the sums the fast forward
/// composited.
pub(crate) struct FastTape<T> {
    settings: RenderSettings,
    stack: LayerStack<T>,
    /// Per layer, per pixel (sums out to the backward's reach).
    pub(in crate::engine) saved: Vec<Vec<LayerAtPixel<T>>>,
}

/// Renders with the fast engine (identical bytes to `render(.., Engine::Fast, ..)`) and
/// records the tape. The caller has validated the inputs and started `progress`.
pub(crate) fn render_with_tape<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> (Image<T>, FastTape<T>) {
    let (img, _, rec) = render_recording(stack, settings, progress, true);
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

/// The backward's per-layer state: the window tables, the padded planes of every layer,
/// their prepared terms and the soft-disc coverage sums.
struct State<T> {
    tables: WindowTables<T>,
    gauge_flip: Vec<Vec<T>>,
    aperture: ApertureEval<T>,
    prepared: Vec<PreparedLayer<T>>,
    sources: Vec<Planes<T>>,
    discs: Vec<Vec<DiscCoverage<T>>>,
}

impl<T: Real> Backward<T> for FastTape<T> {
    /// Back-propagates `grad_output` on the fast schedule. Deterministic for any thread
    /// count: every output element is computed by one task, in a fixed order.
    fn backward(&self, grad_output: &Image<T>, progress: &dyn Progress) -> Result<Gradients<T>> {
        backward_with(
            &self.stack,
            &self.settings,
            &self.saved,
            grad_output,
            progress,
            |ctx, _| sources::pass_sources(ctx),
            None,
        )
    }
}

/// The gradients of pass B over one layer: per image pixel `dL/dIlin`, `dL/da` (scatter
/// part), `dL/dd` (source part), and K's total.
pub(in crate::engine) type SourceGradients<T> = (Vec<[T; 3]>, Vec<T>, Vec<T>, f64);

/// The fast adjoint's backward around a pass B of the caller's choice
/// (`pass_sources(ctx, layer)`): the fast schedule's own ([`sources::pass_sources`]) or
/// the span engine's. `saved` holds per layer and pixel the sums the forward composited.
pub(in crate::engine) fn backward_with<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    saved: &[Vec<LayerAtPixel<T>>],
    grad_output: &Image<T>,
    progress: &dyn Progress,
    pass_sources: impl Fn(&Ctx<'_, T>, usize) -> SourceGradients<T>,
    soft_disc: Option<&SoftDiscHooks<'_, T>>,
) -> Result<Gradients<T>> {
    let (w, h) = (stack.width, stack.height);
    let n_layers = stack.layers.len();
    let options = settings.model();
    let k = T::c(settings.camera.blur_k);
    backward::run(
        stack,
        settings,
        grad_output,
        progress,
        || prepare(stack, settings, soft_disc.map(|h| h.sums)),
        |state| {
            // The soft disc's recomputed coverage replaces the recorded one (the box's
            // recorded sums are used as they are).
            let saved: Vec<Cow<'_, [LayerAtPixel<T>]>> = saved
                .iter()
                .zip(&state.discs)
                .map(|(saved, discs)| {
                    if discs.is_empty() {
                        return Cow::Borrowed(&saved[..]);
                    }
                    Cow::Owned(
                        saved
                            .par_iter()
                            .zip(discs)
                            .map(|(s, d)| LayerAtPixel {
                                coverage: d.value(),
                                ..*s
                            })
                            .collect(),
                    )
                })
                .collect();
            // Receivers whose weight sum is of the order of the dropped tail: their
            // layer colour B = C / (W + 1e-8) is set by the tail (the output hides it,
            // o(x) ~ 0 there, but dL/do does not), so C and W are summed again over
            // the whole window.
            let saved: Vec<Vec<LayerAtPixel<T>>> = saved
                .iter()
                .zip(&state.sources)
                .map(|(saved, src)| {
                    refine::refine_small_weights(
                        saved,
                        src,
                        &state.tables,
                        &state.aperture,
                        settings,
                    )
                })
                .collect();
            // The composite of the refined sums: the display transfer's derivative is
            // steep for dark pixels, and evaluating it at the rendered value would pass
            // the render's own tail error (<= 1e-5) on to every gradient through the
            // transfer's curvature.
            let linear: Vec<[T; 3]> = (0..w * h)
                .into_par_iter()
                .map(|i| {
                    model::composite(
                        (0..n_layers).map(|l| (saved[l][i].colour, saved[l][i].coverage)),
                    )
                })
                .collect();
            (move |i: usize, l: usize| saved[l][i], Cow::Owned(linear))
        },
        |state, l, rg, progress| {
            let rcv = Receivers::new(&state.prepared[l], rg);
            let ctx = Ctx {
                settings,
                tables: &state.tables,
                gauge_flip: &state.gauge_flip,
                aperture: &state.aperture,
                src: &state.sources[l],
                rcv: &rcv,
                discs: &state.discs[l],
                k,
            };
            let (g_disp_receiver, share, k_a) = receivers::pass_receivers(&ctx);
            progress.advance(1);
            let (g_lin, g_alpha_scatter, g_disp_source, k_b) = pass_sources(&ctx, l);
            progress.advance(1);
            let g_alpha_coverage = match options.coverage {
                Coverage::PaperBox => coverage::pass_coverage_box(&ctx),
                Coverage::SoftDisc => match soft_disc {
                    Some(h) => (h.pass_coverage)(&ctx, &share),
                    None => coverage::pass_coverage_disc(&ctx, &share),
                },
            };
            progress.advance(1);
            LayerPartials {
                g_lin,
                g_alpha_scatter,
                g_alpha_coverage,
                g_disp_receiver,
                g_disp_source,
                blur_k: (k_a, k_b),
            }
        },
    )
}

/// Another schedule's soft-disc coverage (the span adjoint's): every receiver's sums
/// with derivatives from a layer's padded planes, and pass C (per image pixel, folded).
pub(in crate::engine) struct SoftDiscHooks<'a, T> {
    pub sums: &'a DiscSumsFn<'a, T>,
    pub pass_coverage: &'a PassCoverageFn<'a, T>,
}

/// Every receiver's soft-disc sums with derivatives from a layer's padded planes.
pub(in crate::engine) type DiscSumsFn<'a, T> =
    dyn Fn(&Planes<T>) -> Vec<DiscCoverage<T>> + Sync + 'a;

/// Pass C of the soft disc: per image pixel, from `dL/do / Z` per receiver.
pub(in crate::engine) type PassCoverageFn<'a, T> = dyn Fn(&Ctx<'_, T>, &[T]) -> Vec<T> + Sync + 'a;

/// The window tables, every layer's prepared terms and padded planes, and (soft disc)
/// the coverage with its derivative over the backward's longer reach: its value
/// replaces the recorded one (whose shorter tail weighs up to 1.5e-5 of Z at
/// r_c ~ 0), so that o and do/dr come from the same sums.
fn prepare<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    disc_sums_with: Option<&DiscSumsFn<'_, T>>,
) -> State<T> {
    let options = settings.model();
    let (w, h) = (stack.width, stack.height);
    let tables = WindowTables::<T>::new(settings);
    let big_r = tables.big_r;
    let aperture = ApertureEval::<T>::new(&settings.aperture);
    let prepared: Vec<PreparedLayer<T>> = stack
        .layers
        .iter()
        .map(|l| model::prepare_layer(l, &settings.camera, &options))
        .collect();
    let sources: Vec<Planes<T>> = prepared
        .iter()
        .map(|p| Planes::padded(p, big_r, options.step))
        .collect();
    let footprint = T::c(options.footprint.px());
    let discs: Vec<Vec<DiscCoverage<T>>> = sources
        .iter()
        .map(|src| {
            if options.coverage != Coverage::SoftDisc {
                return Vec::new();
            }
            if let Some(f) = disc_sums_with {
                return f(src);
            }
            (0..w * h)
                .into_par_iter()
                .map(|i| {
                    let xi = src.index(i % w, i / w);
                    let r_c = model::coverage_radius_px(
                        src.radius[xi],
                        options.coverage_radius,
                        footprint,
                    );
                    let reach = backward_reach(&aperture, r_c.0.f64());
                    disc_sums::<T, true>(
                        src,
                        &tables,
                        &aperture,
                        xi,
                        r_c,
                        reach,
                        LaneReduction::Total,
                    )
                    .0
                })
                .collect()
        })
        .collect();
    let gauge_flip = tables.flipped_gauge();
    State {
        tables,
        gauge_flip,
        aperture,
        prepared,
        sources,
        discs,
    }
}
