//! The coarse-to-fine Adam loop of [`estimate_disparity`].

use super::confidence::{occlusion_band_within_budget, OcclusionBand, OCCLUSION_BAND_BUDGET};
use super::layered::LayeredModel;
use super::log::{DfdLog, DfdNote, LogEntry, RunOptions, ScaleLog, DFD_LOG_SCHEMA_VERSION};
use super::maps::{
    box_mean, colour_vote, dilate, encode_image, pool, pool_adjoint, to_image, upsample,
    weighted_median,
};
use super::objective::{structure_min_side, ImageObjective, SMOOTHNESS_MIN_SIDE};
use super::sweep::{min_filter, sweep, Planes};
use super::{
    render_layer_on, render_layer_vjp_on, DfdOptions, DfdResult, Highlights, Init, Optimiser,
    Parameterisation, CONFIDENCE_HALF_SENSITIVITY,
};
use crate::camera::Window;
use crate::image::Image;
use crate::loss;
use crate::{Error, Real, Result};
use std::time::Instant;

/// An encoded value at or above this counts as clipped (at white).
pub(super) const CLIP_LEVEL: f64 = 0.999;
/// Encoded values above this are high dynamic range input, not clipped.
const HDR_LEVEL: f64 = 1.0 + 1e-6;
/// Largest brightness gain of a clipped highlight (linear), as `ln`.
const MAX_LOG_GAIN: f64 = 4.6; // 100x white
/// Adam learning rate of the highlights' log gains.
const GAIN_LEARNING_RATE: f64 = 0.1;
/// Disparity step of the confidence map's finite difference.
const CONFIDENCE_STEP: f64 = 0.02;
/// Half-size of the confidence map's box (5x5).
const CONFIDENCE_RADIUS: usize = 2;
/// Smallest half-size of the plane sweep's comparison box (5x5); it grows with the blur.
const SWEEP_RADIUS: usize = 2;

/// Adam state for a vector of parameters.
struct Adam {
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl Adam {
    fn new(n: usize) -> Self {
        Adam {
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
        }
    }

    /// One step of the chosen optimiser.
    fn step_with(&mut self, kind: Optimiser, params: &mut [f64], grad: &[f64], lr: f64) {
        match kind {
            Optimiser::Adam => self.step(params, grad, lr),
            Optimiser::SharedAdam => self.step_shared(params, grad, lr),
        }
    }

    /// Adam with one second moment (the mean squared gradient) for all parameters; steps
    /// capped at `3 lr`.
    fn step_shared(&mut self, params: &mut [f64], grad: &[f64], lr: f64) {
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-12);
        self.t += 1;
        let (c1, c2) = (1.0 - b1.powi(self.t), 1.0 - b2.powi(self.t));
        let ms = grad.iter().map(|g| g * g).sum::<f64>() / grad.len().max(1) as f64;
        self.v[0] = b2 * self.v[0] + (1.0 - b2) * ms;
        let denom = (self.v[0] / c2).sqrt() + eps;
        for i in 0..params.len() {
            self.m[i] = b1 * self.m[i] + (1.0 - b1) * grad[i];
            let step = lr * (self.m[i] / c1) / denom;
            params[i] -= step.clamp(-3.0 * lr, 3.0 * lr);
        }
    }

    /// One step of `lr` on `params` along `grad`.
    fn step(&mut self, params: &mut [f64], grad: &[f64], lr: f64) {
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8);
        self.t += 1;
        let (c1, c2) = (1.0 - b1.powi(self.t), 1.0 - b2.powi(self.t));
        for i in 0..params.len() {
            let g = grad[i];
            self.m[i] = b1 * self.m[i] + (1.0 - b1) * g;
            self.v[i] = b2 * self.v[i] + (1.0 - b2) * g * g;
            params[i] -= lr * (self.m[i] / c1) / ((self.v[i] / c2).sqrt() + eps);
        }
    }
}

fn sigmoid(u: f64) -> f64 {
    1.0 / (1.0 + (-u).exp())
}

fn logit(d: f64) -> f64 {
    let d = d.clamp(1e-4, 1.0 - 1e-4);
    (d / (1.0 - d)).ln()
}

