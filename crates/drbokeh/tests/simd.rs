//! The fast engine's kernels are compiled twice, for the baseline target and with AVX2
//! (`engine/simd.rs`), and must give the same bytes: the same inputs are rendered and
//! differentiated with the AVX2 copies and with the baseline copies forced
//! (`simd::force_baseline`), and every output is compared bit for bit.
//!
//! One test function, so that forcing the baseline (process-wide) cannot race another test.

mod common;

use common::random_stack;
use drbokeh::aperture::KernelImage;
use drbokeh::engine::simd;
use drbokeh::presets::ModelOptions;
use drbokeh::{
    render, render_with_tape_on, Aperture, Engine, Image, LayerStack, NoProgress, Real,
    RenderSettings, Window,
};

fn bits<T: Real>(img: &Image<T>) -> Vec<u64> {
    img.data.iter().map(|v| v.f64().to_bits()).collect()
}

/// The render and every gradient of one case, as bits.
fn run<T: Real>(stack: &LayerStack<T>, settings: &RenderSettings) -> Vec<Vec<u64>> {
    let image = render(stack, settings, Engine::Fast, &NoProgress).unwrap();
    let (taped, tape) = render_with_tape_on(stack, settings, Engine::Fast, &NoProgress).unwrap();
    let mut g = Image::<T>::new(stack.width, stack.height, 3);
    for (i, v) in g.data.iter_mut().enumerate() {
        *v = T::c(((i * 7919) % 101) as f64 / 50.0 - 1.0);
    }
    let grads = tape.backward(&g, &NoProgress).unwrap();
    let mut out = vec![bits(&image), bits(&taped)];
    for l in &grads.layers {
        out.extend([bits(&l.rgb), bits(&l.alpha), bits(&l.disparity)]);
    }
    out.push(vec![grads.blur_k.to_bits(), grads.focus.to_bits()]);
    out
}

fn cases() -> Vec<(&'static str, RenderSettings)> {
    let mut ring = Image::<f64>::new(9, 9, 1);
    for y in 0..9 {
        for x in 0..9 {
            let r = ((x as f64 - 4.0).powi(2) + (y as f64 - 4.0).powi(2)).sqrt();
            *ring.at_mut(x, y, 0) = if (2.0..4.5).contains(&r) { 1.0 } else { 0.2 };
        }
    }
    let apertures = [
        ("circle", Aperture::Circle),
        (
            "hexagon",
            Aperture::Polygon {
                blades: 6,
                rotation_deg: 10.0,
            },
        ),
        ("kernel", Aperture::Kernel(KernelImage::new(&ring).unwrap())),
    ];
    let mut out = Vec::new();
    for (name, aperture) in apertures {
        for options in [ModelOptions::PAPER, ModelOptions::PHYSICAL] {
            let mut s = RenderSettings::paper(0.45).with_model(options);
            s.camera.blur_k = 14.0;
            s.camera.window = Window::from_size(23).unwrap();
            s.aperture = aperture.clone();
            out.push((name, s));
        }
    }
    out
}

#[test]
fn avx2_and_baseline_kernels_give_the_same_bytes() {
    if !simd::avx2_active() {
        eprintln!("note: no AVX2 on this CPU: both runs use the baseline kernels");
    }
    let stack32: LayerStack<f32> = random_stack(41, 57, 43, 3);
    let stack64: LayerStack<f64> = random_stack(41, 57, 43, 3);
    for (name, settings) in cases() {
        let preset = settings.preset.name();
        simd::force_baseline(false);
        let (avx32, avx64) = (run(&stack32, &settings), run(&stack64, &settings));
        simd::force_baseline(true);
        assert!(!simd::avx2_active());
        let (base32, base64) = (run(&stack32, &settings), run(&stack64, &settings));
        simd::force_baseline(false);
        for (what, a, b) in [("f32", &avx32, &base32), ("f64", &avx64, &base64)] {
            assert_eq!(a.len(), b.len());
            for (k, (x, y)) in a.iter().zip(b).enumerate() {
                let differ = x.iter().zip(y).filter(|(p, q)| p != q).count();
                assert_eq!(
                    differ, 0,
                    "{name}, {preset}, {what}: output {k} differs in {differ} values"
                );
            }
        }
    }
}
