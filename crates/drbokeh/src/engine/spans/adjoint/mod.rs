//! The span engine's adjoint (`render_with_tape_on(.., Engine::Spans | Engine::Auto, ..)`):
//! the forward is the span render (`render(.., Engine::Spans | Engine::Auto, ..)`, bit for
//! bit), recording per layer and pixel `W`, `B`, `o` and, per layer and row, whether the
//! row's band-layer took spans or taps; the backward is the fast adjoint's chain rule
//! (`engine/fast/adjoint/`: tone, compositing, refinement of small weights, pass A over
//! in-focus receivers, pass C through the coverage) around a span-structured pass B.
//!
//! **Pass B as spans** ([`sources`]). Per source `y` the fast adjoint sums, over the
//! receivers `x` of its disc, `gC(x) S O`, `gc(x) S O`, `gc(x) O (S' - S A'/A)` and
//! `gc(x) S dO/dd(y)` with `gc = gC . Ilin(y) + gW`. This is the transpose of the span
//! scatter: on a receiver row whose band-layer the forward rendered as spans, the disc row's
//! interior (where the forward took `S = 1`) is read from row prefix sums of the receivers'
//! `gC` and `gW` (a difference of two prefix values per component; `S' = 0` there, as in
//! the forward), the ring (the forward's, to `r + u_out`) in the fast adjoint's 8-lane runs
//! with the exact `S` and `S'`, receivers with a small recorded weight (`W < 1e-2`) out to
//! `r + 6` tap by tap, and the receivers whose
//! occlusion term is evaluated (`e(x) >= 1e-9`) get the exact `O` as a correction on top of
//! `O = 1`, one by one (a prefix count per row finds them). Rows whose band-layer took the
//! tap path are summed over every tap within the fast adjoint's reach (`r + 6`), as the
//! fast adjoint does. Kernel apertures: the fast adjoint's pass B.
//!
//! **Bounds** (relative to the sums of the exact adjoint over the same taps; tested at
//! their worst case in `tests/spans_adjoint.rs`):
//! 1. Interior `S := 1`, `S' := 0` (the forward's approximation, differentiated): every
//!    interior term errs by at most `INTERIOR_DEFECT = 1e-5` of itself (`1 - S <= 1e-5`);
//!    the dropped `S'` of the interior integrates along each ray to `1 - S(u_in) <= 1e-5`
//!    of the ring's `int S' du = 1`, so the radius gradient errs by at most `1e-5` of its
//!    ring sum (with the same upstream factors).
//! 2. Tail beyond `r + u_out` dropped (the forward's ring): `S <= 1.4e-7` per tap (paper),
//!    `6.8e-8` (sharp), and `S' <= 3 S`, `6 S`: at most `4.2e-7` of a unit-weight tap.
//! 3. Occlusion: the exact `O` wherever the fast adjoint evaluates it (`e >= 1e-9`);
//!    the forward's in-focus interpolation (error `<= 1e-6` per tap in `O`) is not
//!    differentiated, so the backward is the exact one's within `1e-6` there.
//!
//! **Recorded sums** (both steps). The span render's sharp ring ends at `r + 2.3`
//! ([`Rings::forward`](super::geometry::Rings::forward), `S <= 1.01e-6` per tap), the paper
//! ring at `r + 4.5`; the backward reaches `r + 6`.
//! The render cannot see the difference, but the chain rule can: the display transfer's
//! derivative is evaluated at the composite of the recorded sums, and for a dark channel
//! of a layer colour (`B ~ 1e-6`, the back layer's black stripes in the "blobs" scene of
//! `tests/spans_adjoint.rs`) the dropped tail is about 1 % of `B`; `gamma`'s
//! `d/dx x^(1/g - 1)` has relative sensitivity `1 - 1/g = 0.55`, so `dL/dlinear` was
//! 0.5 % off there, and the front layer's `dL/dC = o / (W + 1e-8)`, large at its edge,
//! carried that into the coverage share and the alpha gradient: 1.8e-2 of its largest
//! value (measured; every recorded `W`, `B`, `o` of the two tapes agreed after the
//! refinement of small weights to within 1e-6, except for that tail). So the tape's sums
//! come from a second span forward whose rings reach `r + 6`
//! ([`super::render_recording_to`]; its output is discarded, the tape's output is the
//! span render): O(r) per source like the forward, where this used to be a fast (O(r^2))
//! forward. The paper step's `r + 4.5` tail does the same on a smaller scale: with its own
//! record the mixed spans/taps scene of `tests/spans_adjoint.rs` was 2.8e-4 off (layer-0
//! alpha), with the `r + 6` record 4.2e-5; it costs paper's `vjp` one more span forward
//! (a render is about 15 % of its CPU at 512 px K 30). The soft disc's
//! own sums and its pass C are spans ([`disc`]: O(r) per receiver).
//!
//! **Speed** (`drbokeh vjp`, whole process, demo scene, f32, 2 shared cores, load 8-13,
//! CPU seconds of one run each, span adjoint / fast adjoint): 512 px K 30 paper 3.7 / 5.6,
//! physical 15.5 / 18.2; 512 px K 60 paper 10.0 / 14.0, physical 38.0 / 49.9; 1 MP K 30
//! paper 14.8 / 24.5, physical 65.3 / 72.2; 1 MP K 60 paper 27.6 / 51.9. The span render
//! takes 0.5-4.3 s of CPU on the same workloads, so the backward is still 5-30x its forward
//! (issue 18's target is 3x). Those physical figures include a second (fast) forward, now
//! a second span forward ("Recorded sums"): 512 px K 30 physical `vjp` 16.7 -> 10.6 s of
//! CPU (load 15, same run, one run each). The soft disc's steps by table then took it to
//! 5.8-6.5 s at low load (from 7.5-8.8, [`disc`]). Then pass B's rings in whole 8-lane
//! chunks with lanes kept over the source (not re-reduced per run), the soft disc's rings
//! and pass C in 8-lane chunks (the circle's table now holds both signs of `dx`), and the
//! refinement of small weights as a plain AVX2 loop that reuses a row's `Z(r_c)`: 4.7-5.0
//! -> 3.3-3.5 s of user CPU (wall 5.0-5.3 -> 3.6-3.7 s, load 4, alternating runs); at
//! load 1.5, user + sys 5.3-5.4 -> 3.8-3.9 s, wall 3.0-3.1 -> 2.2 s, against the render's
//! 0.45-0.54 s CPU and 0.31-0.36 s wall; paper 3.3-3.5 -> 2.3-2.6 s CPU. Gradients stay within 4.1e-6 of the exact adjoint's largest value of each
//! kind there (before: 6.8e-6). The `vjp` was then still about 7x its render: pass B
//! cost ~100 cycles per source row of its reach (per-row bookkeeping more than taps), the
//! soft disc's sums and pass C as much again. So runs of 8 sources (receivers) of one
//! radius in adjacent columns now share their row geometry and each ring step
//! (`sources/runs.rs`; [`disc`]'s groups): 512 px K 30 physical, user CPU 2.7-3.5 ->
//! 1.5-2.1 s (load 4-4.5, alternating runs; paper 1.85-1.9 -> 1.5-1.6 s); gradients as before (within 1.4e-5 of the exact
//! adjoint's largest value of each kind). Then a circle's runs as row correlations
//! (`sources/conv.rs`), the refinement of small weights in 8-lane runs of alpha > 0, and
//! the composite's backward without per-pixel allocations: `drbokeh bench --quick --only
//! adjoint` span backward 0.71-0.87 -> 0.22-0.27 s against a 0.07 s forward (3.1-3.7x),
//! vjp 512 px K 30 physical 1.07-1.34 -> 0.94-0.97 s wall (quiet machine, alternating
//! runs; `docs/performance.md`). Then the serial steps around the passes made parallel
//! (they were a third of the backward's wall time on 2 cores) and the refinement's lanes
//! kept over the whole window: bench 2.5-2.9x its forward (medians of 5 rounds).
//!
//! The recorded sums are the forward's (`C`, `W` within `2e-5` relative, see
//! `spans/mod.rs`), so the chain rule's upstream factors carry the forward's error too; the
//! gradients agree with the exact adjoint to within a few `1e-5` of their largest value.