impl Parameterisation {
    fn to_disparity(self, p: f64) -> f64 {
        match self {
            Parameterisation::Clamped => p,
            Parameterisation::Sigmoid => sigmoid(p),
        }
    }
    fn variable_of(self, d: f64) -> f64 {
        match self {
            Parameterisation::Clamped => d.clamp(0.0, 1.0),
            Parameterisation::Sigmoid => logit(d),
        }
    }
    /// d disparity / d parameter.
    fn derivative(self, p: f64) -> f64 {
        match self {
            Parameterisation::Clamped => 1.0,
            Parameterisation::Sigmoid => {
                let s = sigmoid(p);
                s * (1.0 - s)
            }
        }
    }
    fn after_step(self, p: &mut [f64]) {
        if self == Parameterisation::Clamped {
            p.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
        }
    }
}

/// One scale of the pyramid.
struct Level {
    width: usize,
    height: usize,
    /// Target, encoded.
    target: Vec<f64>,
    /// Pixels left out of the loss.
    excluded: Vec<bool>,
}

fn check_inputs<T: Real>(all_in_focus: &Image<T>, defocused: &Image<T>) -> Result<()> {
    for (what, img) in [
        ("all-in-focus image", all_in_focus),
        ("defocused image", defocused),
    ] {
        if img.channels != 3 || img.data.len() != img.width * img.height * 3 {
            return Err(Error::input(what, "must be an RGB image (3 channels)"));
        }
        img.check_finite(what)?;
        if img.data.iter().any(|v| v.f64() < 0.0) {
            return Err(Error::input(what, "has negative values"));
        }
    }
    if (all_in_focus.width, all_in_focus.height) != (defocused.width, defocused.height) {
        return Err(Error::input(
            "depth from defocus",
            format!(
                "all-in-focus image is {}x{} but the defocused image is {}x{}",
                all_in_focus.width, all_in_focus.height, defocused.width, defocused.height
            ),
        ));
    }
    if all_in_focus.width < 8 || all_in_focus.height < 8 {
        return Err(Error::input(
            "depth from defocus",
            format!(
                "{}x{} is too small (at least 8x8)",
                all_in_focus.width, all_in_focus.height
            ),
        ));
    }
    Ok(())
}

