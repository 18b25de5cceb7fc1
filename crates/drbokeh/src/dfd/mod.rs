//! Depth from defocus (supplement sec. 3.2): recover a disparity map from an all-in-focus
//! image and a defocused image of the same view (known K and focus) by optimising through
//! a rendering layer, minimising `L = w1 |render - target|_1 + wg G + wh HSSIM`.
//!
//! The optimiser is Adam on the disparity values, clamped to [0, 1] after each step, run
//! coarse to fine: at scale `s` both images are average-pooled `2^s` times and K is divided
//! by `2^s` (blur radii shrink with the image); the result is upsampled to initialise the
//! next finer scale. Coarse scales see large structures with small, cheap windows.
//! Loss terms that need more pixels than a scale has (HSSIM: 31 per side, smoothness: 16)
//! are left out at that scale, and the log says so.

pub mod experiment;
pub mod layers;

pub use layers::{render_layer, render_layer_vjp, render_layer_vjp_on, RenderLayer};

use crate::camera::Window;
use crate::image::Image;
use crate::loss;
use crate::presets::RenderSettings;
use crate::{Error, Real, Result};

/// Weights of the three loss terms; 0 turns a term off.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LossWeights {
    /// Weight of the mean absolute error between render and target.
    pub l1: f64,
    /// Weight of the edge-aware smoothness of the disparity.
    pub smoothness: f64,
    /// Weight of HSSIM (sum over windows 3..31 of 1 - SSIM).
    pub hssim: f64,
}

impl LossWeights {
    /// The published training configuration: L1 0.5, smoothness 0.5, HSSIM 10.
    pub const PAPER: LossWeights = LossWeights {
        l1: 0.5,
        smoothness: 0.5,
        hssim: 10.0,
    };

    /// Keeps the paper's weights for the named terms (`l1`, `smooth`, `ssim11`... see
    /// [`LossTerms`]) and zeroes the others.
    pub fn from_terms(terms: &str) -> Result<(Self, LossTerms)> {
        let mut w = LossWeights {
            l1: 0.0,
            smoothness: 0.0,
            hssim: 0.0,
        };
        let mut single_ssim = false;
        for t in terms.split(',').map(str::trim) {
            match t {
                "l1" => w.l1 = Self::PAPER.l1,
                "smooth" | "smoothness" | "g" => w.smoothness = Self::PAPER.smoothness,
                "hssim" => w.hssim = Self::PAPER.hssim,
                "ssim" => {
                    // A single 11-window SSIM with the same total weight as HSSIM's five.
                    w.hssim = Self::PAPER.hssim;
                    single_ssim = true;
                }
                _ => {
                    return Err(Error::param(
                        "--losses",
                        format!("unknown loss term '{t}' (use l1, smooth, ssim, hssim)"),
                    ))
                }
            }
        }
        if w.l1 == 0.0 && w.smoothness == 0.0 && w.hssim == 0.0 {
            return Err(Error::param("--losses", "no loss term selected"));
        }
        Ok((
            w,
            if single_ssim {
                LossTerms::SingleSsim
            } else {
                LossTerms::Hssim
            },
        ))
    }
}

/// Which structural term the `hssim` weight applies to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum LossTerms {
    /// HSSIM over windows 3, 5, 11, 21, 31.
    Hssim,
    /// One SSIM with an 11-window, scaled by 5 (as many terms as HSSIM has).
    SingleSsim,
}

/// Options of one depth-from-defocus run.
#[derive(Clone, Debug)]
pub struct DfdOptions {
    /// Camera of the defocused image (focus, K, gamma); the window is chosen per scale.
    pub settings: RenderSettings,
    /// Rendering layer to optimise through.
    pub layer: RenderLayer,
    /// Loss weights.
    pub weights: LossWeights,
    /// Structural term.
    pub terms: LossTerms,
    /// Adam iterations per scale.
    pub iterations: usize,
    /// Adam learning rate (disparity units per step, roughly).
    pub learning_rate: f64,
    /// Number of scales (1 = full resolution only).
    pub scales: usize,
    /// Initial disparity everywhere.
    pub init: f64,
    /// Engine of the Dr.Bokeh layer's forward and adjoint ([`crate::render_with_tape_on`]);
    /// default [`crate::Engine::Threaded`] (the exact gradient).
    pub engine: crate::Engine,
}