mod disc;
mod sources;

use super::geometry::{GaugeTable, Shape};
use super::{render_recording, render_recording_to, Choice};
use crate::engine::backward::fold_padded;
use crate::engine::fast::adjoint::{
    backward_with, pass_sources, Ctx, SoftDiscHooks, REFINE_WEIGHT_BELOW,
};
use crate::engine::fast::tiles::WindowTables;
use crate::engine::planes::Planes;
use crate::engine::tape::{Backward, Gradients};
use crate::image::Image;
use crate::model::{Coverage, LayerAtPixel};
use crate::presets::RenderSettings;
use crate::progress::{NoProgress, Progress};
use crate::stack::LayerStack;
use crate::{Real, Result};
use disc::DiscCtx;

/// The span schedule's tape: the inputs, per layer and pixel the sums the span forward
/// composited, and per layer and row the forward's choice of spans or taps.
pub(crate) struct SpanTape<T> {
    settings: RenderSettings,
    stack: LayerStack<T>,
    saved: Vec<Vec<LayerAtPixel<T>>>,
    span_rows: Vec<Vec<bool>>,
}

/// Renders with the span engine (identical bytes to `render(.., Engine::Spans or Auto, ..)`
/// for `choice`) and records the tape. The caller has validated the inputs and started
/// `progress`.
pub(crate) fn render_with_tape<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
    choice: Choice,
) -> (Image<T>, SpanTape<T>) {
    let (img, _, _) = render_recording(stack, settings, progress, choice, false);
    // The sums out to the backward's reach (see the module documentation, "Recorded
    // sums"), from a second span forward whose output is not used. Its band-layers take
    // the same spans-or-taps choice as the render's (the choice does not depend on the
    // ring), so its per-row choices are the render's too.
    let rec = render_recording_to(
        stack,
        settings,
        &NoProgress,
        choice,
        true,
        Some(sources::TAP_ROW_TAIL_PX),
    )
    .2
    .unwrap_or_else(|| unreachable!("render_recording_to records when asked"));
    (
        img,
        SpanTape {
            settings: settings.clone(),
            stack: stack.clone(),
            saved: rec.saved,
            span_rows: rec.span_rows,
        },
    )
}

