//! Renders the built-in demo scene at two focus settings and writes PNGs.
//!
//! Run: `cargo run --release -p drbokeh --example render_demo`

use drbokeh::io::{write_output, BitDepth};
use drbokeh::{demo, render, Engine, LayerStack, NoProgress, RenderSettings};

fn main() -> Result<(), drbokeh::Error> {
    let stack: LayerStack<f32> = demo::scene(320, 213);
    for (name, focus) in [
        ("demo-subject.png", demo::DEMO_FOCUS),
        ("demo-front.png", 0.9),
    ] {
        let mut settings = RenderSettings::paper(focus);
        settings.camera.blur_k = 20.0;
        settings.camera.window = drbokeh::Window::auto(20.0 * stack.max_defocus(focus) + 1.0);
        let image = render(&stack, &settings, Engine::Threaded, &NoProgress)?;
        write_output(name.as_ref(), &image, BitDepth::Eight, |v| v.powf(2.2))?;
        println!("wrote {name}");
    }
    Ok(())
}
