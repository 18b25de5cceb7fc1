//! The greedy searches: whole segments to a neighbour's value, then single boundary pixels
//! to a neighbour's value, each move kept where the judge's loss on the crop it can reach
//! falls.
use crate::judge::Judge;
use crate::segments::{crop, distinct_moves, median, neighbours4, Segments};
use drbokeh::dfd::disparity_errors;
use drbokeh::Image;
use std::time::Instant;

/// What the moves are judged against, and how.
pub struct Search<'a> {
    pub judge: &'a Judge<'a>,
    /// The traced defocused image.
    pub target: &'a Image<f32>,
    /// How far (px) a changed pixel's light can reach: the largest blur radius plus 2.
    pub reach_px: usize,
    /// A move is kept only if it lowers the loss by this fraction.
    pub gain: f64,
    /// Moves closer than this to the current value (or to each other) are not proposed.
    pub mindiff: f32,
}

impl Search<'_> {
    /// The crop a change of the pixels a..=b (along one axis of length n) can reach, at
    /// least 40 px (HSSIM's largest window is 31).
    fn grow(&self, a: usize, b: usize, n: usize) -> (usize, usize) {
        let lo = a.saturating_sub(2 * self.reach_px);
        let hi = (b + 2 * self.reach_px + 1).min(n);
        let lo = if hi - lo < 40 {
            hi.saturating_sub(40)
        } else {
            lo
        };
        let hi = if hi - lo < 40 { (lo + 40).min(n) } else { hi };
        (lo, hi)
    }

    /// The best of `cands` for the pixels `pixels` (all set to one value), judged on the
    /// crop every pixel the change can reach lies in; `None` where none lowers the loss by
    /// the fraction `gain`. The one move of both searches.
    fn best_move(&self, cur: &Image<f32>, pixels: &[usize], cands: &[f32]) -> Option<f32> {
        if cands.is_empty() {
            return None;
        }
        let (base, losses) = self.losses(cur, pixels, cands);
        let mut best = (base * (1.0 - self.gain), None);
        for (&c, l) in cands.iter().zip(losses) {
            if l < best.0 {
                best = (l, Some(c));
            }
        }
        best.1
    }

    /// The loss of the crop that setting `pixels` to a value can reach: as it is, and with
    /// the pixels set to each of `cands`.
    pub fn losses(&self, cur: &Image<f32>, pixels: &[usize], cands: &[f32]) -> (f64, Vec<f64>) {
        let (w, h) = (cur.width, cur.height);
        let (mut x0, mut y0, mut x1, mut y1) = (w, h, 0, 0);
        for &i in pixels {
            x0 = x0.min(i % w);
            x1 = x1.max(i % w);
            y0 = y0.min(i / w);
            y1 = y1.max(i / w);
        }
        let (cx0, cx1) = self.grow(x0, x1, w);
        let (cy0, cy1) = self.grow(y0, y1, h);
        let (cw, ch) = (cx1 - cx0, cy1 - cy0);
        let a = crop(&self.judge.aif, cx0, cy0, cw, ch);
        let tg = crop(self.target, cx0, cy0, cw, ch);
        let base_d = crop(cur, cx0, cy0, cw, ch);
        let base = self.judge.loss(&a, &base_d, &tg, cx0, cy0);
        let losses = cands
            .iter()
            .map(|&c| {
                let mut d = base_d.clone();
                for &i in pixels {
                    let (x, y) = (i % w - cx0, i / w - cy0);
                    d.data[y * cw + x] = c;
                }
                self.judge.loss(&a, &d, &tg, cx0, cy0)
            })
            .collect();
        (base, losses)
    }

    /// `sweeps` passes over the segments: each is proposed the median of each neighbour
    /// that differs from its own median. Returns (proposals, moves kept).
    pub fn segments(&self, cur: &mut Image<f32>, segs: &Segments, sweeps: usize) -> (usize, usize) {
        let (mut tried, mut kept) = (0, 0);
        let med = |cur: &Image<f32>, k: usize| {
            median(segs.members[k].iter().map(|&i| cur.data[i]).collect())
        };
        for _ in 0..sweeps {
            for k in 0..segs.members.len() {
                if segs.members[k].is_empty() {
                    continue;
                }
                let cands = distinct_moves(
                    med(cur, k),
                    segs.nbrs[k].iter().map(|&n| med(cur, n)),
                    self.mindiff,
                );
                tried += cands.len();
                if let Some(c) = self.best_move(cur, &segs.members[k], &cands) {
                    kept += 1;
                    for &i in &segs.members[k] {
                        cur.data[i] = c;
                    }
                }
            }
        }
        (tried, kept)
    }

    /// Up to `passes` passes of one-pixel moves along the boundaries (a pixel whose
    /// 4-neighbour differs by more than `mindiff` is proposed that neighbour's value), so
    /// that a boundary can move a pixel at a time where moving whole segments cannot.
    /// Progress (with the MAE against `truth`) on stderr; a pass that moves nothing stops.
    pub fn pixels(&self, cur: &mut Image<f32>, passes: usize, truth: &Image<f32>, t0: Instant) {
        let (w, h) = (cur.width, cur.height);
        for pass in 0..passes {
            let (mut moved, mut proposed) = (0, 0);
            for i in 0..w * h {
                let cands = distinct_moves(
                    cur.data[i],
                    neighbours4(i, w, h).map(|n| cur.data[n]),
                    self.mindiff,
                );
                if cands.is_empty() {
                    continue;
                }
                proposed += 1;
                if proposed % 2000 == 0 {
                    eprintln!(
                        "  pixel pass {pass}: {proposed} proposed, {moved} moved, MAE {:.4} ({:.0}s)",
                        disparity_errors(cur, truth).mae,
                        t0.elapsed().as_secs_f64()
                    );
                }
                if let Some(c) = self.best_move(cur, &[i], &cands) {
                    moved += 1;
                    cur.data[i] = c;
                }
            }
            println!(
                "  pixel pass {pass}: {proposed} boundary pixels, {moved} moved, MAE {:.4} ({:.0}s)",
                disparity_errors(cur, truth).mae,
                t0.elapsed().as_secs_f64()
            );
            if moved == 0 {
                break;
            }
        }
    }
}