impl<T: Real> Backward<T> for SpanTape<T> {
    /// Back-propagates `grad_output`: pass B as spans on the rows the forward rendered as
    /// spans, as taps elsewhere. Deterministic for any thread count (every output element is
    /// computed by one task, in a fixed order).
    fn backward(&self, grad_output: &Image<T>, progress: &dyn Progress) -> Result<Gradients<T>> {
        let settings = &self.settings;
        let shape = Shape::of(&settings.aperture);
        let big_r = WindowTables::<T>::new(settings).big_r;
        let table = shape
            .as_ref()
            .map(|_| GaugeTable::<T>::new(&settings.aperture, big_r, -1));
        // Tail receivers of pass B (`sources.rs`): recorded weight sums below the
        // refinement threshold.
        let tail: Vec<Vec<bool>> = self
            .saved
            .iter()
            .map(|s| {
                s.iter()
                    .map(|p| p.weight.f64() < REFINE_WEIGHT_BELOW)
                    .collect()
            })
            .collect();
        // The soft disc as spans (circle and polygon apertures).
        let options = settings.model();
        let (w, h) = (self.stack.width, self.stack.height);
        let gather = shape
            .as_ref()
            .filter(|_| options.coverage == Coverage::SoftDisc)
            .map(|shape| (shape, GaugeTable::<T>::new(&settings.aperture, big_r, 1)));
        let coverage_radius = (options.coverage_radius, options.footprint.px());
        let sums = |src: &Planes<T>| {
            let (shape, table) = gather.as_ref().expect("hooks only with a gather table");
            disc::disc_sums(&DiscCtx::new(src, shape, table, (w, h), coverage_radius))
        };
        let pass_coverage = |ctx: &Ctx<'_, T>, share: &[T]| {
            let (shape, table) = gather.as_ref().expect("hooks only with a gather table");
            let dc = DiscCtx::new(ctx.src, shape, table, (w, h), coverage_radius);
            let padded = disc::pass_coverage(&dc, share);
            fold_padded(
                &ctx.src.source,
                padded.into_iter().map(T::c).collect(),
                w * h,
            )
        };
        let hooks = SoftDiscHooks {
            sums: &sums,
            pass_coverage: &pass_coverage,
        };
        backward_with(
            &self.stack,
            settings,
            &self.saved,
            grad_output,
            progress,
            |ctx, l| match (&shape, &table) {
                (Some(shape), Some(table)) if self.span_rows[l].iter().any(|&s| s) => {
                    sources::pass_sources(ctx, shape, table, &self.span_rows[l], &tail[l])
                }
                _ => pass_sources(ctx),
            },
            gather.as_ref().map(|_| &hooks),
        )
    }
}
