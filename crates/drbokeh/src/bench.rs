//! Standard performance workloads (`drbokeh bench`): each workload's engines measured in one
//! run (the span engine and its automatic choice against the fast engine, the fast engine
//! against the plain multi-threaded engine and the single-threaded reference where
//! affordable), with taps visited, throughput, time per pixel and the largest differences to
//! the fast engine (linear light and display-encoded); the GEGL-equivalent workload
//! ([`gegl_scene`]) and a radius sweep of the span engine.

use crate::camera::WindowCap;
use crate::demo;
use crate::engine::{render_with_stats, Engine, NoProgress};
use crate::engine::{render_with_tape_on, Gradients};
use crate::image::Image;
use crate::model;
use crate::presets::{Preset, RenderSettings};
use crate::stack::{Layer, LayerStack};
use crate::{Result, Window};
use std::time::Instant;

/// One workload: a stack and camera.
pub struct Workload {
    /// Short name, e.g. `1MP-2L-K30`.
    pub name: String,
    /// The stack (f32).
    pub stack: LayerStack<f32>,
    /// Settings (window fixed, so engines are compared on the same model).
    pub settings: RenderSettings,
    /// The engines measured, in order; differences and speed-ups are measured against the
    /// fast engine's row when it is among them.
    pub engines: Vec<Engine>,
}

/// One measured row.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BenchRow {
    /// Workload name.
    pub workload: String,
    /// Megapixels.
    pub megapixels: f64,
    /// Layers.
    pub layers: usize,
    /// Blur strength K.
    pub blur_k: f64,
    /// Window size L.
    pub window: usize,
    /// Engine measured.
    pub engine: String,
    /// Wall seconds.
    pub seconds: f64,
    /// Taps visited.
    pub taps: u64,
    /// Taps per second.
    pub taps_per_second: f64,
    /// Time of the threaded engine divided by this engine's (same run), if measured.
    pub speedup_vs_threaded: Option<f64>,
    /// Largest absolute difference to the fast engine, in linear light, if measured.
    pub max_linear_diff: Option<f64>,
    /// Largest absolute difference to the fast engine, display-encoded, if measured.
    pub max_display_diff: Option<f64>,
    /// Mean absolute difference to the fast engine, display-encoded, if measured.
    pub mean_display_diff: Option<f64>,
    /// Time of the fast engine divided by this engine's (same run), if measured.
    pub speedup_vs_fast: Option<f64>,
    /// Wall nanoseconds per pixel and layer.
    pub ns_per_pixel_layer: f64,
    /// Span engine: band-layers rendered as spans and on the tap path.
    pub span_layers: u64,
    /// Span engine: band-layers rendered on the tap path.
    pub tap_layers: u64,
    /// Summed area of the blur discs, `sum over pixels with alpha > 0 of pi (r + SCATTER_TAIL_PX)^2`:
    /// the work a radius-bounded engine must do.
    pub disc_area: f64,
}

/// Two layers: a soft-edged disc in front (disparity 0.8) of a textured background whose
/// disparity ramps from 0.1 to 0.3; focus 0.5.
pub fn two_layer(width: usize, height: usize) -> LayerStack<f32> {
    let mut front = Layer::<f32>::constant(width, height, [0.9, 0.5, 0.2], 0.0, 0.8);
    let mut back = Layer::<f32>::constant(width, height, [0.0; 3], 1.0, 0.2);
    let (cx, cy) = (width as f32 / 2.0, height as f32 / 2.0);
    let rad = width.min(height) as f32 / 4.0;
    for y in 0..height {
        for x in 0..width {
            let r = ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)).sqrt();
            *front.alpha.at_mut(x, y, 0) = (0.5 - (r - rad) / 3.0).clamp(0.0, 1.0);
            for c in 0..3 {
                *back.rgb_encoded.at_mut(x, y, c) = (((x / 16 + y / 16 + c) % 3) as f32) / 2.0;
            }
            *back.disparity.at_mut(x, y, 0) = 0.1 + 0.2 * y as f32 / height as f32;
        }
    }
    LayerStack::new(vec![front, back]).unwrap()
}

