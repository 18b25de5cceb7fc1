//! Schedules that evaluate the model ([`crate::model`]): each evaluates exactly the model's
//! functions and differs only in which taps it visits and in what order. The reference
//! engine is the oracle; every other schedule is tested against it.
//!
//! | schedule | forward | adjoint |
//! | --- | --- | --- |
//! | [`Engine::Reference`] | `reference.rs` (plain loops) | the threaded adjoint |
//! | [`Engine::Threaded`] | `threaded/forward.rs` | `threaded/adjoint.rs` (exact, every window tap) |
//! | [`Engine::Fast`] | `fast/forward.rs` (bands, tiles, reach, lanes) | `fast/adjoint/` (same schedule) |
//! | [`Engine::Spans`], [`Engine::Auto`] | `spans/` (row spans, per band-layer choice of spans or the fast taps) | `spans/adjoint/` (span gathers where the forward used spans, the fast adjoint's taps elsewhere) |
//!
//! Shared by the schedules: `planes.rs` (the padded struct-of-arrays planes), `tape.rs`
//! (what the forward records, the gradients), `backward.rs` (the chain rule around each
//! schedule's passes), `simd.rs` (the AVX2 dispatch). This file is the one dispatch from
//! [`Engine`] to a schedule.

mod backward;
mod fast;
mod longest_first;
pub mod paths;
mod planes;
mod reference;
mod schedule;
pub mod simd;
mod spans;
mod summed_area;
mod tape;
mod threaded;

pub use crate::progress::{NoProgress, Progress};
pub use schedule::Engine;
pub use tape::{Gradients, LayerGradients, Tape};

use crate::image::Image;
use crate::presets::RenderSettings;
use crate::stack::LayerStack;
use crate::{Real, Result};

/// Counters of one render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RenderStats {
    /// Source-receiver pairs visited: every masked window tap of every pixel and layer for
    /// the reference and threaded engines, the taps inside each tile's reach for the fast
    /// engine; for the span engine, its tap path's taps plus its span path's work (ring
    /// taps and span writes).
    pub taps: u64,
    /// Span engine: band-layers rendered as spans.
    pub span_layers: u64,
    /// Span engine: band-layers rendered on the tap path.
    pub tap_layers: u64,
}

/// Renders a layer stack: returns the display-encoded RGB image (3 channels).
pub fn render<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    engine: Engine,
    progress: &dyn Progress,
) -> Result<Image<T>> {
    Ok(render_with_stats(stack, settings, engine, progress)?.0)
}

/// [`render`], also returning [`RenderStats`].
pub fn render_with_stats<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    engine: Engine,
    progress: &dyn Progress,
) -> Result<(Image<T>, RenderStats)> {
    stack.validate()?;
    settings.validate()?;
    progress.start(stack.height as u64);
    let window_taps = || {
        let per_pixel =
            crate::model::window_taps(settings.camera.window.radius_px(), &settings.aperture).len();
        (per_pixel * stack.width * stack.height * stack.layers.len()) as u64
    };
    Ok(match engine {
        Engine::Reference => (
            reference::render(stack, settings, progress),
            RenderStats {
                taps: window_taps(),
                ..RenderStats::default()
            },
        ),
        Engine::Threaded => (
            threaded::forward::render(stack, settings, progress),
            RenderStats {
                taps: window_taps(),
                ..RenderStats::default()
            },
        ),
        Engine::Fast => {
            let (img, taps) = fast::forward::render(stack, settings, progress);
            (
                img,
                RenderStats {
                    taps,
                    ..RenderStats::default()
                },
            )
        }
        Engine::Spans | Engine::Auto => {
            let choice = if engine == Engine::Spans {
                spans::Choice::Spans
            } else {
                spans::Choice::Auto
            };
            let (img, s) = spans::render(stack, settings, progress, choice);
            (
                img,
                RenderStats {
                    taps: s.taps + s.span_work,
                    span_layers: s.span_layers,
                    tap_layers: s.tap_layers,
                },
            )
        }
    })
}

/// Renders like [`render`] with the threaded engine (bit-identical output) and records
/// what [`Tape::backward`] needs: the exact adjoint, every window tap
/// (`render_with_tape_on(.., Engine::Threaded, ..)`).
pub fn render_with_tape<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<(Image<T>, Tape<T>)> {
    render_with_tape_on(stack, settings, Engine::Threaded, progress)
}

/// Renders with the chosen engine and records what [`Tape::backward`] needs.
///
/// - [`Engine::Reference`] and [`Engine::Threaded`]: the exact adjoint on the threaded
///   schedule (every window tap); the output is the threaded render, bit for bit.
/// - [`Engine::Fast`]: forward and backward on the fast engine's schedule (tiles bounded by
///   the blur radii that reach them, the soft step's tail beyond `r + 4.5` px dropped; see
///   `engine/fast/adjoint/`); the output is `render(.., Engine::Fast, ..)`, bit for bit,
///   and the gradients agree with the exact adjoint to about 1e-6 of their largest value.
/// - [`Engine::Spans`] and [`Engine::Auto`]: the span render (output `render(.., engine,
///   ..)`, bit for bit) and the span adjoint (`engine/spans/adjoint/`): the fast adjoint's
///   chain rule with its pass over sources as span gathers of prefix sums on the rows the
///   forward rendered as spans, as taps where it took the tap path, and the soft disc's
///   sums as spans; gradients within `3e-4` of the exact adjoint's largest value of each
///   kind (tested; measured `1e-5` to `3e-4`).
pub fn render_with_tape_on<T: Real>(
    stack: &LayerStack<T>,
    settings: &RenderSettings,
    engine: Engine,
    progress: &dyn Progress,
) -> Result<(Image<T>, Tape<T>)> {
    stack.validate()?;
    settings.validate()?;
    progress.start(stack.height as u64);
    Ok(match engine {
        Engine::Reference | Engine::Threaded => {
            let (img, tape) = threaded::forward::render_with_tape(stack, settings, progress);
            (img, Tape::new(settings, Engine::Threaded, Box::new(tape)))
        }
        Engine::Fast => {
            let (img, tape) = fast::adjoint::render_with_tape(stack, settings, progress);
            (img, Tape::new(settings, Engine::Fast, Box::new(tape)))
        }
        Engine::Spans | Engine::Auto => {
            let choice = if engine == Engine::Spans {
                spans::Choice::Spans
            } else {
                spans::Choice::Auto
            };
            let (img, tape) = spans::adjoint::render_with_tape(stack, settings, progress, choice);
            (img, Tape::new(settings, engine, Box::new(tape)))
        }
    })
}
