//! Times the engines on the workloads quoted in the closing notes: the demo, and a
//! 1024x1024 two-layer stack at the paper defaults (K = 30, L = 71), reference vs threaded;
//! and the adjoint at 512x512 (fast forward, tape and backward, and the exact threaded
//! adjoint for comparison). Ratios are measured in one run.
//!
//! Run: `cargo run --release -p drbokeh --example timing [-- --skip-reference]`

use drbokeh::{demo, render, Engine, Layer, LayerStack, NoProgress, RenderSettings, Window};
use std::time::Instant;

/// A two-layer stack: a soft-edged disc in front (disparity 0.8) of a textured background
/// (disparity 0.2).
fn two_layer(size: usize) -> LayerStack<f32> {
    let mut front = Layer::<f32>::constant(size, size, [0.9, 0.5, 0.2], 0.0, 0.8);
    let mut back = Layer::<f32>::constant(size, size, [0.0; 3], 1.0, 0.2);
    let c = size as f32 / 2.0;
    for y in 0..size {
        for x in 0..size {
            let r = ((x as f32 - c).powi(2) + (y as f32 - c).powi(2)).sqrt();
            *front.alpha.at_mut(x, y, 0) = (0.5 - (r - size as f32 / 4.0) / 3.0).clamp(0.0, 1.0);
            for ch in 0..3 {
                *back.rgb_encoded.at_mut(x, y, ch) = (((x / 16 + y / 16 + ch) % 3) as f32) / 2.0;
            }
        }
    }
    LayerStack::new(vec![front, back]).unwrap()
}

fn time<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = Instant::now();
    let v = f();
    (v, t.elapsed().as_secs_f64())
}

fn main() {
    let skip_reference = std::env::args().any(|a| a == "--skip-reference");
    let threads = rayon::current_num_threads();
    println!("threads: {threads}");

    let stack: LayerStack<f32> = demo::scene(640, 426);
    let mut s = RenderSettings::paper(demo::DEMO_FOCUS);
    s.camera.window = Window::auto(30.0 * stack.max_defocus(demo::DEMO_FOCUS) + 1.0);
    let (fast, t_fast) = time(|| render(&stack, &s, Engine::Threaded, &NoProgress).unwrap());
    println!(
        "demo 640x426, 3 layers, K 30, L {}: threaded {t_fast:.2} s",
        s.camera.window.size()
    );
    if !skip_reference {
        let (slow, t_ref) = time(|| render(&stack, &s, Engine::Reference, &NoProgress).unwrap());
        println!(
            "  reference {t_ref:.2} s  (ratio {:.2}x, max diff {:.1e})",
            t_ref / t_fast,
            slow.max_abs_diff(&fast)
        );
    }

    let stack = two_layer(1024);
    let s = RenderSettings::paper(0.5);
    let (quick, t_quick) = time(|| render(&stack, &s, Engine::Fast, &NoProgress).unwrap());
    let (fast, t_fast) = time(|| render(&stack, &s, Engine::Threaded, &NoProgress).unwrap());
    println!(
        "1024x1024, 2 layers, K 30, L 71: fast {t_quick:.2} s, threaded {t_fast:.2} s (fast is {:.1}x faster; max linear diff {:.1e})",
        t_fast / t_quick,
        quick.data.iter().zip(&fast.data).map(|(a, b)| (a.powf(2.2) - b.powf(2.2)).abs()).fold(0.0f32, f32::max)
    );
    if !skip_reference {
        let (slow, t_ref) = time(|| render(&stack, &s, Engine::Reference, &NoProgress).unwrap());
        println!(
            "  reference {t_ref:.2} s  (ratio {:.2}x, max diff {:.1e})",
            t_ref / t_fast,
            slow.max_abs_diff(&fast)
        );
    }

    // The adjoint at 512x512 (the workload of `drbokeh bench`): fast forward, fast forward
    // with tape and fast backward; the exact threaded adjoint too unless --skip-reference.
    let w = drbokeh::bench::adjoint_workload();
    let r = drbokeh::bench::run_adjoint(&w, !skip_reference).unwrap();
    println!(
        "512x512, 2 layers, K 30, L 71: forward (fast) {:.2} s, forward+tape (fast) {:.2} s, backward (fast) {:.2} s; backward/forward {:.2}x",
        r.forward_fast, r.forward_tape_fast, r.backward_fast, r.backward_over_forward
    );
    if let (Some(tape), Some(bwd), Some(diff), Some(max)) = (
        r.forward_tape_threaded,
        r.backward_threaded,
        r.max_grad_diff,
        r.max_grad,
    ) {
        println!(
            "  threaded (exact): forward+tape {tape:.2} s, backward {bwd:.2} s; max gradient diff {diff:.1e} (largest gradient {max:.1e})"
        );
    }
}