impl DfdOptions {
    /// Defaults: paper weights with HSSIM, 200 iterations per scale, learning rate 0.02,
    /// 2 scales, initial disparity 0.5.
    pub fn new(settings: RenderSettings, layer: RenderLayer) -> Self {
        DfdOptions {
            settings,
            layer,
            weights: LossWeights::PAPER,
            terms: LossTerms::Hssim,
            iterations: 200,
            learning_rate: 0.02,
            scales: 2,
            init: 0.5,
            engine: crate::Engine::Threaded,
        }
    }
}

/// One line of the loss curve.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LogEntry {
    /// Scale (0 = full resolution).
    pub scale: usize,
    /// Iteration within the scale.
    pub iteration: usize,
    /// Weighted total loss.
    pub loss: f64,
    /// Unweighted L1 (null if off).
    pub l1: Option<f64>,
    /// Unweighted smoothness (null if off or the scale is too small).
    pub smoothness: Option<f64>,
    /// Unweighted structural term (null if off or the scale is too small).
    pub structure: Option<f64>,
}

fn upsample_nearest<T: Real>(img: &Image<T>, w: usize, h: usize) -> Image<T> {
    let mut out = Image::new(w, h, img.channels);
    for y in 0..h {
        for x in 0..w {
            let (sx, sy) = ((x / 2).min(img.width - 1), (y / 2).min(img.height - 1));
            for c in 0..img.channels {
                *out.at_mut(x, y, c) = img.at(sx, sy, c);
            }
        }
    }
    out
}

