//! The fast schedule's vectorisable runs over contiguous taps, shared by its forward and
//! adjoint: branch-free bodies whose per-tap terms all come from the model, summed in
//! [`LANES`] fixed lanes (so the order, and the bytes, do not depend on threads or on the
//! vector width).

use super::tiles::WindowTables;
use crate::engine::planes::Planes;
use crate::model::{self, ApertureEval, DiscCoverage, ScatterStep};
use crate::Real;

/// Calls `add(lane, i)` for every `i in 0..m` with `lane = i % LANES`, in order of `i`:
/// the full groups of [`LANES`] first (a loop the compiler vectorises), then the rest.
/// Summing `x[i]` into `lanes[lane]` this way fixes the order of every float sum, so the
/// result does not depend on the vector width.
#[inline(always)]
pub(super) fn for_each_lane(m: usize, mut add: impl FnMut(usize, usize)) {
    let full = m / LANES * LANES;
    for base in (0..full).step_by(LANES) {
        for l in 0..LANES {
            add(l, base + l);
        }
    }
    for i in full..m {
        add(i - full, i);
    }
}

/// Sum of [`LANES`] partial sums, in lane order.
#[inline(always)]
pub(super) fn lane_sum<T: Real>(v: &[T; LANES]) -> T {
    v.iter().fold(T::zero(), |a, &b| a + b)
}

/// Accumulator lanes of the gather run: independent partial sums that the compiler can
/// keep in one SIMD register each (float sums cannot be reordered otherwise).
pub(super) const LANES: usize = 8;

/// One tap's weight `c(y,x)` in the fast engine's form; `OCCLUDING = false` means `O = 1`;
/// `SHARP` selects [`ScatterStep::Sharp`] (else the paper's step).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn tap_weight_fast<T: Real, const OCCLUDING: bool, const SHARP: bool>(
    alpha: T,
    radius: T,
    gauge: T,
    inv_area: T,
    disp: T,
    d_x: T,
    e_x: T,
) -> T {
    let s = if SHARP {
        model::sharp_step_fast(radius - gauge)
    } else {
        model::soft_step_fast(radius - gauge)
    };
    let o = if OCCLUDING {
        model::occlusion_fast(e_x, disp, d_x)
    } else {
        T::one()
    };
    model::tap_weight_inv_area(alpha, s, inv_area, o)
}

/// Taps per chunk of the gather run: weights are first computed for a chunk into a
/// scratch array (a plain map, which the compiler vectorises), then reduced in lanes.
pub(super) const CHUNK: usize = 64;

/// Sums `c(y,x) Ilin(y)` and `c(y,x)` over a contiguous run of `n` sources starting at
/// padded index `lo`, with the run's gauges, in [`LANES`] lanes.
#[inline(always)]
fn gather_run_lanes<T: Real, const OCCLUDING: bool, const SHARP: bool>(
    b: &Planes<T>,
    lo: usize,
    n: usize,
    gauge: &[T],
    d_x: T,
    e_x: T,
) -> ([T; 3], T) {
    let (mut lr, mut lg, mut lb, mut lw) = (
        [T::zero(); LANES],
        [T::zero(); LANES],
        [T::zero(); LANES],
        [T::zero(); LANES],
    );
    let mut c = [T::zero(); CHUNK];
    let mut start = 0;
    while start < n {
        let m = (n - start).min(CHUNK);
        let s0 = lo + start;
        let (alpha, radius, inv_area, disp) = (
            &b.alpha[s0..s0 + m],
            &b.radius[s0..s0 + m],
            &b.inv_area[s0..s0 + m],
            &b.rel_disp[s0..s0 + m],
        );
        let g = &gauge[start..start + m];
        for i in 0..m {
            c[i] = tap_weight_fast::<T, OCCLUDING, SHARP>(
                alpha[i],
                radius[i],
                g[i],
                inv_area[i],
                disp[i],
                d_x,
                e_x,
            );
        }
        let (red, green, blue) = (
            &b.red[s0..s0 + m],
            &b.green[s0..s0 + m],
            &b.blue[s0..s0 + m],
        );
        // Lane l sums the taps i with i % LANES == l (CHUNK is a multiple of LANES).
        for_each_lane(m, |l, i| {
            lr[l] = lr[l] + c[i] * red[i];
            lg[l] = lg[l] + c[i] * green[i];
            lb[l] = lb[l] + c[i] * blue[i];
            lw[l] = lw[l] + c[i];
        });
        start += m;
    }
    ([lane_sum(&lr), lane_sum(&lg), lane_sum(&lb)], lane_sum(&lw))
}

