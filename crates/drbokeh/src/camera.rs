//! Camera controls: focus, blur strength, window, tone. Units are in the names:
//! `focus_disparity` is a normalised disparity, `blur_k` is pixels of blur radius per unit
//! of relative disparity, window sizes are in pixels.

use crate::model::HighlightBoost;
use crate::{Error, Result};

/// The largest window size `L` accepted (a guard: the reference cost grows with `L^2`).
pub const MAX_WINDOW_SIZE: usize = 1001;
/// The largest window size chosen automatically when the user gives none (the paper's demo
/// default). Larger blurs are clipped to this window unless `--window` asks for more.
pub const MAX_AUTO_WINDOW_SIZE: usize = 71;
/// Margin (pixels) added to the largest scatter radius when choosing a window automatically:
/// the soft step `S` has fallen to about 1e-5 at `dist = r + 3`.
pub const AUTO_WINDOW_MARGIN_PX: f64 = 3.0;

/// How far an automatic window may grow ([`Window::automatic`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WindowCap {
    /// At most [`MAX_AUTO_WINDOW_SIZE`]: larger blurs are clipped (engines whose cost grows
    /// with `L^2`).
    Clipped,
    /// At most [`MAX_WINDOW_SIZE`] (engines whose cost follows the blur radii).
    Unclipped,
}

/// The square neighbourhood `L x L` (`L = 2R + 1`, odd) over which each receiver gathers.
/// The aperture mask additionally requires `dist < R`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    radius_px: usize,
}

impl Window {
    /// A window of odd size `L` (3 <= L <= [`MAX_WINDOW_SIZE`]).
    pub fn from_size(size: usize) -> Result<Self> {
        if size % 2 == 0 {
            return Err(Error::param(
                "window",
                format!("window size must be odd (L = 2R + 1), got {size}"),
            ));
        }
        if !(3..=MAX_WINDOW_SIZE).contains(&size) {
            return Err(Error::param(
                "window",
                format!("window size must be between 3 and {MAX_WINDOW_SIZE}, got {size}"),
            ));
        }
        Ok(Window {
            radius_px: size / 2,
        })
    }

    /// The automatic window: the smallest that holds a scatter radius of `max_radius_px`
    /// plus [`AUTO_WINDOW_MARGIN_PX`], at least `R = 1`, capped as `cap` says. The one rule
    /// every automatic window follows (front ends, evaluation, gallery, benchmarks;
    /// equation M22 of docs/model.md, with [`crate::model::automatic_window`]).
    pub fn automatic(max_radius_px: f64, cap: WindowCap) -> Self {
        let r = (max_radius_px + AUTO_WINDOW_MARGIN_PX).ceil().max(1.0) as usize;
        let cap = match cap {
            WindowCap::Clipped => MAX_AUTO_WINDOW_SIZE,
            WindowCap::Unclipped => MAX_WINDOW_SIZE,
        };
        Window {
            radius_px: r.min(cap / 2),
        }
    }

    /// [`Window::automatic`] capped at [`MAX_AUTO_WINDOW_SIZE`].
    pub fn auto(max_radius_px: f64) -> Self {
        Window::automatic(max_radius_px, WindowCap::Clipped)
    }

    /// [`Window::automatic`] capped at [`MAX_WINDOW_SIZE`]: for engines whose cost follows
    /// the actual blur radii (the fast engine), no clipping in practice.
    pub fn auto_unclipped(max_radius_px: f64) -> Self {
        Window::automatic(max_radius_px, WindowCap::Unclipped)
    }

    /// When this (automatic) window clips a blur of scatter radius `max_radius_px` (plus
    /// the margin): the window size that would hold it.
    pub fn clips(&self, max_radius_px: f64) -> Option<usize> {
        let needed = max_radius_px + AUTO_WINDOW_MARGIN_PX;
        (needed > self.radius_px as f64 + 0.5).then(|| 2 * needed.ceil() as usize + 1)
    }

    /// `R`, the half-size in pixels.
    pub fn radius_px(&self) -> usize {
        self.radius_px
    }

    /// `L = 2R + 1`.
    pub fn size(&self) -> usize {
        2 * self.radius_px + 1
    }
}

/// Everything the model needs to know about the camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Focus disparity `f` in [0, 1]: the normalised disparity that is in focus.
    pub focus_disparity: f64,
    /// Blur strength `K`: blur radius in pixels per unit of relative disparity (>= 0).
    pub blur_k: f64,
    /// The gather window.
    pub window: Window,
    /// Gamma `g` of the display encoding (`linear = (encoded + offset)^g`).
    pub gamma: f64,
    /// Offset of the display encoding.
    pub offset: f64,
    /// The highlight boost before linearisation, if on (docs/model.md, M20;
    /// [`HighlightBoost::PAPER`] is the paper's).
    pub highlight: Option<HighlightBoost>,
}

impl Camera {
    /// The paper's defaults (K = 30, L = 71, gamma 2.2, no offset, no highlight boost)
    /// focused at `focus_disparity`.
    pub fn paper_default(focus_disparity: f64) -> Self {
        Camera {
            focus_disparity,
            blur_k: 30.0,
            window: Window::from_size(71).unwrap(),
            gamma: 2.2,
            offset: 0.0,
            highlight: None,
        }
    }

    /// Checks every field's range; messages name the parameters (`focus`, `blur`, ...).
    pub fn validate(&self) -> Result<()> {
        let f = self.focus_disparity;
        if !f.is_finite() || !(0.0..=1.0).contains(&f) {
            return Err(Error::param(
                "focus",
                format!("focus disparity must be in [0, 1], got {f}"),
            ));
        }
        if !self.blur_k.is_finite() || self.blur_k < 0.0 || self.blur_k > 10_000.0 {
            return Err(Error::param(
                "blur",
                format!("blur strength K must be in [0, 10000], got {}", self.blur_k),
            ));
        }
        if !self.gamma.is_finite() || self.gamma <= 0.0 || self.gamma > 10.0 {
            return Err(Error::param(
                "gamma",
                format!("gamma must be in (0, 10], got {}", self.gamma),
            ));
        }
        if !self.offset.is_finite() || !(0.0..=1.0).contains(&self.offset) {
            return Err(Error::param(
                "offset",
                format!("offset must be in [0, 1], got {}", self.offset),
            ));
        }
        if let Some(boost) = &self.highlight {
            boost.validate()?;
        }
        Ok(())
    }
}