/// Estimates disparity from an all-in-focus image and a defocused image (both HxWx3,
/// display-encoded). `on_iteration` sees each log entry as it is made (for progress).
pub fn estimate_disparity<T: Real>(
    all_in_focus: &Image<T>,
    defocused: &Image<T>,
    options: &DfdOptions,
    on_iteration: &mut dyn FnMut(&LogEntry),
) -> Result<(Image<T>, Vec<LogEntry>)> {
    if all_in_focus.channels != 3 || defocused.channels != 3 {
        return Err(Error::input(
            "depth from defocus",
            "both images must have 3 channels",
        ));
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
    all_in_focus.check_finite("all-in-focus image")?;
    defocused.check_finite("defocused image")?;
    options.settings.validate()?;
    if options.scales == 0 || options.scales > 8 {
        return Err(Error::param("--scales", "must be between 1 and 8"));
    }
    if !(options.learning_rate > 0.0 && options.learning_rate.is_finite()) {
        return Err(Error::param("--lr", "learning rate must be positive"));
    }
    let mut aifs = vec![all_in_focus.clone()];
    let mut targets = vec![defocused.clone()];
    for _ in 1..options.scales {
        let (a, t) = (aifs.last().unwrap(), targets.last().unwrap());
        if a.width < 4 || a.height < 4 {
            break;
        }
        aifs.push(loss::pyramid::avg_pool2(a)?);
        targets.push(loss::pyramid::avg_pool2(t)?);
    }
    let coarsest = aifs.last().unwrap();
    let mut disparity = Image::from_vec(
        coarsest.width,
        coarsest.height,
        1,
        vec![T::c(options.init); coarsest.width * coarsest.height],
    )?;
    let mut log = Vec::new();
    for scale in (0..aifs.len()).rev() {
        let (aif, target) = (&aifs[scale], &targets[scale]);
        if disparity.width != aif.width || disparity.height != aif.height {
            disparity = upsample_nearest(&disparity, aif.width, aif.height);
        }
        let mut settings = options.settings.clone();
        settings.camera.blur_k = options.settings.camera.blur_k / (1u64 << scale) as f64;
        let f = settings.camera.focus_disparity;
        settings.camera.window = Window::auto(settings.camera.blur_k * f.max(1.0 - f) + 1.0);
        let min_side = aif.width.min(aif.height);
        let use_structure = options.weights.hssim > 0.0 && min_side >= 31;
        let use_smooth = options.weights.smoothness > 0.0 && min_side >= 16;
        let n = disparity.data.len();
        let (mut m, mut v) = (vec![0.0f64; n], vec![0.0f64; n]);
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8);
        for it in 0..options.iterations {
            let mut entry = LogEntry {
                scale,
                iteration: it,
                loss: 0.0,
                l1: None,
                smoothness: None,
                structure: None,
            };
            let weights = options.weights;
            let terms = options.terms;
            let (_, mut grad) = render_layer_vjp_on(
                options.layer,
                options.engine,
                aif,
                &disparity,
                &settings,
                |render: &Image<T>| {
                    let mut g = Image::new(render.width, render.height, 3);
                    if weights.l1 > 0.0 {
                        let (val, gl) = loss::l1_grad(render, target)?;
                        entry.l1 = Some(val.f64());
                        entry.loss += weights.l1 * val.f64();
                        for (a, b) in g.data.iter_mut().zip(&gl.data) {
                            *a = *a + T::c(weights.l1) * *b;
                        }
                    }
                    if use_structure {
                        let (val, gs) = match terms {
                            LossTerms::Hssim => loss::hssim_grad(render, target)?,
                            LossTerms::SingleSsim => {
                                let (s, gs) =
                                    loss::ssim_grad(render, target, &loss::SsimWindow::sized(11)?)?;
                                let k = T::c(loss::HSSIM_WINDOWS.len() as f64);
                                (
                                    k * (T::one() - s),
                                    Image {
                                        data: gs.data.iter().map(|&v| -k * v).collect(),
                                        ..gs
                                    },
                                )
                            }
                        };
                        entry.structure = Some(val.f64());
                        entry.loss += weights.hssim * val.f64();
                        for (a, b) in g.data.iter_mut().zip(&gs.data) {
                            *a = *a + T::c(weights.hssim) * *b;
                        }
                    }
                    Ok(g)
                },
            )?;
            if use_smooth {
                let (val, gs) = loss::edge_aware_smoothness_grad(&disparity, aif)?;
                entry.smoothness = Some(val.f64());
                entry.loss += options.weights.smoothness * val.f64();
                for (a, b) in grad.data.iter_mut().zip(&gs.data) {
                    *a = *a + T::c(options.weights.smoothness) * *b;
                }
            }
            on_iteration(&entry);
            log.push(entry);
            let t = (it + 1) as i32;
            for i in 0..n {
                let g = grad.data[i].f64();
                m[i] = b1 * m[i] + (1.0 - b1) * g;
                v[i] = b2 * v[i] + (1.0 - b2) * g * g;
                let (mh, vh) = (m[i] / (1.0 - b1.powi(t)), v[i] / (1.0 - b2.powi(t)));
                let step = options.learning_rate * mh / (vh.sqrt() + eps);
                disparity.data[i] = T::c((disparity.data[i].f64() - step).clamp(0.0, 1.0));
            }
        }
    }
    Ok((disparity, log))
}

/// Disparity error statistics against ground truth.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct DisparityErrors {
    /// Mean absolute error.
    pub mae: f64,
    /// Root mean squared error.
    pub rmse: f64,
    /// Fraction of pixels with `max(est/gt, gt/est) < 1.25`.
    pub within_1_25: f64,
}

/// Compares an estimate with ground truth (same size, one channel).
pub fn disparity_errors<T: Real>(estimate: &Image<T>, truth: &Image<T>) -> DisparityErrors {
    let n = truth.data.len() as f64;
    let (mut abs, mut sq, mut ok) = (0.0, 0.0, 0.0);
    for (&e, &t) in estimate.data.iter().zip(&truth.data) {
        let (e, t) = (e.f64(), t.f64());
        abs += (e - t).abs();
        sq += (e - t) * (e - t);
        let ratio = if e > 0.0 && t > 0.0 {
            (e / t).max(t / e)
        } else {
            f64::INFINITY
        };
        if ratio < 1.25 {
            ok += 1.0;
        }
    }
    DisparityErrors {
        mae: abs / n,
        rmse: (sq / n).sqrt(),
        within_1_25: ok / n,
    }
}
