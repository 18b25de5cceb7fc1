//! What the fast adjoint's passes over one layer share: the receivers' terms and upstream
//! gradients ([`Receivers`]) and the read-only state of the passes ([`Ctx`]).

use crate::engine::backward::ReceiverGrads;
use crate::engine::fast::tiles::{WindowTables, FOCUS_WEIGHT_CUTOFF};
use crate::engine::planes::Planes;
use crate::model::{self, ApertureEval};
use crate::presets::RenderSettings;
use crate::Real;
use rayon::prelude::*;

/// Shared read-only state of the passes over one layer.
pub(in crate::engine) struct Ctx<'a, T> {
    pub settings: &'a RenderSettings,
    pub tables: &'a WindowTables<T>,
    /// `gauge_flip[ddy + R][ddx + R]`: the gauge of the tap from source y to receiver
    /// `x = y + (ddx, ddy)`, i.e. of the offset `y - x = (-ddx, -ddy)`.
    pub gauge_flip: &'a [Vec<T>],
    pub aperture: &'a ApertureEval<T>,
    pub src: &'a Planes<T>,
    pub rcv: &'a Receivers<T>,
    /// Per receiver, the soft-disc coverage sums with derivatives (empty for the box).
    pub discs: &'a [model::DiscCoverage<T>],
    pub k: T,
}

/// One layer's receiver terms and upstream gradients, image-sized.
pub(in crate::engine) struct Receivers<T> {
    pub width: usize,
    pub height: usize,
    /// `dL/dC(x)` per channel and `dL/dW(x)`.
    pub g_red: Vec<T>,
    pub g_green: Vec<T>,
    pub g_blue: Vec<T>,
    pub g_weight: Vec<T>,
    /// `dL/do(x)`.
    pub g_coverage: Vec<T>,
    /// `e(x)`, set to 0 where it is below [`FOCUS_WEIGHT_CUTOFF`] (there the fast engine
    /// takes `O = 1`).
    pub focus_weight: Vec<T>,
    pub rel_disp: Vec<T>,
    pub radius: Vec<T>,
}

impl<T: Real> Receivers<T> {
    pub fn new(layer: &model::PreparedLayer<T>, rg: ReceiverGrads<T>) -> Self {
        let cutoff = T::c(FOCUS_WEIGHT_CUTOFF);
        let e: Vec<T> = layer
            .focus_weight
            .par_iter()
            .map(|&e| if e >= cutoff { e } else { T::zero() })
            .collect();
        let channel = |c: usize| rg.d_colour_sum.par_iter().map(|g| g[c]).collect();
        Receivers {
            width: layer.width,
            height: layer.height,
            g_red: channel(0),
            g_green: channel(1),
            g_blue: channel(2),
            g_weight: rg.d_weight_sum,
            g_coverage: rg.d_coverage,
            focus_weight: e,
            rel_disp: layer.rel_disp.clone(),
            radius: layer.radius_px.clone(),
        }
    }
}
