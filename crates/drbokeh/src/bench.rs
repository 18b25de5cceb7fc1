//! Standard performance workloads (`drbokeh bench`): the fast engine against the plain
//! multi-threaded engine (and the single-threaded reference where affordable), measured in
//! one run, with taps visited, throughput and the largest difference in linear light.

use crate::camera::WindowCap;
use crate::demo;
use crate::engine::render_with_tape_on;
use crate::engine::{render_with_stats, Engine, NoProgress};
use crate::image::Image;
use crate::model;
use crate::presets::RenderSettings;
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
    /// Which comparison engines are affordable here.
    pub compare: Vec<Engine>,
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
    /// Largest absolute difference to the comparison engine, in linear light, if measured.
    pub max_linear_diff: Option<f64>,
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

fn settings(focus: f64, k: f64, window: Window) -> RenderSettings {
    let mut s = RenderSettings::paper(focus);
    s.camera.blur_k = k;
    s.camera.window = window;
    s
}

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
        |name: &str, make: &dyn Fn() -> (LayerStack<f32>, RenderSettings), compare: Vec<Engine>| {
            if keep(name) {
                let (stack, settings) = make();
                w.push(Workload {
                    name: name.into(),
                    stack,
                    settings,
                    compare,
                })
            }
        };
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
        vec![Engine::Threaded, Engine::Reference],
    );
    for k in [10.0, 30.0, 60.0] {
        add(
            &format!("0.25MP-2L-K{k}"),
            &|| (two_layer(512, 512), settings(0.5, k, l71)),
            vec![Engine::Threaded],
        );
    }
    add(
        "0.25MP-1L-uniform-K30",
        &|| (uniform_blur(512, 512), settings(0.5, 30.0, l71)),
        vec![Engine::Threaded],
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
        vec![Engine::Threaded],
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
        vec![],
    );
    if !quick {
        add(
            "1MP-2L-K30-L71 (paper defaults)",
            &|| (two_layer(1024, 1024), settings(0.5, 30.0, l71)),
            vec![Engine::Threaded],
        );
        add(
            "1MP-1L-uniform-K30",
            &|| (uniform_blur(1024, 1024), settings(0.5, 30.0, l71)),
            vec![],
        );
        add(
            "4MP-2L-K30",
            &|| (two_layer(2048, 2048), settings(0.5, 30.0, l71)),
            vec![],
        );
        add(
            "24MP-2L-K30",
            &|| (two_layer(6000, 4000), settings(0.5, 30.0, l71)),
            vec![],
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
            vec![],
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

fn max_linear_diff(a: &Image<f32>, b: &Image<f32>, gamma: f64) -> f64 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| ((*x as f64).powf(gamma) - (*y as f64).powf(gamma)).abs())
        .fold(0.0, f64::max)
}

/// Runs one workload: the fast engine, then each comparison engine. `report` sees each row.
pub fn run_workload(w: &Workload, report: &mut dyn FnMut(&BenchRow)) -> Result<Vec<BenchRow>> {
    let mp = (w.stack.width * w.stack.height) as f64 / 1e6;
    let area = disc_area(&w.stack, &w.settings);
    let row = |engine: Engine, seconds: f64, taps: u64| BenchRow {
        workload: w.name.clone(),
        megapixels: mp,
        layers: w.stack.layers.len(),
        blur_k: w.settings.camera.blur_k,
        window: w.settings.camera.window.size(),
        engine: format!("{engine:?}").to_lowercase(),
        seconds,
        taps,
        taps_per_second: taps as f64 / seconds,
        speedup_vs_threaded: None,
        max_linear_diff: None,
        disc_area: area,
    };
    let t = Instant::now();
    let (fast, stats) = render_with_stats(&w.stack, &w.settings, Engine::Fast, &NoProgress)?;
    let mut rows = vec![row(Engine::Fast, t.elapsed().as_secs_f64(), stats.taps)];
    for &engine in &w.compare {
        let t = Instant::now();
        let (img, stats) = render_with_stats(&w.stack, &w.settings, engine, &NoProgress)?;
        let mut r = row(engine, t.elapsed().as_secs_f64(), stats.taps);
        let diff = max_linear_diff(&img, &fast, w.settings.camera.gamma);
        r.max_linear_diff = Some(diff);
        rows[0].max_linear_diff = Some(rows[0].max_linear_diff.unwrap_or(0.0).max(diff));
        if engine == Engine::Threaded {
            rows[0].speedup_vs_threaded = Some(r.seconds / rows[0].seconds);
        }
        rows.push(r);
    }
    rows.iter().for_each(report);
    Ok(rows)
}

/// The adjoint workload: forward (fast), forward with tape and backward on the fast
/// schedule, and (when `with_threaded`) the exact threaded adjoint for comparison.
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
        compare: vec![Engine::Threaded],
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
    let mut row = AdjointRow {
        workload: w.name.clone(),
        forward_fast,
        forward_tape_fast,
        backward_fast,
        backward_over_forward: backward_fast / forward_fast,
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
        let (mut diff, mut max) = (0.0f64, 0.0f64);
        for (a, b) in exact.layers.iter().zip(&fast.layers) {
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
        row.max_grad_diff = Some(diff);
        row.max_grad = Some(max);
    }
    Ok(row)
}
