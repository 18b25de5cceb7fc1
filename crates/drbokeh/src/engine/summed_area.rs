//! Summed-area tables, built in parallel: shared by the adjoints' box coverage (f64 sums of
//! gradients) and the span adjoint's receiver sets (u32 counts).

use rayon::prelude::*;
use std::ops::Add;

/// Fills `table` (`(h + 1) x (w + 1)`, row-major) with the summed-area table of
/// `value(x, y)` over a `w x h` image: entry `(y + 1, x + 1)` is the sum over rows `..= y`
/// and columns `..= x`. The first row and column are not written (they hold the table's
/// zeros). Each row's prefix sums are taken in parallel, then each row adds the one above:
/// the same sums, in the same order per entry, as a row-by-row build.
pub(crate) fn fill_summed_area<V>(
    table: &mut [V],
    w: usize,
    h: usize,
    value: impl Fn(usize, usize) -> V + Sync,
) where
    V: Copy + Add<Output = V> + Send + Sync,
{
    let s1 = w + 1;
    assert_eq!(table.len(), (h + 1) * s1, "summed-area table shape");
    table[s1..]
        .par_chunks_mut(s1)
        .enumerate()
        .for_each(|(y, row)| {
            for x in 0..w {
                row[x + 1] = row[x] + value(x, y);
            }
        });
    for y in 1..h {
        let (above, row) = table.split_at_mut((y + 1) * s1);
        for (v, &a) in row[..s1].iter_mut().zip(&above[y * s1..]) {
            *v = *v + a;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_plain_double_sum() {
        let (w, h) = (7, 5);
        let value = |x: usize, y: usize| ((x * 31 + y * 17) % 11) as u32;
        let mut table = vec![0u32; (h + 1) * (w + 1)];
        fill_summed_area(&mut table, w, h, value);
        for y in 0..=h {
            for x in 0..=w {
                let plain: u32 = (0..y)
                    .flat_map(|yy| (0..x).map(move |xx| (xx, yy)))
                    .map(|(xx, yy)| value(xx, yy))
                    .sum();
                assert_eq!(table[y * (w + 1) + x], plain, "({x}, {y})");
            }
        }
    }
}