/// Estimates disparity from an all-in-focus image and a defocused image (both HxWx3,
/// display-encoded, the same view) with the camera of `options.settings` (see the
/// [module documentation](super)). `on_iteration` sees each log entry as it is made (for
/// progress).
pub fn estimate_disparity<T: Real>(
    all_in_focus: &Image<T>,
    defocused: &Image<T>,
    options: &DfdOptions,
    on_iteration: &mut dyn FnMut(&LogEntry),
) -> Result<DfdResult<T>> {
    let started = Instant::now();
    check_inputs(all_in_focus, defocused)?;
    options.validate()?;
    let (w, h) = (all_in_focus.width, all_in_focus.height);
    if let Some(map) = &options.initial_disparity {
        if (map.width, map.height, map.channels) != (w, h, 1) || map.data.len() != w * h {
            return Err(Error::input(
                "initial disparity",
                format!(
                    "is {}x{}x{}, but the pair is {w}x{h} (one channel expected)",
                    map.width, map.height, map.channels
                ),
            ));
        }
        map.check_finite("initial disparity")?;
    }
    let tone = options.settings.tone();
    let cam = &options.settings.camera;
    let (k_full, focus) = (cam.blur_k, cam.focus_disparity);
    let max_rel = focus.max(1.0 - focus);

    // Clipped pixels: aif channels at white (highlights whose brightness is lost), target
    // pixels at white (the sensor clipped them: left out).
    let aif_clipped: Vec<bool> = all_in_focus
        .data
        .iter()
        .map(|v| (CLIP_LEVEL..=HDR_LEVEL).contains(&v.f64()))
        .collect();
    let target_clipped: Vec<bool> = defocused
        .data
        .chunks_exact(3)
        .map(|p| p.iter().any(|v| v.f64() >= CLIP_LEVEL))
        .collect();
    let mut excluded = target_clipped.clone();
    if options.highlights == Highlights::Mask {
        let seed: Vec<bool> = aif_clipped
            .chunks_exact(3)
            .map(|c| c.iter().any(|&b| b))
            .collect();
        let reach = dilate(&seed, w, h, k_full * max_rel + 2.0);
        for (e, r) in excluded.iter_mut().zip(&reach) {
            *e |= *r;
        }
    }
    let masked_fraction = excluded.iter().filter(|&&e| e).count() as f64 / (w * h) as f64;

    let param = options.parameterisation;
    let sched = options.schedule;
    // Pyramid, pooled in linear light.
    let finest = sched.finest_for(w, h, k_full * max_rel);
    let n_scales = sched.levels_for(w, h, finest);
    let aif_lin: Vec<f64> = all_in_focus
        .data
        .iter()
        .map(|v| tone.linearize(v.f64()))
        .collect();
    let target_lin: Vec<f64> = defocused
        .data
        .iter()
        .map(|v| tone.linearize(v.f64()))
        .collect();
    let mut levels = vec![Level {
        width: w,
        height: h,
        target: defocused.data.iter().map(|v| v.f64()).collect(),
        excluded: excluded.clone(),
    }];
    let (mut lin_t, mut excl) = (target_lin.clone(), excluded);
    while levels.len() < n_scales {
        let last = levels.last().expect("one level");
        let (lw, lh) = (last.width, last.height);
        if lw < 16 || lh < 16 {
            break;
        }
        let next_t = pool(&lin_t, lw, lh, 3);
        let (pw, ph) = (lw / 2, lh / 2);
        let next_e: Vec<bool> = (0..pw * ph)
            .map(|i| {
                let (x, y) = (i % pw, i / pw);
                excl[2 * y * lw + 2 * x]
                    || excl[2 * y * lw + 2 * x + 1]
                    || excl[(2 * y + 1) * lw + 2 * x]
                    || excl[(2 * y + 1) * lw + 2 * x + 1]
            })
            .collect();
        levels.push(Level {
            width: pw,
            height: ph,
            target: next_t.iter().map(|&v| tone.encode(v.max(0.0))).collect(),
            excluded: next_e.clone(),
        });
        lin_t = next_t;
        excl = next_e;
    }
    let n_scales = levels.len();

    // Highlight gains (log, >= 0) on the clipped aif channels.
    let model_highlights = options.highlights == Highlights::Model;
    let clipped_idx: Vec<usize> = (0..aif_clipped.len()).filter(|&i| aif_clipped[i]).collect();
    let mut log_gain = if model_highlights {
        super::highlights::energy_log_gains(
            &aif_lin,
            &target_lin,
            &clipped_idx,
            w,
            h,
            k_full * max_rel + 2.0,
            MAX_LOG_GAIN,
        )
    } else {
        vec![0.0f64; clipped_idx.len()]
    };
    let mut gain_adam = Adam::new(clipped_idx.len());
    // The aif at scale `s` (linear), with the current gains.
    let aif_at = |s: usize, log_gain: &[f64]| -> Vec<f64> {
        let mut lin = aif_lin.clone();
        for (&i, &g) in clipped_idx.iter().zip(log_gain) {
            lin[i] *= g.exp();
        }
        let (mut lw, mut lh) = (w, h);
        for _ in 0..s {
            lin = pool(&lin, lw, lh, 3);
            lw /= 2;
            lh /= 2;
        }
        lin
    };

    let mut entries = Vec::new();
    let mut scale_logs = Vec::new();
    let mut current: Option<(Vec<f64>, usize, usize)> = None; // disparity at the last scale
    for scale in (finest..n_scales).rev() {
        let t_scale = Instant::now();
        let level = &levels[scale];
        let (lw, lh) = (level.width, level.height);
        let mut settings = options.settings.clone();
        settings.camera.blur_k = k_full / (1u64 << scale) as f64;
        settings.camera.window = Window::auto_unclipped(settings.camera.blur_k * max_rel + 1.0);
        let target: Image<T> = to_image(&level.target, lw, lh, 3);
        let min_side = lw.min(lh);
        let objective = ImageObjective {
            weights: options.weights,
            terms: options.terms,
            use_structure: min_side >= structure_min_side(options.terms),
            target: &target,
            excluded: &level.excluded,
        };
        let use_smooth = options.weights.smoothness > 0.0 && min_side >= SMOOTHNESS_MIN_SIDE;

        // Starting disparity of this scale.
        let start: Vec<f64> = match (&current, &options.initial_disparity) {
            (Some((d, sw, sh)), _) => upsample(d, *sw, *sh, lw, lh),
            (None, Some(map)) => {
                let mut d: Vec<f64> = map
                    .data
                    .iter()
                    .map(|&v| (v as f64).clamp(0.0, 1.0))
                    .collect();
                let (mut mw, mut mh) = (w, h);
                for _ in 0..scale {
                    d = pool(&d, mw, mh, 1);
                    mw /= 2;
                    mh /= 2;
                }
                d
            }
            (None, None) => match options.init {
                Init::Constant(v) => vec![v; lw * lh],
                Init::Sweep(n) => {
                    // The sweep runs at the finest scale optimised (where blur sizes are
                    // resolved) and is pooled down to this one.
                    let fl = &levels[finest];
                    let (fw, fh) = (fl.width, fl.height);
                    let mut fs = options.settings.clone();
                    fs.camera.blur_k = k_full / (1u64 << finest) as f64;
                    fs.camera.window = Window::auto_unclipped(fs.camera.blur_k * max_rel + 1.0);
                    let aif: Image<T> = encode_image(&aif_at(finest, &log_gain), fw, fh, &tone);
                    let ft: Image<T> = to_image(&fl.target, fw, fh, 3);
                    let radius =
                        ((fs.camera.blur_k * max_rel / 2.0).round() as usize).max(SWEEP_RADIUS);
                    let mut planes = Planes {
                        count: n,
                        window_radius: radius,
                        front: None,
                    };
                    let mut d = sweep(options, &fs, &aif, &ft, &fl.excluded, &planes)?;
                    if let Some(fraction) = options.sweep_context {
                        let erode_px = (fs.camera.blur_k * max_rel * fraction).round() as usize;
                        let front = min_filter(&d, fw, fh, erode_px);
                        planes.front = Some(&front);
                        d = sweep(options, &fs, &aif, &ft, &fl.excluded, &planes)?;
                    }
                    let (mut mw, mut mh) = (fw, fh);
                    for _ in finest..scale {
                        d = pool(&d, mw, mh, 1);
                        mw /= 2;
                        mh /= 2;
                    }
                    d
                }
            },
        };
        let mut p: Vec<f64> = start.iter().map(|&d| param.variable_of(d)).collect();
        let mut adam = Adam::new(p.len());
        let lr = sched.learning_rate
            * sched
                .learning_rate_decay
                .powi((n_scales - 1 - scale) as i32);
        let max_iters = if scale == finest {
            sched.fine_iterations_for(finest, k_full * max_rel)
        } else {
            sched.iterations
        };
        // The smoothness guide: the clipped all-in-focus image at this scale, scaled by the
        // edge sensitivity (G's edge weight becomes exp(-sensitivity |dI|)).
        let guide: Image<T> = {
            let g: Image<T> =
                encode_image(&aif_at(scale, &vec![0.0; clipped_idx.len()]), lw, lh, &tone);
            let k = T::c(options.edge_sensitivity);
            Image {
                data: g.data.iter().map(|&v| v.min(T::one()) * k).collect(),
                ..g
            }
        };
        let (mut best, mut best_at) = (f64::INFINITY, 0usize);
        let mut iterations = 0;
        let mut plateau = false;
        let mut last_loss = f64::NAN;
        let layered = options
            .layered
            .filter(|_| options.layer == super::RenderLayer::DrBokeh);
        let mut model: Option<LayeredModel<T>> = None;
        for it in 0..max_iters {
            let disp: Vec<f64> = p.iter().map(|&v| param.to_disparity(v)).collect();
            let disp_img: Image<T> = to_image(&disp, lw, lh, 1);
            let aif_lin_s = aif_at(scale, &log_gain);
            let aif: Image<T> = encode_image(&aif_lin_s, lw, lh, &tone);
            let mut entry = LogEntry {
                scale,
                iteration: it,
                loss: 0.0,
                l1: None,
                smoothness: None,
                structure: None,
            };
            if let Some(l) = layered {
                if it % l.every == 0 {
                    model = Some(LayeredModel::decompose(&aif, &disp_img, l.max_layers)?);
                }
            }
            let colour_gradient = model_highlights && !clipped_idx.is_empty();
            let upstream = |render: &Image<T>| objective.evaluate(render, &mut entry);
            let vjp = match &model {
                Some(m) => m.vjp(
                    options.engine,
                    &aif,
                    &disp_img,
                    &settings,
                    colour_gradient,
                    upstream,
                )?,
                None => render_layer_vjp_on(
                    options.layer,
                    options.engine,
                    &aif,
                    &disp_img,
                    &settings,
                    colour_gradient,
                    upstream,
                )?,
            };
            let mut grad: Vec<f64> = vjp.d_disparity.data.iter().map(|v| v.f64()).collect();
            if use_smooth {
                let (val, gs) = loss::edge_aware_smoothness_grad(&disp_img, &guide)?;
                entry.smoothness = Some(val.f64());
                entry.loss += options.weights.smoothness * val.f64();
                for (a, b) in grad.iter_mut().zip(&gs.data) {
                    *a += options.weights.smoothness * b.f64();
                }
            }
            for (g, &v) in grad.iter_mut().zip(&p) {
                *g *= param.derivative(v);
            }
            // Highlight gains: encoded-colour gradient -> linear at this scale -> full
            // resolution -> log gain.
            if let Some(d_rgb) = &vjp.d_rgb {
                let mut g_lin: Vec<f64> = d_rgb
                    .data
                    .iter()
                    .zip(&aif_lin_s)
                    .map(|(g, &l)| g.f64() * tone.encode_derivative(l.max(1e-12)))
                    .collect();
                let mut sizes = vec![(w, h)];
                for _ in 0..scale {
                    let (a, b) = *sizes.last().expect("one size");
                    sizes.push((a / 2, b / 2));
                }
                for s in (0..scale).rev() {
                    let (a, b) = sizes[s];
                    g_lin = pool_adjoint(&g_lin, a, b, 3);
                }
                let g_gain: Vec<f64> = clipped_idx
                    .iter()
                    .zip(&log_gain)
                    .map(|(&i, &u)| g_lin[i] * aif_lin[i] * u.exp())
                    .collect();
                gain_adam.step(&mut log_gain, &g_gain, GAIN_LEARNING_RATE);
                log_gain
                    .iter_mut()
                    .for_each(|u| *u = u.clamp(0.0, MAX_LOG_GAIN));
            }
            adam.step_with(options.optimiser, &mut p, &grad, lr);
            param.after_step(&mut p);
            on_iteration(&entry);
            last_loss = entry.loss;
            iterations = it + 1;
            if entry.loss < best * (1.0 - sched.min_improvement) {
                best = entry.loss;
                best_at = it;
            }
            entries.push(entry);
            if sched.patience > 0 && it >= best_at + sched.patience {
                plateau = it + 1 < max_iters;
                break;
            }
        }
        let disp: Vec<f64> = p.iter().map(|&v| param.to_disparity(v)).collect();
        let seconds = t_scale.elapsed().as_secs_f64();
        scale_logs.push(ScaleLog {
            scale,
            width: lw,
            height: lh,
            blur: settings.camera.blur_k,
            iterations,
            stopped_on_plateau: plateau,
            seconds,
            seconds_per_iteration: seconds / iterations.max(1) as f64,
            final_loss: last_loss,
        });
        current = Some((disp, lw, lh));
    }
    let (mut disp_f, fw, fh) = current.expect("at least one scale");
    if let Some(m) = options.median {
        let guide: Vec<[f64; 3]> = aif_at(finest, &vec![0.0; clipped_idx.len()])
            .chunks_exact(3)
            .map(|p| [0, 1, 2].map(|c| tone.encode(p[c].max(0.0)).min(1.0)))
            .collect();
        let reach = k_full / (1u64 << finest) as f64 * max_rel;
        let r = ((m.radius_blur_fraction * reach).round() as usize).max(1);
        disp_f = weighted_median(&disp_f, &guide, fw, fh, r, m.sigma);
    }

    // Sensitivity, at the finest scale optimised: how much the render changes with the
    // disparity (docs/dfd.md, "Confidence").
    let aif_f: Image<T> = encode_image(&aif_at(finest, &log_gain), fw, fh, &tone);
    let mut settings = options.settings.clone();
    settings.camera.blur_k = k_full / (1u64 << finest) as f64;
    settings.camera.window = Window::auto_unclipped(settings.camera.blur_k * max_rel + 1.0);
    let shifted = |delta: f64| -> Result<Image<T>> {
        let d: Vec<f64> = disp_f
            .iter()
            .map(|&v| (v + delta).clamp(0.0, 1.0))
            .collect();
        render_layer_on(
            options.layer,
            options.engine,
            &aif_f,
            &to_image(&d, fw, fh, 1),
            &settings,
        )
    };
    let (up, down) = (shifted(CONFIDENCE_STEP)?, shifted(-CONFIDENCE_STEP)?);
    let sens: Vec<f64> = (0..fw * fh)
        .map(|i| {
            let span = ((disp_f[i] + CONFIDENCE_STEP).min(1.0)
                - (disp_f[i] - CONFIDENCE_STEP).max(0.0))
            .max(1e-6);
            (0..3)
                .map(|c| (up.data[3 * i + c].f64() - down.data[3 * i + c].f64()).abs())
                .sum::<f64>()
                / (3.0 * span)
        })
        .collect();
    let sens = box_mean(&sens, fw, fh, CONFIDENCE_RADIUS);
    let sensitivity: Vec<f64> = sens
        .iter()
        .map(|&s| s / (s + CONFIDENCE_HALF_SENSITIVITY))
        .collect();
    let (disp, sensitivity) = if (fw, fh) == (w, h) {
        (disp_f, sensitivity)
    } else {
        let mut d = upsample(&disp_f, fw, fh, w, h);
        if let Some(m) = options.median {
            // Snap the upsampled edges onto the full-resolution colour edges.
            let guide: Vec<[f64; 3]> = aif_lin
                .chunks_exact(3)
                .map(|p| [0, 1, 2].map(|c| tone.encode(p[c].max(0.0)).min(1.0)))
                .collect();
            d = weighted_median(&d, &guide, w, h, 1 << finest, m.sigma);
        }
        (d, upsample(&sensitivity, fw, fh, w, h))
    };
    let disp = match options.colour_vote {
        Some(bins) => {
            let guide: Vec<[f64; 3]> = all_in_focus
                .data
                .chunks_exact(3)
                .map(|p| [p[0].f64(), p[1].f64(), p[2].f64()])
                .collect();
            let keep: Vec<bool> = aif_clipped
                .chunks_exact(3)
                .map(|c| c.iter().any(|&b| b))
                .collect();
            colour_vote(&disp, &guide, &keep, bins)
        }
        None => disp,
    };
    // Confidence: the occlusion band of the final map (docs/dfd.md, "Confidence").
    let confidence = occlusion_band_within_budget(
        &disp,
        w,
        h,
        k_full,
        focus,
        OcclusionBand::DEFAULT,
        OCCLUSION_BAND_BUDGET,
    );
    let disparity: Image<T> = to_image(&disp, w, h, 1);

    let log = DfdLog {
        schema_version: DFD_LOG_SCHEMA_VERSION,
        drbokeh_version: env!("CARGO_PKG_VERSION").to_string(),
        width: w,
        height: h,
        focus,
        blur: k_full,
        options: RunOptions::of(options),
        clipped_aif_pixels: clipped_idx.len(),
        clipped_target_pixels: target_clipped.iter().filter(|&&c| c).count(),
        masked_fraction,
        scales: scale_logs,
        entries,
        notes: DfdNote::for_run(w, h, focus, k_full, finest),
        seconds: started.elapsed().as_secs_f64(),
    };
    Ok(DfdResult {
        disparity,
        confidence: to_image(&confidence, w, h, 1),
        sensitivity: to_image(&sensitivity, w, h, 1),
        log,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameterisations_round_trip() {
        for p in [Parameterisation::Clamped, Parameterisation::Sigmoid] {
            for d in [0.05, 0.3, 0.5, 0.95] {
                assert!((p.to_disparity(p.variable_of(d)) - d).abs() < 1e-9);
            }
        }
        // The sigmoid's derivative against a finite difference.
        let s = Parameterisation::Sigmoid;
        let u = 0.7;
        let fd = (s.to_disparity(u + 1e-6) - s.to_disparity(u - 1e-6)) / 2e-6;
        assert!((fd - s.derivative(u)).abs() < 1e-8);
    }
}