/// The worst case: one opaque layer blurred uniformly (every pixel at the same defocus).
pub fn uniform_blur(width: usize, height: usize) -> LayerStack<f32> {
    let mut l = Layer::<f32>::constant(width, height, [0.0; 3], 1.0, 0.0);
    for y in 0..height {
        for x in 0..width {
            for c in 0..3 {
                *l.rgb_encoded.at_mut(x, y, c) = (((x / 8 + y / 8 + c) % 3) as f32) / 2.0;
            }
        }
    }
    LayerStack::new(vec![l]).unwrap()
}

/// [`uniform_blur`] with every pixel's disparity jittered by up to `0.05` (deterministic):
/// at focus 0.5 and blur K, radii `K (0.5 - 0.05 u)`, `u` uniform in `[0, 1)`, so no two
/// neighbours share a radius (the sweep's worst case for the span engine, where no disc
/// profile is shared).
pub fn jittered_blur(width: usize, height: usize) -> LayerStack<f32> {
    let mut stack = uniform_blur(width, height);
    let mut rng = XorShift(0x2545_f491_4f6c_dd1d);
    for d in stack.layers[0].disparity.data.iter_mut() {
        *d = (0.05 * rng.next()) as f32;
    }
    stack
}

fn settings(focus: f64, k: f64, window: Window) -> RenderSettings {
    let mut s = RenderSettings::paper(focus);
    s.camera.blur_k = k;
    s.camera.window = window;
    s
}

