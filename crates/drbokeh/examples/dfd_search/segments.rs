//! The segments the search moves: SLIC superpixels of the all-in-focus image, their
//! adjacency, and the small helpers both searches share.
use drbokeh::Image;
use std::collections::BTreeSet;

pub fn crop(img: &Image<f32>, x0: usize, y0: usize, w: usize, h: usize) -> Image<f32> {
    let c = img.channels;
    let mut data = Vec::with_capacity(w * h * c);
    for y in y0..y0 + h {
        let row = (y * img.width + x0) * c;
        data.extend_from_slice(&img.data[row..row + w * c]);
    }
    Image::from_vec(w, h, c, data).unwrap()
}

/// The values of `values` that differ from `from` and from each other by more than
/// `mindiff`, in order: the moves a search proposes.
pub fn distinct_moves(from: f32, values: impl Iterator<Item = f32>, mindiff: f32) -> Vec<f32> {
    let mut cands: Vec<f32> = Vec::new();
    for m in values {
        if (m - from).abs() > mindiff && cands.iter().all(|c| (c - m).abs() > mindiff) {
            cands.push(m);
        }
    }
    cands
}

/// The 4-neighbours of pixel `i` of a `w` x `h` image: left, right, up, down.
pub fn neighbours4(i: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (x, y) = (i % w, i / w);
    [
        (x > 0).then(|| i - 1),
        (x + 1 < w).then(|| i + 1),
        (y > 0).then(|| i - w),
        (y + 1 < h).then(|| i + w),
    ]
    .into_iter()
    .flatten()
}

/// SLIC superpixels of an RGB image in [0, 1]; returns one label per pixel, connected.
pub fn slic(img: &Image<f32>, step: usize, compactness: f32) -> Vec<usize> {
    let (w, h) = (img.width, img.height);
    let mut centres: Vec<[f32; 5]> = Vec::new();
    let mut y = step / 2;
    while y < h {
        let mut x = step / 2;
        while x < w {
            let i = y * w + x;
            centres.push([
                x as f32,
                y as f32,
                img.data[3 * i],
                img.data[3 * i + 1],
                img.data[3 * i + 2],
            ]);
            x += step;
        }
        y += step;
    }
    let mut label = vec![0usize; w * h];
    let s2 = (step * step) as f32;
    let m2 = compactness * compactness;
    for _ in 0..10 {
        let mut best = vec![f32::INFINITY; w * h];
        for (k, c) in centres.iter().enumerate() {
            let (cx, cy) = (c[0] as isize, c[1] as isize);
            let r = step as isize;
            for yy in (cy - r).max(0)..(cy + r + 1).min(h as isize) {
                for xx in (cx - r).max(0)..(cx + r + 1).min(w as isize) {
                    let i = yy as usize * w + xx as usize;
                    let dc: f32 = (0..3)
                        .map(|j| (img.data[3 * i + j] - c[2 + j]).powi(2))
                        .sum();
                    let ds = (xx as f32 - c[0]).powi(2) + (yy as f32 - c[1]).powi(2);
                    let d = dc / m2 + ds / s2;
                    if d < best[i] {
                        best[i] = d;
                        label[i] = k;
                    }
                }
            }
        }
        let mut acc = vec![[0f64; 6]; centres.len()];
        for i in 0..w * h {
            let a = &mut acc[label[i]];
            a[0] += (i % w) as f64;
            a[1] += (i / w) as f64;
            for j in 0..3 {
                a[2 + j] += img.data[3 * i + j] as f64;
            }
            a[5] += 1.0;
        }
        for (c, a) in centres.iter_mut().zip(&acc) {
            if a[5] > 0.0 {
                for j in 0..5 {
                    c[j] = (a[j] / a[5]) as f32;
                }
            }
        }
    }
    // Connected components of the labels; fragments under 8 px join a neighbour.
    let mut comp = vec![usize::MAX; w * h];
    let mut n = 0;
    let mut sizes = Vec::new();
    for s in 0..w * h {
        if comp[s] != usize::MAX {
            continue;
        }
        let mut stack = vec![s];
        comp[s] = n;
        let mut size = 0;
        while let Some(i) = stack.pop() {
            size += 1;
            let (x, y) = (i % w, i / w);
            let mut push = |j: usize| {
                if comp[j] == usize::MAX && label[j] == label[s] {
                    comp[j] = n;
                    stack.push(j);
                }
            };
            if x > 0 {
                push(i - 1);
            }
            if x + 1 < w {
                push(i + 1);
            }
            if y > 0 {
                push(i - w);
            }
            if y + 1 < h {
                push(i + w);
            }
        }
        sizes.push(size);
        n += 1;
    }
    for i in 0..w * h {
        if sizes[comp[i]] < 8 {
            let (x, y) = (i % w, i / w);
            let nb = [
                (x > 0).then(|| i - 1),
                (y > 0).then(|| i - w),
                (x + 1 < w).then(|| i + 1),
                (y + 1 < h).then(|| i + w),
            ];
            if let Some(j) = nb.into_iter().flatten().find(|&j| sizes[comp[j]] >= 8) {
                comp[i] = comp[j];
            }
        }
    }
    comp
}

/// The median of `v` (the upper one of an even count).
pub fn median(mut v: Vec<f32>) -> f32 {
    v.sort_by(f32::total_cmp);
    v[v.len() / 2]
}

/// A segmentation's members (pixel indices) and 4-adjacency.
pub struct Segments {
    pub members: Vec<Vec<usize>>,
    pub nbrs: Vec<BTreeSet<usize>>,
}

impl Segments {
    /// Members and neighbours of the labels `seg` of a `w` x `h` image.
    pub fn new(seg: &[usize], w: usize, h: usize) -> Self {
        let nseg = seg.iter().max().map_or(0, |m| m + 1);
        let mut members = vec![Vec::new(); nseg];
        let mut nbrs = vec![BTreeSet::new(); nseg];
        for i in 0..w * h {
            members[seg[i]].push(i);
            let (x, y) = (i % w, i / w);
            if x + 1 < w && seg[i + 1] != seg[i] {
                nbrs[seg[i]].insert(seg[i + 1]);
                nbrs[seg[i + 1]].insert(seg[i]);
            }
            if y + 1 < h && seg[i + w] != seg[i] {
                nbrs[seg[i]].insert(seg[i + w]);
                nbrs[seg[i + w]].insert(seg[i]);
            }
        }
        Segments { members, nbrs }
    }
}