/// The sums `sum c Ilin` and `sum c` of the run of `n` taps of window row `dy` from offset
/// `dx0` (padded index `lo` of the first source), for any aperture: [`gather_run`] in
/// lanes for circle and polygon ([`gather_run_lanes`], branch-free, vectorisable; the lane
/// order is fixed, so results do not depend on threads); for kernel apertures, the model's
/// scalar scatter term.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn gather_segment<T: Real>(
    b: &Planes<T>,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    lo: usize,
    n: usize,
    (dx0, dy): (isize, isize),
    d_x: T,
    e_x: T,
    occluding: bool,
) -> ([T; 3], T) {
    let big_r = tables.big_r as isize;
    if let ApertureEval::Gauge = aperture {
        let (t, g0) = ((dy + big_r) as usize, (dx0 + big_r) as usize);
        let gauge = &tables.gauge[t][g0..g0 + n];
        // The step shape and occlusion are loop-invariant: one monomorphised loop each
        // (direct calls, so that each is inlined into its AVX2 or baseline caller).
        return match (b.step, occluding) {
            (ScatterStep::Paper, true) => {
                gather_run_lanes::<T, true, false>(b, lo, n, gauge, d_x, e_x)
            }
            (ScatterStep::Paper, false) => {
                gather_run_lanes::<T, false, false>(b, lo, n, gauge, d_x, e_x)
            }
            (ScatterStep::Sharp, true) => {
                gather_run_lanes::<T, true, true>(b, lo, n, gauge, d_x, e_x)
            }
            (ScatterStep::Sharp, false) => {
                gather_run_lanes::<T, false, true>(b, lo, n, gauge, d_x, e_x)
            }
        };
    }
    let (mut acc, mut sw) = ([T::zero(); 3], T::zero());
    for i in 0..n {
        let yi = lo + i;
        let a = b.alpha[yi];
        if a == T::zero() {
            continue;
        }
        let dx = dx0 + i as isize;
        let (s, _) = tables.scatter_at::<false>(b.step, aperture, (dx, dy), b.radius[yi]);
        let o = if occluding {
            model::occlusion_fast(e_x, b.rel_disp[yi], d_x)
        } else {
            T::one()
        };
        let c = model::tap_weight_inv_area(a, s, b.inv_area[yi], o);
        acc[0] = acc[0] + c * b.red[yi];
        acc[1] = acc[1] + c * b.green[yi];
        acc[2] = acc[2] + c * b.blue[yi];
        sw = sw + c;
    }
    (acc, sw)
}

/// How a run's lanes are added into the soft-disc sums: the render adds each lane to the
/// running sums in turn; the adjoint adds the lanes' total (the two round differently, and
/// each has its own tested bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum LaneReduction {
    /// `sum = ((sum + l0) + l1) + ...`.
    EachLane,
    /// `sum = sum + (((0 + l0) + l1) + ...)`.
    Total,
}

/// The soft-disc coverage sums ([`DiscCoverage`]) at padded receiver `xi`, over the taps
/// of each row within `reach` of the receiver, for a disc of radius `r_c` (`dr` =
/// `dr_c/dr(x)`); with `DERIV`, also the derivative sums. Returns the sums and the taps
/// visited. Circle and polygon run in lanes; kernel apertures use the model's scalar
/// scatter term.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(super) fn disc_sums<T: Real, const DERIV: bool>(
    src: &Planes<T>,
    tables: &WindowTables<T>,
    aperture: &ApertureEval<T>,
    xi: usize,
    (r_c, dr): (T, T),
    reach: f64,
    reduction: LaneReduction,
) -> (DiscCoverage<T>, u64) {
    let big_r = tables.big_r as isize;
    let mut disc = DiscCoverage::<T>::default();
    let mut taps = 0u64;
    for dy in -big_r..=big_r {
        let Some(hw) = tables.half_width(dy, reach) else {
            continue;
        };
        let row = (xi as isize + dy * src.stride as isize) as usize;
        let t = (dy + big_r) as usize;
        let g0 = tables.big_r - hw;
        let n = 2 * hw + 1;
        taps += n as u64;
        let alpha = &src.alpha[row - hw..row - hw + n];
        let gauge = &tables.gauge[t][g0..g0 + n];
        match aperture {
            ApertureEval::Gauge => {
                let mut lanes = [[T::zero(); LANES]; 4];
                for i in 0..n {
                    let s = model::scatter_step_fast(src.step, r_c - gauge[i]);
                    let l = i % LANES;
                    lanes[0][l] = lanes[0][l] + s * alpha[i];
                    lanes[1][l] = lanes[1][l] + s;
                    if DERIV {
                        let ds = model::scatter_step_derivative(src.step, s) * dr;
                        lanes[2][l] = lanes[2][l] + ds * alpha[i];
                        lanes[3][l] = lanes[3][l] + ds;
                    }
                }
                match reduction {
                    LaneReduction::EachLane => {
                        for l in 0..LANES {
                            disc.alpha_sum = disc.alpha_sum + lanes[0][l];
                            disc.weight = disc.weight + lanes[1][l];
                            if DERIV {
                                disc.d_alpha_sum = disc.d_alpha_sum + lanes[2][l];
                                disc.d_weight = disc.d_weight + lanes[3][l];
                            }
                        }
                    }
                    LaneReduction::Total => {
                        disc.alpha_sum = disc.alpha_sum + lane_sum(&lanes[0]);
                        disc.weight = disc.weight + lane_sum(&lanes[1]);
                        if DERIV {
                            disc.d_alpha_sum = disc.d_alpha_sum + lane_sum(&lanes[2]);
                            disc.d_weight = disc.d_weight + lane_sum(&lanes[3]);
                        }
                    }
                }
            }
            ApertureEval::Kernel(..) => {
                for i in 0..n {
                    let dx = i as isize - hw as isize;
                    let (s, ds) = tables.scatter_at::<DERIV>(src.step, aperture, (dx, dy), r_c);
                    if DERIV {
                        disc.add_with_derivative(s, ds * dr, alpha[i]);
                    } else {
                        disc.add(s, alpha[i]);
                    }
                }
            }
        }
    }
    (disc, taps)
}

/// The scatter term of the centre tap and its derivative with respect to `r`.
#[inline(always)]
pub(super) fn centre_scatter<T: Real>(
    step: ScatterStep,
    aperture: &ApertureEval<T>,
    r: T,
) -> (T, T) {
    match aperture {
        ApertureEval::Gauge => {
            let s = model::scatter_step_fast(step, r);
            (s, model::scatter_step_derivative(step, s))
        }
        ApertureEval::Kernel(..) => {
            model::scatter_term_and::<T, true>(step, aperture, 0, 0, T::zero(), T::zero(), r)
        }
    }
}