/// A deterministic xorshift generator for the synthetic workloads.
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The GEGL-equivalent workload (issue 18): a photo-like image (colour gradients, hard-edged
/// shapes, small bright highlights) and a blur radius map ramping from 3 px at the top-left
/// corner to 33 px at the bottom-right, `r = 3 + 30 (x / (W-1) + y / (H-1)) / 2` (mean disc
/// `pi E[r^2]` about 1140 px^2 on any size). Returns the display-encoded RGB image and the
/// radius map in pixels.
pub fn gegl_scene(width: usize, height: usize) -> (Image<f32>, Image<f32>) {
    let mut rgb = Image::<f32>::new(width, height, 3);
    let mut radius = Image::<f32>::new(width, height, 1);
    let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
    let (fw, fh) = (width.max(2) as f64 - 1.0, height.max(2) as f64 - 1.0);
    for y in 0..height {
        for x in 0..width {
            let (u, v) = (x as f64 / fw, y as f64 / fh);
            let base = [
                0.25 + 0.5 * u,
                0.3 + 0.4 * (6.0 * v).sin().abs(),
                0.6 - 0.4 * u * v,
            ];
            // Hard-edged blocks every 96 px.
            let block = ((x / 96 + y / 96) % 3) as f64 * 0.15;
            for c in 0..3 {
                *rgb.at_mut(x, y, c) = (base[c] * (0.7 + block)).min(1.0) as f32;
            }
            *radius.at_mut(x, y, 0) = (3.0 + 30.0 * (u + v) / 2.0) as f32;
        }
    }
    // Highlights: one small bright disc per 4000 pixels.
    for _ in 0..(width * height / 4000).max(1) {
        let (cx, cy) = (rng.next() * width as f64, rng.next() * height as f64);
        let rad = 1.0 + 2.0 * rng.next();
        let (x0, x1) = (
            (cx - rad).max(0.0) as usize,
            ((cx + rad) as usize + 1).min(width),
        );
        let (y0, y1) = (
            (cy - rad).max(0.0) as usize,
            ((cy + rad) as usize + 1).min(height),
        );
        for y in y0..y1 {
            for x in x0..x1 {
                if (x as f64 - cx).powi(2) + (y as f64 - cy).powi(2) <= rad * rad {
                    for c in 0..3 {
                        *rgb.at_mut(x, y, c) = 1.0;
                    }
                }
            }
        }
    }
    (rgb, radius)
}

/// Blur strength of the GEGL-equivalent workload: focus 0 and disparity `r / 33`, so that
/// the physical preset's radius `K |d|` is the radius map (the paper's adds its 1 px
/// footprint).
pub const GEGL_BLUR_K: f64 = 33.0;

/// The GEGL-equivalent workload as a single opaque layer (disparity `r / 33`) and its
/// settings (focus 0, K 33, window just large enough).
pub fn gegl_workload(
    width: usize,
    height: usize,
    preset: Preset,
) -> (LayerStack<f32>, RenderSettings) {
    let (rgb, radius) = gegl_scene(width, height);
    let disparity = Image::from_vec(
        width,
        height,
        1,
        radius.data.iter().map(|r| r / GEGL_BLUR_K as f32).collect(),
    )
    .expect("same size");
    let stack = LayerStack::single(rgb, disparity).expect("valid stack");
    let mut s = settings(0.0, GEGL_BLUR_K, Window::auto_unclipped(GEGL_BLUR_K + 1.0));
    s.preset = preset;
    (stack, s)
}

/// The radii of the span engine's radius sweep, in pixels.
pub const SWEEP_RADII_PX: [f64; 6] = [5.0, 10.0, 25.0, 50.0, 100.0, 200.0];

/// The standard workloads; `quick` keeps only the small ones.
pub fn workloads(quick: bool) -> Vec<Workload> {
    workloads_where(quick, |_| true)
}

/// The standard workloads whose name passes `keep`; the others' stacks are never built
/// (a filter that matches nothing allocates nothing).
pub fn workloads_where(quick: bool, keep: impl Fn(&str) -> bool) -> Vec<Workload> {
    let l71 = Window::from_size(71).unwrap();
    let mut w = Vec::new();
    let mut add =
        |name: &str, make: &dyn Fn() -> (LayerStack<f32>, RenderSettings), engines: Vec<Engine>| {
            if keep(name) {
                let (stack, settings) = make();
                w.push(Workload {
                    name: name.into(),
                    stack,
                    settings,
                    engines,
                })
            }
        };
    let spans_fast = || vec![Engine::Fast, Engine::Auto, Engine::Spans];
    let with_threaded = || vec![Engine::Fast, Engine::Auto, Engine::Spans, Engine::Threaded];
    add(
        "demo-3L-K30",
        &|| {
            let demo_stack: LayerStack<f32> = demo::scene(640, 426);
            let demo_window = model::automatic_window(
                30.0,
                demo_stack.max_defocus(demo::DEMO_FOCUS),
                WindowCap::Clipped,
            );
            (demo_stack, settings(demo::DEMO_FOCUS, 30.0, demo_window))
        },
        vec![
            Engine::Fast,
            Engine::Auto,
            Engine::Spans,
            Engine::Threaded,
            Engine::Reference,
        ],
    );
    for k in [10.0, 30.0, 60.0] {
        add(
            &format!("0.25MP-2L-K{k}"),
            &|| (two_layer(512, 512), settings(0.5, k, l71)),
            with_threaded(),
        );
    }
    add(
        "0.25MP-1L-uniform-K30",
        &|| (uniform_blur(512, 512), settings(0.5, 30.0, l71)),
        with_threaded(),
    );
    add(
        "0.25MP-3L-K30",
        &|| {
            let mut three = two_layer(512, 512);
            three
                .layers
                .insert(0, Layer::constant(512, 512, [0.2, 0.8, 0.3], 0.0, 0.95));
            for y in 0..512 {
                for x in 0..512 {
                    if (x / 40 + y / 40) % 5 == 0 {
                        *three.layers[0].alpha.at_mut(x, y, 0) = 0.8;
                    }
                }
            }
            (three, settings(0.5, 30.0, l71))
        },
        with_threaded(),
    );
    // Large blur with no window limit: radius 101 px (and 201 px in the full run).
    add(
        "0.07MP-1L-radius100",
        &|| {
            (
                uniform_blur(256, 256),
                settings(
                    0.5,
                    200.0,
                    model::automatic_window(200.0, 0.5, WindowCap::Unclipped),
                ),
            )
        },
        spans_fast(),
    );
    // The GEGL-equivalent workload (issue 18), both presets.
    let gegl_size = if quick { 512 } else { 1024 };
    for preset in [Preset::Physical, Preset::Paper] {
        add(
            &format!(
                "gegl-{}MP-1L-r3..33-{}",
                if quick { "0.25" } else { "1" },
                preset.name()
            ),
            &|| gegl_workload(gegl_size, gegl_size, preset),
            spans_fast(),
        );
    }
    // Radius sweep of the span engine: one opaque layer blurred uniformly, preset physical
    // (radius K |d| exactly); the fast engine where affordable.
    let sweep_size = if quick { 256 } else { 512 };
    for r in SWEEP_RADII_PX {
        let fast_affordable = r <= if quick { 10.0 } else { 25.0 };
        add(
            &format!("sweep-{sweep_size}px-1L-r{r}"),
            &|| {
                let mut s = settings(0.5, 2.0 * r, Window::auto_unclipped(r));
                s.preset = Preset::Physical;
                (uniform_blur(sweep_size, sweep_size), s)
            },
            if fast_affordable {
                vec![Engine::Fast, Engine::Spans]
            } else {
                vec![Engine::Spans]
            },
        );
        // The same radius with every pixel's radius different (up to 10% smaller).
        add(
            &format!("sweep-{sweep_size}px-1L-r{r}-jittered"),
            &|| {
                let mut s = settings(0.5, 2.0 * r, Window::auto_unclipped(r));
                s.preset = Preset::Physical;
                (jittered_blur(sweep_size, sweep_size), s)
            },
            vec![Engine::Spans],
        );
        if quick && r >= 50.0 {
            break;
        }
    }
    if !quick {
        add(
            "1MP-2L-K30-L71 (paper defaults)",
            &|| (two_layer(1024, 1024), settings(0.5, 30.0, l71)),
            with_threaded(),
        );
        add(
            "1MP-1L-uniform-K30",
            &|| (uniform_blur(1024, 1024), settings(0.5, 30.0, l71)),
            spans_fast(),
        );
        add(
            "4MP-2L-K30",
            &|| (two_layer(2048, 2048), settings(0.5, 30.0, l71)),
            spans_fast(),
        );
        add(
            "24MP-2L-K30",
            &|| (two_layer(6000, 4000), settings(0.5, 30.0, l71)),
            spans_fast(),
        );
        // 24 MP at K 100: radii to 51 px (front) and 41 px (background), no window limit.
        add(
            "24MP-2L-K100",
            &|| {
                let stack = two_layer(6000, 4000);
                let window = Window::auto_unclipped(100.0 * stack.max_defocus(0.5) + 1.0);
                (stack, settings(0.5, 100.0, window))
            },
            vec![Engine::Auto, Engine::Spans],
        );
        add(
            "0.07MP-1L-radius200",
            &|| {
                (
                    uniform_blur(256, 256),
                    settings(
                        0.5,
                        400.0,
                        model::automatic_window(400.0, 0.5, WindowCap::Unclipped),
                    ),
                )
            },
            spans_fast(),
        );
    }
    w
}

/// The names of the standard workloads (nothing is built).
pub fn workload_names(quick: bool) -> Vec<String> {
    let names = std::cell::RefCell::new(Vec::new());
    workloads_where(quick, |n| {
        names.borrow_mut().push(n.to_string());
        false
    });
    names.into_inner()
}

/// The name of the adjoint workload ([`adjoint_workload`]).
pub const ADJOINT_WORKLOAD_NAME: &str = "adjoint-0.25MP-2L-K30-L71";

fn disc_area(stack: &LayerStack<f32>, s: &RenderSettings) -> f64 {
    let (k, f) = (s.camera.blur_k, s.camera.focus_disparity);
    stack
        .layers
        .iter()
        .flat_map(|l| l.alpha.data.iter().zip(&l.disparity.data))
        .filter(|(a, _)| **a > 0.0)
        .map(|(_, d)| {
            let r = (k * (*d as f64 - f).abs()
                + s.model().footprint.px()
                + crate::model::SCATTER_TAIL_PX)
                .min(s.camera.window.radius_px() as f64);
            std::f64::consts::PI * r * r
        })
        .sum()
}

/// `(max linear, max display, mean display)` absolute differences of two renders.
fn differences(a: &Image<f32>, b: &Image<f32>, s: &RenderSettings) -> (f64, f64, f64) {
    let tone = s.tone();
    let (mut lin, mut max, mut sum) = (0.0f64, 0.0f64, 0.0f64);
    for (x, y) in a.data.iter().zip(&b.data) {
        let (x, y) = (*x as f64, *y as f64);
        lin = lin.max((tone.linearize(x) - tone.linearize(y)).abs());
        max = max.max((x - y).abs());
        sum += (x - y).abs();
    }
    (lin, max, sum / a.data.len().max(1) as f64)
}

/// Runs one workload: each of its engines in order. `report` sees each row.
pub fn run_workload(w: &Workload, report: &mut dyn FnMut(&BenchRow)) -> Result<Vec<BenchRow>> {
    let mp = (w.stack.width * w.stack.height) as f64 / 1e6;
    let area = disc_area(&w.stack, &w.settings);
    let pixel_layers = (w.stack.width * w.stack.height * w.stack.layers.len()) as f64;
    let mut rows: Vec<BenchRow> = Vec::new();
    let mut fast: Option<(Image<f32>, f64)> = None;
    let mut threaded_seconds = None;
    for &engine in &w.engines {
        let t = Instant::now();
        let (img, stats) = render_with_stats(&w.stack, &w.settings, engine, &NoProgress)?;
        let seconds = t.elapsed().as_secs_f64();
        let mut row = BenchRow {
            workload: w.name.clone(),
            megapixels: mp,
            layers: w.stack.layers.len(),
            blur_k: w.settings.camera.blur_k,
            window: w.settings.camera.window.size(),
            engine: format!("{engine:?}").to_lowercase(),
            seconds,
            taps: stats.taps,
            taps_per_second: stats.taps as f64 / seconds,
            speedup_vs_threaded: None,
            max_linear_diff: None,
            max_display_diff: None,
            mean_display_diff: None,
            speedup_vs_fast: None,
            ns_per_pixel_layer: seconds * 1e9 / pixel_layers,
            span_layers: stats.span_layers,
            tap_layers: stats.tap_layers,
            disc_area: area,
        };
        if engine == Engine::Threaded {
            threaded_seconds = Some(seconds);
        }
        match &fast {
            None if engine == Engine::Fast => fast = Some((img, seconds)),
            Some((f, fast_seconds)) => {
                let (lin, max, mean) = differences(&img, f, &w.settings);
                row.max_linear_diff = Some(lin);
                row.max_display_diff = Some(max);
                row.mean_display_diff = Some(mean);
                row.speedup_vs_fast = Some(fast_seconds / seconds);
            }
            None => {}
        }
        rows.push(row);
    }
    if let Some(t) = threaded_seconds {
        for r in &mut rows {
            r.speedup_vs_threaded = Some(t / r.seconds);
        }
    }
    rows.iter().for_each(report);
    Ok(rows)
}

/// The adjoint workload: forward (fast), forward with tape and backward on the fast
/// schedule, the same on `auto` (the span adjoint), and (when `with_threaded`) the exact
/// threaded adjoint for comparison.
#[derive(Clone, Debug, serde::Serialize)]
pub struct AdjointRow {
    /// Workload name.
    pub workload: String,
    /// Wall seconds of `render(.., Engine::Fast, ..)`.
    pub forward_fast: f64,
    /// Wall seconds of the fast forward with tape.
    pub forward_tape_fast: f64,
    /// Wall seconds of the fast backward.
    pub backward_fast: f64,
    /// `backward_fast / forward_fast`.
    pub backward_over_forward: f64,
    /// Wall seconds of `render(.., Engine::Auto, ..)` (spans where they are cheaper);
    /// this and the next two: medians of 5 rounds.
    pub forward_auto: f64,
    /// Wall seconds of the auto forward with tape (the span render, recorded).
    pub forward_tape_auto: f64,
    /// Wall seconds of the span adjoint's backward (`Engine::Auto`'s tape).
    pub backward_auto: f64,
    /// `backward_auto / forward_auto`.
    pub backward_over_forward_auto: f64,
    /// Largest absolute difference between the span adjoint's and the fast adjoint's
    /// gradients (all layers and kinds).
    pub max_grad_diff_auto_fast: f64,
    /// Wall seconds of the threaded forward with tape, if measured.
    pub forward_tape_threaded: Option<f64>,
    /// Wall seconds of the threaded (exact) backward, if measured.
    pub backward_threaded: Option<f64>,
    /// Largest absolute difference between the fast and threaded gradients (all layers and
    /// kinds), if measured.
    pub max_grad_diff: Option<f64>,
    /// Largest absolute threaded gradient, the scale of `max_grad_diff`, if measured.
    pub max_grad: Option<f64>,
}

/// The adjoint workload: 512x512, 2 layers, K 30, L 71 ([`two_layer`]), upstream gradient
/// a fixed pseudo-random field in [-1, 1].
pub fn adjoint_workload() -> Workload {
    Workload {
        name: ADJOINT_WORKLOAD_NAME.into(),
        stack: two_layer(512, 512),
        settings: settings(0.5, 30.0, Window::from_size(71).expect("valid window")),
        engines: vec![Engine::Fast, Engine::Threaded],
    }
}

/// Runs the adjoint workload; the threaded adjoint (a minute on 2 cores) only if
/// `with_threaded`.
pub fn run_adjoint(w: &Workload, with_threaded: bool) -> Result<AdjointRow> {
    let (width, height) = (w.stack.width, w.stack.height);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let g: Vec<f32> = (0..width * height * 3)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 23) as f32 - 1.0
        })
        .collect();
    let g = Image::from_vec(width, height, 3, g)?;
    let t = Instant::now();
    render_with_stats(&w.stack, &w.settings, Engine::Fast, &NoProgress)?;
    let forward_fast = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (_, tape) = render_with_tape_on(&w.stack, &w.settings, Engine::Fast, &NoProgress)?;
    let forward_tape_fast = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let fast = tape.backward(&g, &NoProgress)?;
    let backward_fast = t.elapsed().as_secs_f64();
    drop(tape);
    // The span adjoint takes a fraction of a second: forward, forward with tape and
    // backward in turn, AUTO_ROUNDS times, each reported as its median (one slow round on
    // a shared machine would otherwise decide the ratio).
    let (mut fwd, mut fwd_tape, mut bwd) = (Vec::new(), Vec::new(), Vec::new());
    let mut auto = None;
    for _ in 0..AUTO_ROUNDS {
        let t = Instant::now();
        render_with_stats(&w.stack, &w.settings, Engine::Auto, &NoProgress)?;
        fwd.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let (_, tape) = render_with_tape_on(&w.stack, &w.settings, Engine::Auto, &NoProgress)?;
        fwd_tape.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        auto = Some(tape.backward(&g, &NoProgress)?);
        bwd.push(t.elapsed().as_secs_f64());
    }
    let auto = auto.expect("AUTO_ROUNDS > 0");
    let (forward_auto, forward_tape_auto, backward_auto) =
        (median(fwd), median(fwd_tape), median(bwd));
    let mut row = AdjointRow {
        workload: w.name.clone(),
        forward_fast,
        forward_tape_fast,
        backward_fast,
        backward_over_forward: backward_fast / forward_fast,
        forward_auto,
        forward_tape_auto,
        backward_auto,
        backward_over_forward_auto: backward_auto / forward_auto,
        max_grad_diff_auto_fast: max_gradient_difference(&auto, &fast).0,
        forward_tape_threaded: None,
        backward_threaded: None,
        max_grad_diff: None,
        max_grad: None,
    };
    if with_threaded {
        let t = Instant::now();
        let (_, tape) = render_with_tape_on(&w.stack, &w.settings, Engine::Threaded, &NoProgress)?;
        row.forward_tape_threaded = Some(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let exact = tape.backward(&g, &NoProgress)?;
        row.backward_threaded = Some(t.elapsed().as_secs_f64());
        let (diff, max) = max_gradient_difference(&exact, &fast);
        row.max_grad_diff = Some(diff);
        row.max_grad = Some(max);
    }
    Ok(row)
}

/// Rounds of the span adjoint's forward, forward with tape and backward in
/// [`run_adjoint`] (medians reported).
const AUTO_ROUNDS: usize = 5;

/// The median of `v` (the upper one of an even count); `v` is not empty.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The largest absolute difference between two sets of gradients (all layers and kinds),
/// and the largest absolute value of the first.
fn max_gradient_difference(a: &Gradients<f32>, b: &Gradients<f32>) -> (f64, f64) {
    let (mut diff, mut max) = (0.0f64, 0.0f64);
    for (a, b) in a.layers.iter().zip(&b.layers) {
        for (x, y) in [
            (&a.rgb, &b.rgb),
            (&a.alpha, &b.alpha),
            (&a.disparity, &b.disparity),
        ] {
            for (p, q) in x.data.iter().zip(&y.data) {
                diff = diff.max((*p as f64 - *q as f64).abs());
                max = max.max((*p as f64).abs());
            }
        }
    }
    (diff, max)
}
