//! Analysis: per clipped blob of a benchmark's aif.png, the light the photo lost (aif.exr).
use drbokeh::eval::report::{list_scenes, SceneInputs};
use drbokeh::image::Image;
use drbokeh::model::{Tone, Transfer};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let t0: f64 = args[0].parse()?;
    let tone = Tone::new(Transfer::Srgb, 2.2, 0.0);
    for bench in &args[1..] {
        for dir in list_scenes(bench.as_ref())? {
            let scene = SceneInputs::load(&dir)?;
            let png: Image<f64> = drbokeh::io::read_rgb(&dir.join("aif.png"))?;
            let exr: Image<f64> = drbokeh::io::read_rgb(&dir.join("aif.exr"))?;
            let (w, h) = (png.width, png.height);
            let v: Vec<f64> = png
                .data
                .chunks_exact(3)
                .map(|p| p.iter().cloned().fold(0.0, f64::max))
                .collect();
            for reg in drbokeh::highlight::regions(w, h, |i| v[i] >= t0) {
                let nclip = reg.iter().filter(|&&i| v[i] >= 254.5 / 255.0).count();
                if nclip == 0 {
                    continue;
                }
                // region dilated by 2 px
                let mut mark = vec![false; w * h];
                for &i in &reg {
                    let (x, y) = (i % w, i / w);
                    for ny in y.saturating_sub(2)..=(y + 2).min(h - 1) {
                        for nx in x.saturating_sub(2)..=(x + 2).min(w - 1) {
                            mark[ny * w + nx] = true;
                        }
                    }
                }
                let mut miss = [0.0; 3];
                let mut lit = [0.0; 3];
                for i in 0..w * h {
                    if !mark[i] {
                        continue;
                    }
                    for c in 0..3 {
                        let p = tone.linearize(png.data[3 * i + c]);
                        let e = exr.data[3 * i + c].max(0.0);
                        miss[c] += e - p;
                        lit[c] += p;
                    }
                }
                // rim: unclipped pixels 8-adjacent to a clipped pixel of the region;
                // background: the ring at Chebyshev distance 3-4 from the region.
                let lin = |i: usize| {
                    (0..3)
                        .map(|c| tone.linearize(png.data[3 * i + c]))
                        .sum::<f64>()
                        / 3.0
                };
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
                let (d2, d4) = (dil(2), dil(4));
                let bgv: Vec<f64> = (0..w * h).filter(|&i| d4[i] && !d2[i]).map(lin).collect();
                let mut bgs = bgv.clone();
                bgs.sort_by(|a, b| a.partial_cmp(b).unwrap());
                let bg = if bgs.is_empty() {
                    0.0
                } else {
                    bgs[bgs.len() / 2]
                };
                let mut clipm = vec![false; w * h];
                for &i in &reg {
                    if v[i] >= 254.5 / 255.0 {
                        clipm[i] = true;
                    }
                }
                let mut rim = 0.0;
                let mut nrim = 0;
                let mut nedge = 0;
                for i in 0..w * h {
                    let (x, y) = (i % w, i / w);
                    let mut adj = false;
                    for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                        for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                            if clipm[ny * w + nx] {
                                adj = true;
                            }
                        }
                    }
                    if clipm[i] {
                        let mut e = false;
                        for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
                            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                            if nx < 0
                                || ny < 0
                                || nx >= w as i64
                                || ny >= h as i64
                                || !clipm[ny as usize * w + nx as usize]
                            {
                                e = true;
                            }
                        }
                        if e {
                            nedge += 1;
                        }
                    } else if adj {
                        rim += (lin(i) - bg).max(0.0);
                        nrim += 1;
                    }
                }
                let i0 = reg[0];
                print!("rim {rim:.3} nrim {nrim} nedge {nedge} bg {bg:.3} ");
                let rad = scene.blur_k * (scene.disparity.data[i0] as f64 - scene.focus).abs();
                println!(
                    "{} {} nreg {} nclip {} miss {:.2} {:.2} {:.2} lit {:.2} rad {:.1}",
                    bench.rsplit('/').next().unwrap(),
                    scene.name,
                    reg.len(),
                    nclip,
                    miss[0],
                    miss[1],
                    miss[2],
                    (lit[0] + lit[1] + lit[2]) / 3.0,
                    rad
                );
            }
        }
    }
    Ok(())
}
