//! Times the fast engine alone on a 1024x1024 two-layer stack (K = 30, L = 71).
//! Run: `cargo run --release -p drbokeh --example fast_only`
use drbokeh::{render, Engine, Layer, LayerStack, NoProgress, RenderSettings};
fn main() {
    let size = 1024;
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
    let stack = LayerStack::new(vec![front, back]).unwrap();
    let s = RenderSettings::paper(0.5);
    let t = std::time::Instant::now();
    let _ = render(&stack, &s, Engine::Fast, &NoProgress).unwrap();
    println!(
        "fast 1024x1024 2 layers K30 L71: {:.2} s",
        t.elapsed().as_secs_f64()
    );
}
