//! Criterion benchmarks of the rendering kernels: the soft step (exact vs fast exp), a
//! small two-layer render per engine, and the adjoint's backward pass.
//!
//! Run: `cargo bench -p drbokeh --bench kernels`

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use drbokeh::bench::two_layer;
use drbokeh::{model, render, render_with_tape, Engine, Image, NoProgress, RenderSettings, Window};
use std::hint::black_box;

fn soft_step(c: &mut Criterion) {
    let xs: Vec<f32> = (0..4096).map(|i| (i as f32 - 2048.0) / 256.0).collect();
    let mut g = c.benchmark_group("soft_step");
    g.throughput(Throughput::Elements(xs.len() as u64));
    g.bench_function("std exp", |b| {
        b.iter(|| {
            xs.iter()
                .map(|&x| model::soft_step(black_box(x)))
                .sum::<f32>()
        })
    });
    g.bench_function("fast exp", |b| {
        b.iter(|| {
            xs.iter()
                .map(|&x| model::soft_step_fast(black_box(x)))
                .sum::<f32>()
        })
    });
    g.finish();
}

fn engines(c: &mut Criterion) {
    let stack = two_layer(128, 128);
    let mut s = RenderSettings::paper(0.5);
    s.camera.window = Window::from_size(41).unwrap();
    let mut g = c.benchmark_group("render 128x128 2 layers K30 L41");
    g.sample_size(10);
    for engine in [Engine::Fast, Engine::Threaded] {
        g.bench_function(format!("{engine:?}"), |b| {
            b.iter(|| render(black_box(&stack), &s, engine, &NoProgress).unwrap())
        });
    }
    g.finish();
}

fn adjoint(c: &mut Criterion) {
    let stack = two_layer(64, 64);
    let mut s = RenderSettings::paper(0.5);
    s.camera.window = Window::from_size(41).unwrap();
    let grad = Image::from_vec(64, 64, 3, vec![1.0f32; 64 * 64 * 3]).unwrap();
    let mut g = c.benchmark_group("adjoint 64x64 2 layers K30 L41");
    g.sample_size(10);
    g.bench_function("forward with tape", |b| {
        b.iter(|| render_with_tape(&stack, &s, &NoProgress).unwrap())
    });
    let (_, tape) = render_with_tape(&stack, &s, &NoProgress).unwrap();
    g.bench_function("backward", |b| {
        b.iter(|| tape.backward(black_box(&grad), &NoProgress).unwrap())
    });
    g.finish();
}

criterion_group!(benches, soft_step, engines, adjoint);
criterion_main!(benches);
