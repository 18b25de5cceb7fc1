//! Analysis: per clipped region of a benchmark's aif.png (defocused by >= 1 px), the true
//! light (aif.exr, grey) of its clipped pixels by depth (4-steps from the nearest unclipped
//! pixel: 1, 2, 3+), next to the rim cue of `--highlight auto`.
//!
//! ```text
//! cargo run --release -p drbokeh --example blob_profile -- BENCHMARK...
//! ```
use drbokeh::eval::report::{list_scenes, SceneInputs};
use drbokeh::image::Image;
use drbokeh::model::{Tone, Transfer};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let tone = Tone::new(Transfer::Srgb, 2.2, 0.0);
    for bench in std::env::args().skip(1) {
        for dir in list_scenes(bench.as_ref())? {
            let scene = SceneInputs::load(&dir)?;
            let png: Image<f64> = drbokeh::io::read_rgb(&dir.join("aif.png"))?;
            let exr: Image<f64> = drbokeh::io::read_rgb(&dir.join("aif.exr"))?;
            let (w, h) = (png.width, png.height);
            let clip: Vec<bool> = png
                .data
                .chunks_exact(3)
                .map(|p| p.iter().any(|&v| v >= 254.5 / 255.0))
                .collect();
            let grey = |img: &Image<f64>, i: usize, lin: bool| {
                (0..3)
                    .map(|c| {
                        let v = img.data[3 * i + c];
                        if lin {
                            tone.linearize(v)
                        } else {
                            v.max(0.0)
                        }
                    })
                    .sum::<f64>()
                    / 3.0
            };
            let is_clip = |x: i64, y: i64| {
                x >= 0
                    && y >= 0
                    && x < w as i64
                    && y < h as i64
                    && clip[y as usize * w + x as usize]
            };
            let depth = |i: usize| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                for r in 1..=2i64 {
                    for a in 0..=r {
                        let b = r - a;
                        for (dx, dy) in [(a, b), (-a, b), (a, -b), (-a, -b)] {
                            if !is_clip(x + dx, y + dy) {
                                return r as usize;
                            }
                        }
                    }
                }
                3
            };
            for reg in drbokeh::highlight::regions(w, h, |i| clip[i]) {
                let rad = scene.blur_k * (scene.disparity.data[reg[0]] as f64 - scene.focus).abs();
                if rad < 1.0 {
                    continue;
                }
                let mut n = [0usize; 4];
                let mut sum = [0.0f64; 4];
                let mut max = 0.0f64;
                for &i in &reg {
                    let d = depth(i);
                    let g = grey(&exr, i, false);
                    n[d] += 1;
                    sum[d] += g;
                    max = max.max(g);
                }
                // rim: unclipped 8-neighbours of the region; their photo light (linear grey)
                let mut rim = 0.0;
                let mut nrim = 0;
                let mut mark = vec![false; w * h];
                for &i in &reg {
                    let (x, y) = (i % w, i / w);
                    for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                        for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                            let j = ny * w + nx;
                            if !clip[j] && !mark[j] {
                                mark[j] = true;
                                rim += grey(&png, j, true);
                                nrim += 1;
                            }
                        }
                    }
                }
                // background: median linear grey of the ring 3-4 px (Chebyshev) out
                let dil = |r: usize| {
                    let mut m = vec![false; w * h];
                    for &i in &reg {
                        let (x, y) = (i % w, i / w);
                        for ny in y.saturating_sub(r)..=(y + r).min(h - 1) {
                            for nx in x.saturating_sub(r)..=(x + r).min(w - 1) {
                                m[ny * w + nx] = true;
                            }
                        }
                    }
                    m
                };
                let (d1, d2, d4) = (dil(1), dil(2), dil(4));
                let (mut r2, mut n2r) = (0.0, 0usize);
                let mut ring2: Vec<f64> = vec![];
                for i in 0..w * h {
                    if d2[i] && !d1[i] {
                        let g = grey(&png, i, true);
                        r2 += g;
                        n2r += 1;
                        ring2.push(g);
                    }
                }
                ring2.sort_by(f64::total_cmp);
                let r2med = ring2.get(ring2.len() / 2).copied().unwrap_or(0.0);
                let mut rims: Vec<f64> = (0..w * h)
                    .filter(|&i| d1[i] && !clip[i])
                    .map(|i| grey(&png, i, true))
                    .collect();
                rims.sort_by(f64::total_cmp);
                let mut ring: Vec<f64> = (0..w * h)
                    .filter(|&i| d4[i] && !d2[i])
                    .map(|i| grey(&png, i, true))
                    .collect();
                ring.sort_by(f64::total_cmp);
                let bg = ring.get(ring.len() / 2).copied().unwrap_or(0.0);
                let m = |d: usize| if n[d] > 0 { sum[d] / n[d] as f64 } else { 0.0 };
                println!(
                    "{} {} n {} {} {} mean {:.3} {:.3} {:.3} max {:.3} rim {:.3} nrim {} rad {:.1} bg {:.3} r2 {:.3} {} {:.3} rims {:?}",
                    bench.rsplit('/').next().unwrap_or(""),
                    scene.name,
                    n[1],
                    n[2],
                    n[3],
                    m(1),
                    m(2),
                    m(3),
                    max,
                    rim,
                    nrim,
                    rad,
                    bg,
                    r2,
                    n2r,
                    r2med,
                    rims.iter().map(|v| (v * 1000.0).round() / 1000.0).collect::<Vec<_>>()
                );
            }
        }
    }
    Ok(())
}
