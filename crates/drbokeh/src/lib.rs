//! # drbokeh
//!
//! Differentiable, occlusion-aware bokeh rendering (Dr.Bokeh) in Rust. A [`LayerStack`]
//! (layers front to back: colour, alpha, disparity) is rendered by the soft scatter model
//! of [`model`], evaluated by an [`engine`], and composited front to back.
//!
//! ```
//! use drbokeh::{render, Engine, Layer, LayerStack, NoProgress, RenderSettings};
//! let background = Layer::<f32>::constant(32, 32, [0.2, 0.4, 0.8], 1.0, 0.1);
//! let stack = LayerStack::new(vec![background]).unwrap();
//! let mut settings = RenderSettings::paper(0.5);
//! settings.camera.window = drbokeh::Window::from_size(21).unwrap();
//! let out = render(&stack, &settings, Engine::Threaded, &NoProgress).unwrap();
//! assert!((out.at(5, 5, 2) - 0.8).abs() < 1e-4);
//! ```

pub mod aperture;
pub mod baselines;
pub mod bench;
pub mod budget;
pub mod camera;
pub mod demo;
pub mod dfd;
pub mod engine;
mod error;
pub mod eval;
pub mod highlight;
pub mod image;
pub mod io;
pub mod layering;
pub mod loss;
pub mod model;
pub mod presets;
mod progress;
mod real;
pub mod scene;
pub mod stack;
pub mod trace;

pub use aperture::Aperture;
pub use camera::{Camera, Window};
pub use engine::{
    render, render_with_stats, render_with_tape, render_with_tape_on, Engine, Gradients,
    LayerGradients, RenderStats, Tape,
};
pub use error::{Error, Result};
pub use image::Image;
pub use model::HighlightBoost;
pub use presets::{Preset, RenderSettings};
pub use progress::{NoProgress, Progress};
pub use real::Real;
pub use stack::{Layer, LayerStack};
