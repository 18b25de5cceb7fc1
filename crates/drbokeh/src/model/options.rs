//! The replaceable terms of the model: one enum per term, and [`ModelOptions`], one field
//! per term. The presets (`crate::presets`) are named choices of these; each variant's
//! formula lives beside its derivative in the sibling modules (docs/model.md, "Presets").

/// How the layer coverage `o_l(x)` is computed.
/// Equations M15, M16 of docs/model.md.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Coverage {
    /// The paper: mean of alpha over the square of half-size `min(floor(r(x)/2), R)`.
    PaperBox,
    /// Alpha averaged over the receiver's own soft aperture:
    /// `o(x) = sum_y M S(r(x), y) a(y) / sum_y M S(r(x), y)` (same S, M and aperture as
    /// the scatter term, radius of the receiver). Continuous in `r(x)`.
    SoftDisc,
}

/// The radius of the receiver's disc in [`Coverage::SoftDisc`].
/// Equation M16 of docs/model.md.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CoverageRadius {
    /// The receiver's scatter radius `r(x) = K |d(x)| + 1` (the scatter term's radius).
    Scatter,
    /// The circle of confusion alone, `K |d(x)|` (no `+1` pixel footprint), so that an
    /// in-focus receiver's coverage is (nearly) its own alpha.
    CircleOfConfusion,
}

/// The pixel footprint added to the circle of confusion in the scatter radius
/// `r = K |d| + footprint` (docs/model.md, M2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Footprint {
    /// The paper's `+1`.
    Pixel,
    /// `+0.5`: half the pixel pitch. The soft step `S(r - dist)` is 1/2 at
    /// `dist = r - ln(10)/3 = r - 0.77`, so even `+1` already gives in-focus pixels a soft
    /// edge; the benchmark prefers the smaller footprint (docs/physical.md).
    HalfPixel,
    /// `+0`: the scatter radius is the circle of confusion itself, `r = K |d|`. Needs
    /// [`ScatterStep::Sharp`], whose source area stays finite at `r = 0`.
    Point,
}

impl Footprint {
    /// The largest footprint of any variant ([`Footprint::Pixel`]), in pixels.
    /// Equation M2 of docs/model.md.
    pub const LARGEST_PX: f64 = 1.0;

    /// The footprint in pixels.
    /// Equation M2 of docs/model.md.
    pub fn px(self) -> f64 {
        match self {
            Footprint::Pixel => 1.0,
            Footprint::HalfPixel => 0.5,
            Footprint::Point => 0.0,
        }
    }
}

/// The soft step `S(r - dist)` of the scatter term and the source area it is normalised by
/// (formulas in [`crate::model::scatter_step`] and [`crate::model::source_area`]).
/// Equations M3, M4, M7 of docs/model.md.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ScatterStep {
    /// The supplement's eq. 2, `S = 1 / (1 + 10 exp(-3 (r - dist)))`, with area `r^2`. Its
    /// half-weight point is at `dist = r - ln(10)/3 = r - 0.77`: a disc 0.77 px smaller
    /// than `r`, and a 10-90 % ramp 1.5 px wide that blurs in-focus pixels.
    Paper,
    /// Centred on the circle of confusion with a one-pixel ramp,
    /// `S = 1 / (1 + exp(-6 (r - dist)))` (half weight at `dist = r`, 10-90 % over
    /// 0.73 px, about a pixel's own width), normalised by the step's own area
    /// `pi r^2 + 1/2` (a disc of radius r; 1/2 at `r = 0`, where the centre pixel keeps
    /// half weight and its neighbours 0.25 %), so every source spreads the same energy.
    Sharp,
}

/// The display transfer used to linearise inputs and encode the output.
/// Equations M18, M19 of docs/model.md.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Transfer {
    /// The paper: `lin = (I + offset)^g` with the camera's gamma and offset.
    Gamma,
    /// The exact sRGB curve (IEC 61966-2-1); the camera's gamma and offset are not used.
    Srgb,
}

/// The replaceable terms of the model, one field per term.
/// Section "Presets" of docs/model.md.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ModelOptions {
    /// Layer coverage term.
    pub coverage: Coverage,
    /// Radius of the soft-disc coverage (unused by [`Coverage::PaperBox`]).
    pub coverage_radius: CoverageRadius,
    /// Display transfer.
    pub transfer: Transfer,
    /// Pixel footprint in the scatter radius.
    pub footprint: Footprint,
    /// Shape of the scatter term's soft step and its area normalisation.
    pub step: ScatterStep,
}

impl ModelOptions {
    /// The published model's choices.
    /// Section "Presets" of docs/model.md.
    pub const PAPER: ModelOptions = ModelOptions {
        coverage: Coverage::PaperBox,
        coverage_radius: CoverageRadius::Scatter,
        transfer: Transfer::Gamma,
        footprint: Footprint::Pixel,
        step: ScatterStep::Paper,
    };
    /// The `physical` preset's choices.
    /// Section "Presets" of docs/model.md.
    pub const PHYSICAL: ModelOptions = ModelOptions {
        coverage: Coverage::SoftDisc,
        coverage_radius: CoverageRadius::CircleOfConfusion,
        transfer: Transfer::Gamma,
        footprint: Footprint::Point,
        step: ScatterStep::Sharp,
    };
}
