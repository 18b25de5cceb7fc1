//! Unit tests of the photo highlight model (`crate::highlight`).

use super::*;

#[test]
fn regions_are_8_connected_in_first_pixel_order() {
    // 4 x 3:  # . . #
    //         . # . #
    //         . . . .
    let on = [0, 5, 3, 7];
    let r = regions(4, 3, |i| on.contains(&i));
    // 0 and 5 touch diagonally; 3 and 7 vertically.
    assert_eq!(r.len(), 2);
    let mut a = r[0].clone();
    a.sort_unstable();
    let mut b = r[1].clone();
    b.sort_unstable();
    assert_eq!((a, b), (vec![0, 5], vec![3, 7]));
    assert_eq!(r[0][0], 0, "a region starts at its first pixel");
    assert!(regions(0, 0, |_| true).is_empty());
}
use crate::model::Transfer;

fn tone() -> Tone {
    Tone::new(Transfer::Gamma, 2.2, 0.0)
}

/// Sets every channel of the pixels in columns `x0..x1`, rows `y0..y1` of `img` to `v`.
fn fill_rect(img: &mut Image<f64>, (x0, x1): (usize, usize), (y0, y1): (usize, usize), v: f64) {
    let w = img.width;
    for y in y0..y1 {
        for x in x0..x1 {
            img.data[3 * (y * w + x)..3 * (y * w + x) + 3].fill(v);
        }
    }
}

#[test]
fn parse_and_validate() {
    assert_eq!(PhotoHighlights::parse("off").unwrap(), PhotoHighlights::Off);
    assert_eq!(
        PhotoHighlights::parse("paper").unwrap(),
        PhotoHighlights::PaperBoost
    );
    assert_eq!(
        PhotoHighlights::parse("3:0.9").unwrap(),
        PhotoHighlights::Recover(HighlightRecovery {
            gain: 3.0,
            threshold: 0.9
        })
    );
    let r = HighlightRecovery::parse("6").unwrap();
    assert_eq!(r.gain, 6.0);
    assert_eq!(r.threshold, HighlightRecovery::DEFAULT.threshold);
    let r = HighlightRecovery::parse("3:0.9").unwrap();
    assert_eq!((r.gain, r.threshold), (3.0, 0.9));
    for bad in ["", "x", "0.5", "3:1", "3:0", "3:x", "nan", "inf"] {
        assert!(HighlightRecovery::parse(bad).is_err(), "{bad}");
    }
}

#[test]
fn small_clipped_blob_gets_gain_large_area_less_unclipped_none() {
    // 40x40 grey image; a 2x2 clipped blob, a 20x10 clipped area, a bright unclipped blob.
    let mut img = Image::<f64>::new(40, 40, 3);
    img.data.iter_mut().for_each(|v| *v = 0.3);
    fill_rect(&mut img, (2, 4), (2, 4), 1.0);
    fill_rect(&mut img, (10, 30), (20, 30), 1.0);
    fill_rect(&mut img, (30, 32), (2, 4), 0.95);
    let r = HighlightRecovery {
        gain: 5.0,
        threshold: 0.85,
    };
    let mut disp = Image::<f64>::new(40, 40, 1);
    disp.data.iter_mut().for_each(|v| *v = 1.0);
    // In focus at the far right (x >= 36), defocused by 30 px elsewhere.
    for y in 0..40 {
        for x in 36..40 {
            disp.data[y * 40 + x] = 0.0;
        }
    }
    fill_rect(&mut img, (37, 39), (30, 32), 1.0);
    let out = r.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
    let lin = |img: &Image<f64>, x: usize, y: usize| tone().linearize(img.data[3 * (y * 40 + x)]);
    assert!((lin(&out, 2, 2) - 5.0).abs() < 1e-9, "{}", lin(&out, 2, 2));
    // 200 px area: gain 1 + 4 * 16/200.
    assert!((lin(&out, 15, 25) - (1.0 + 4.0 * 16.0 / 200.0)).abs() < 1e-9);
    assert_eq!(lin(&out, 30, 2), lin(&img, 30, 2));
    assert_eq!(lin(&out, 0, 0), lin(&img, 0, 0));
    // An in-focus clipped blob keeps its colour.
    assert_eq!(lin(&out, 37, 30), lin(&img, 37, 30));
    // Gain 1 is the identity.
    let id = HighlightRecovery { gain: 1.0, ..r };
    assert_eq!(id.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap(), img);
    assert!((defocus_gate(0.5), defocus_gate(2.0), defocus_gate(5.0)) == (0.0, 0.5, 1.0));
}
#[test]
fn estimate_reads_gain_and_tint_from_the_rim() {
    // Two clipped 4x4 blobs on a grey background, defocused by 30 px: blob A with a
    // rim barely above the background (a bright source: its edge falls fast), blob B
    // with a brighter orange rim (a dimmer source). Linear values.
    let (w, h) = (48, 24);
    let bg = 0.05;
    let mut lin = vec![bg; w * h * 3];
    let mut put = |x: usize, y: usize, c: [f64; 3]| {
        lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&c);
    };
    for (x0, rim) in [(8usize, [0.07; 3]), (32, [0.2, 0.1, 0.06])] {
        for y in 8..16 {
            for x in x0..x0 + 8 {
                let inner = (x0 + 2..x0 + 6).contains(&x) && (10..14).contains(&y);
                put(x, y, if inner { [1.0; 3] } else { rim });
            }
        }
    }
    let tone = tone();
    let mut img = Image::<f64>::new(w, h, 3);
    for (v, l) in img.data.iter_mut().zip(&lin) {
        *v = tone.encode(*l);
    }
    let mut disp = Image::<f64>::new(w, h, 1);
    disp.data.iter_mut().for_each(|v| *v = 1.0);
    // The earlier cue, tint and profile (per clipped edge pixel, 3-4 px ring, a share
    // of the gain on edge pixels); the defaults are tested below.
    let est = HighlightEstimate {
        rim_k: 0.3,
        max_gain: 8.0,
        edge: 1.0,
        white_rim: 0.05,
        keep: false,
        rim_ramp: 1.0,
        edge_power: None,
        ring_cue: false,
        tint_weighted: false,
        // The per-region rule (pooling over the image is tested below).
        pool: 0.0,
        ..HighlightEstimate::DEFAULT
    };
    let out = est.apply(&img, &disp, 0.0, 30.0, &tone).unwrap();
    let at = |im: &Image<f64>, x: usize, y: usize, c: usize| {
        tone.linearize(im.data[3 * (y * w + x) + c])
    };
    // Interior pixels of the blobs (not on the clipped edge).
    let (a, b) = (at(&out, 11, 11, 0), at(&out, 35, 11, 0));
    assert!(a > 2.0 * b, "bright-source blob {a} vs dim-source blob {b}");
    assert!(b > 1.5, "a clipped blob is recovered above white: {b}");
    assert!(
        (a - est.max_gain).abs() < 1e-9,
        "capped at the largest gain: {a}"
    );
    // B takes its rim's orange tint (red well above green, green >= blue), never
    // below the photo's white.
    let (r, g, bl) = (
        at(&out, 35, 11, 0),
        at(&out, 35, 11, 1),
        at(&out, 35, 11, 2),
    );
    assert!(r > 1.5 * g && g >= bl && bl >= 1.0 - 1e-9, "{r} {g} {bl}");
    // The clipped edge pixels get the share `edge` of the gain.
    let half = HighlightEstimate { edge: 0.5, ..est };
    let out_half = half.apply(&img, &disp, 0.0, 30.0, &tone).unwrap();
    let edge_px = at(&out_half, 10, 10, 0);
    assert!(
        (edge_px - (1.0 + 0.5 * (a - 1.0))).abs() < 1e-9,
        "{edge_px}"
    );
    assert_eq!(at(&out_half, 11, 11, 0), a);
    // The background and the unclipped rim outside the threshold are untouched.
    assert_eq!(at(&out, 0, 0, 0), at(&img, 0, 0, 0));
    // In focus: nothing changes.
    let focused = est.apply(&img, &disp, 1.0, 30.0, &tone).unwrap();
    assert_eq!(focused, img);
    // Parsing.
    assert_eq!(
        PhotoHighlights::parse("auto").unwrap(),
        PhotoHighlights::Estimate(HighlightEstimate::DEFAULT)
    );
    let e = HighlightEstimate::parse("auto:k=0.5,max=4,edge=0.5,tint=0,paper=0,white=0.1").unwrap();
    assert_eq!(
        (e.rim_k, e.max_gain, e.edge, e.tint, e.boost, e.white_rim),
        (0.5, 4.0, 0.5, false, None, 0.1)
    );
    assert_eq!(e.edge_power, None, "edge= switches to the share rule");
    let e = HighlightEstimate::parse("auto:edgep=0.5,keep=0,cue=0,tintw=0,rim=0.5").unwrap();
    assert_eq!(
        (
            e.edge_power,
            e.keep,
            e.ring_cue,
            e.tint_weighted,
            e.rim_ramp
        ),
        (Some(0.5), false, false, false, 0.5)
    );
    // The boost on top: the photo constants by default, the paper's with paper=1, none
    // with paper=0; boost= and boostt= change one constant, in the order given.
    let boost = |s: &str| PhotoHighlights::parse(s).unwrap().boost();
    assert_eq!(boost("auto"), Some(HighlightBoost::PHOTO));
    assert_eq!(boost("auto:paper=1"), Some(HighlightBoost::PAPER));
    assert_eq!(boost("auto:paper=0"), None);
    assert_eq!(boost("paper"), Some(HighlightBoost::PAPER));
    assert_eq!(boost("off"), None);
    assert_eq!(boost("2:0.95"), None);
    assert_eq!(
        boost("auto:paper=0,boost=0.3"),
        Some(HighlightBoost {
            amount: 0.3,
            ..HighlightBoost::PHOTO
        })
    );
    assert_eq!(
        boost("auto:paper=1,boostt=0.95"),
        Some(HighlightBoost {
            threshold_encoded: 0.95,
            ..HighlightBoost::PAPER
        })
    );
    for bad in [
        "auto:k",
        "auto:k=0",
        "auto:tint=2",
        "auto:white=-1",
        "auto:max=0.5",
        "auto:edge=2",
        "auto:x=1",
        "auto:edgep=2",
        "auto:rim=-1",
        "auto:keep=2",
        "auto:cue=0.5",
        "auto:boost=-1",
        "auto:boost=nan",
        "auto:boostt=1",
        "auto:paper=2",
        "autox",
    ] {
        assert!(PhotoHighlights::parse(bad).is_err(), "{bad}");
    }
}

/// Builds an encoded image from linear colours.
fn encode_lin(lin: &[f64], w: usize, h: usize) -> Image<f64> {
    let mut img = Image::<f64>::new(w, h, 3);
    for (v, l) in img.data.iter_mut().zip(lin) {
        *v = tone().encode(*l);
    }
    img
}

#[test]
fn ring_cue_reads_the_rim_against_the_next_ring() {
    // A clipped 4x4 blob whose 1 px rim and the next ring out lie on a bright patch
    // (0.3) in a dark scene (0.05): against the next ring the rim holds no light (a
    // bright source: the largest gain); against the 3-4 px ring it seems to hold
    // much (a dim source). Linear values, defocused by 30 px.
    let (w, h) = (24, 24);
    let mut lin = vec![0.05; w * h * 3];
    for y in 6..18 {
        for x in 6..18 {
            let v = if (10..14).contains(&x) && (10..14).contains(&y) {
                1.0
            } else if (8..16).contains(&x) && (8..16).contains(&y) {
                0.3
            } else {
                0.05
            };
            lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&[v; 3]);
        }
    }
    let img = encode_lin(&lin, w, h);
    let mut disp = Image::<f64>::new(w, h, 1);
    disp.data.iter_mut().for_each(|v| *v = 1.0);
    let ring = HighlightEstimate {
        tint: false,
        pool: 0.0,
        ..HighlightEstimate::DEFAULT
    };
    let old = HighlightEstimate {
        ring_cue: false,
        ..ring
    };
    let centre = |e: &HighlightEstimate| {
        let out = e.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
        tone().linearize(out.data[3 * (11 * w + 11)])
    };
    assert!(
        (centre(&ring) - ring.max_gain).abs() < 1e-9,
        "{}",
        centre(&ring)
    );
    assert!(centre(&old) < 0.5 * ring.max_gain, "{}", centre(&old));
}

#[test]
fn weighted_tint_follows_the_brightest_rim_pixels() {
    // A clipped 2x2 blob; one rim pixel carries the source's orange light, the others
    // a faint bluish cast over the grey background. Weighted by light, the tint is
    // orange; summed unweighted, the many faint pixels make it bluish.
    let (w, h) = (20, 20);
    let mut lin = vec![0.1; w * h * 3];
    let mut put = |x: usize, y: usize, c: [f64; 3]| {
        lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&c);
    };
    for (x, y) in [(9, 9), (10, 9), (9, 10), (10, 10)] {
        put(x, y, [1.0; 3]);
    }
    for y in 8..12 {
        for x in 8..12 {
            if !(9..11).contains(&x) || !(9..11).contains(&y) {
                put(x, y, [0.1, 0.1, 0.17]);
            }
        }
    }
    put(8, 9, [0.6, 0.35, 0.15]);
    let img = encode_lin(&lin, w, h);
    let mut disp = Image::<f64>::new(w, h, 1);
    disp.data.iter_mut().for_each(|v| *v = 1.0);
    let est = HighlightEstimate {
        white_rim: 0.0,
        ..HighlightEstimate::DEFAULT
    };
    let rgb = |e: &HighlightEstimate| {
        let out = e.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
        let i = 3 * (9 * w + 9);
        [0, 1, 2].map(|c| tone().linearize(out.data[i + c]))
    };
    let [r, _, b] = rgb(&est);
    assert!(r > 1.5 * b, "weighted: orange, got r {r} b {b}");
    let [r, _, b] = rgb(&HighlightEstimate {
        tint_weighted: false,
        ..est
    });
    assert!(b > r, "unweighted: bluish, got r {r} b {b}");
}

#[test]
fn profile_keeps_unclipped_channels_and_the_rim() {
    // A clipped 6x6 blob with no rim light (the largest gain `G`): interior pixels get
    // `G`, edge pixels `G^p`; a pixel clipped in red and green only keeps its blue; a
    // bright unclipped pixel of the region keeps its value with `rim` 0.
    let (w, h) = (20, 20);
    let mut lin = vec![0.05; w * h * 3];
    for y in 7..13 {
        for x in 7..13 {
            lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&[1.0; 3]);
        }
    }
    lin[3 * (9 * w + 9) + 2] = 0.5; // clipped in red and green only (interior)
    let bright = tone().linearize(0.95);
    lin[3 * (10 * w + 13)..3 * (10 * w + 13) + 3].copy_from_slice(&[bright; 3]);
    let img = encode_lin(&lin, w, h);
    let mut disp = Image::<f64>::new(w, h, 1);
    disp.data.iter_mut().for_each(|v| *v = 1.0);
    let est = HighlightEstimate {
        tint: false,
        rim_k: 100.0,
        pool: 0.0,
        ..HighlightEstimate::DEFAULT
    };
    let out = est.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
    let at = |im: &Image<f64>, x: usize, y: usize, c: usize| {
        tone().linearize(im.data[3 * (y * w + x) + c])
    };
    let g = est.max_gain;
    let p = est.edge_power.unwrap();
    assert!((at(&out, 10, 10, 0) - g).abs() < 1e-9);
    assert!((at(&out, 7, 10, 0) - g.powf(p)).abs() < 1e-9);
    assert!((at(&out, 7, 7, 1) - g.powf(p)).abs() < 1e-9);
    assert!((at(&out, 9, 9, 0) - g).abs() < 1e-9);
    assert_eq!(at(&out, 9, 9, 2), at(&img, 9, 9, 2));
    assert_eq!(at(&out, 13, 10, 0), at(&img, 13, 10, 0));
    // Without `keep` and with the full ramp, both change.
    let all = HighlightEstimate {
        keep: false,
        rim_ramp: 1.0,
        ..est
    };
    let out = all.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
    assert!((at(&out, 9, 9, 2) - g).abs() < 1e-9);
    assert!(at(&out, 13, 10, 0) > at(&img, 13, 10, 0) + 0.5);
}

#[test]
fn gain_follows_the_least_blurred_clipped_pixel_behind() {
    // Two 4x4 clipped blobs on grey, each with a clipped column on its right that the
    // depth map puts on a blurred foreground (disparity 1, 30 px of blur): blob A's core
    // is in focus (disparity 0), blob B's core is defocused (disparity 0.5, 15 px).
    // Blob C: a defocused light (disparity -0.5, 15 px) crossed by an in-focus wire
    // (its middle column, disparity 0) in front of it.
    let (w, h) = (45, 12);
    let mut img = Image::<f64>::new(w, h, 3);
    img.data.iter_mut().for_each(|v| *v = 0.3);
    let mut disp = Image::<f64>::new(w, h, 1);
    for (x0, core, col, col_disp) in [(3, 0.0, 4, 1.0), (18, 0.5, 4, 1.0), (33, -0.5, 2, 0.0)] {
        for y in 4..8 {
            for x in x0..x0 + 5 {
                img.data[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&[1.0; 3]);
                disp.data[y * w + x] = if x == x0 + col { col_disp } else { core };
            }
        }
    }
    let r = HighlightRecovery {
        gain: 5.0,
        threshold: 0.9,
    };
    let out = r.apply(&img, &disp, 0.0, 30.0, &tone()).unwrap();
    let lin = |im: &Image<f64>, x: usize, y: usize| tone().linearize(im.data[3 * (y * w + x)]);
    // A: in-focus source, so neither its core nor its foreground-labelled edge gain.
    assert_eq!(lin(&out, 4, 5), 1.0);
    assert_eq!(lin(&out, 7, 5), 1.0);
    // B: a defocused source, so both gain (20 px area: 1 + 4 * 16 / 20).
    let g = 1.0 + 4.0 * 16.0 / 20.0;
    assert!((lin(&out, 19, 5) - g).abs() < 1e-9);
    assert!((lin(&out, 22, 5) - g).abs() < 1e-9);
    // C: the light behind the wire keeps its gain; the wire, in focus, keeps its colour.
    // The wire is blob C's column x0 + 2 = 35.
    assert!((lin(&out, 34, 5) - g).abs() < 1e-9);
    assert!((lin(&out, 36, 5) - g).abs() < 1e-9);
    assert!((lin(&out, 35, 5) - 1.0).abs() < 1e-12);
    // Pixels 0-3 (even ones clipped) at disparities 0.2, 0.9, 0.5, 0.0 with radii 4, 1,
    // 2, 0.5: behind disparity 0.5 lies pixel 0 (4) and pixel 2 (2).
    let clipped = |j: usize| j % 2 == 0;
    let d = |j: usize| [0.2, 0.9, 0.5, 0.0][j];
    let radius = |j: usize| [4.0, 1.0, 2.0, 0.5][j];
    let s = SourceRadii::new(&[0, 1, 2, 3], clipped, d, radius);
    assert_eq!(
        (s.behind(0.5), s.behind(1.0), s.behind(0.3)),
        (2.0, 2.0, 4.0)
    );
    assert_eq!(s.behind(0.1), f64::INFINITY);
    let none = SourceRadii::new(&[1, 3], clipped, d, radius);
    assert_eq!(none.behind(1.0), f64::INFINITY);
}

#[test]
fn a_light_across_a_depth_edge_moves_to_the_farthest_depth_a_near_specular_stays() {
    // 24 x 12, grey; disparity 0 (far) except a near band (0.8) over columns 8..10 and a
    // near square (0.8) at columns 16..22, rows 2..8.
    let (w, h) = (24, 12);
    let mut rgb = Image::<f64>::new(w, h, 3);
    rgb.data.iter_mut().for_each(|v| *v = 0.3);
    let mut map = Image::<f64>::new(w, h, 1);
    for y in 0..h {
        for x in 0..w {
            let near = (8..10).contains(&x) || ((16..22).contains(&x) && (2..8).contains(&y));
            map.data[y * w + x] = if near { 0.8 } else { 0.0 };
        }
    }
    // A clipped light seen across the band (6 of its 12 pixels on the band's depth)...
    fill_rect(&mut rgb, (6, 12), (4, 6), 1.0);
    // ...a clipped specular on the near square whose rim touches one far pixel...
    fill_rect(&mut rgb, (17, 22), (3, 6), 1.0);
    fill_rect(&mut rgb, (22, 23), (4, 5), 0.95);
    // ...and a bright but unclipped patch across the band (nothing was lost there).
    fill_rect(&mut rgb, (7, 11), (9, 11), 0.95);
    let before = map;
    let disp = lights_at_farthest_depth(&rgb, &before).expect("the light moves");
    for y in 0..h {
        for x in 0..w {
            let (b, a) = (before.data[y * w + x], disp.data[y * w + x]);
            if (8..10).contains(&x) && (4..6).contains(&y) {
                assert_eq!(a, 0.0, "light pixel ({x},{y}) at the far depth");
            } else {
                assert_eq!(a, b, "({x},{y}) unchanged");
            }
        }
    }
    // Without the light, nothing moves (and nothing is copied).
    let mut plain = rgb.clone();
    plain.data.iter_mut().for_each(|v| *v = v.min(0.95));
    assert!(lights_at_farthest_depth(&plain, &before).is_none());
}

#[test]
fn a_large_clipped_area_keeps_its_depth_map() {
    // A 40 x 40 overexposed wall (1600 px, more than 16 point areas of 16 px) across a
    // depth edge: not a light, nothing moves.
    let (w, h) = (40, 40);
    let mut rgb = Image::<f64>::new(w, h, 3);
    rgb.data.iter_mut().for_each(|v| *v = 1.0);
    let mut map = Image::<f64>::new(w, h, 1);
    for (i, d) in map.data.iter_mut().enumerate() {
        *d = if i % w < 10 { 0.8 } else { 0.0 };
    }
    assert!(lights_at_farthest_depth(&rgb, &map).is_none());
}

#[test]
fn pooling_raises_the_cap_where_every_rim_is_faint_and_keeps_dim_scenes() {
    // 16 clipped 2x2 blobs on a dark background, each with a lifted rim (its 8-ring).
    // A faint rim (lift 0.01: rim gain K / x = 20) in every blob says the whole image
    // was exposed for bright lights: pooling lifts the cap to `pool_max` and the rim
    // constant with it. Bright rims (lift 0.3: K / x < 1) leave the default as it is.
    let (w, h) = (48, 48);
    let scene = |lift: f64| {
        let mut lin = vec![0.05; w * h * 3];
        for by in [6, 16, 26, 36] {
            for bx in [6, 16, 26, 36] {
                for y in by - 1..by + 3 {
                    for x in bx - 1..bx + 3 {
                        let inside = (bx..bx + 2).contains(&x) && (by..by + 2).contains(&y);
                        let v = if inside { 1.0 } else { 0.05 + lift };
                        lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&[v; 3]);
                    }
                }
            }
        }
        encode_lin(&lin, w, h)
    };
    let mut disp = Image::<f64>::new(w, h, 1);
    disp.data.iter_mut().for_each(|v| *v = 1.0);
    // The default pools (0.9); `pool: 0` is the rule without it.
    let pooled = HighlightEstimate {
        tint: false,
        ..HighlightEstimate::DEFAULT
    };
    assert_eq!(pooled.pool, 0.9);
    let plain = HighlightEstimate {
        pool: 0.0,
        ..pooled
    };
    assert_eq!(HighlightEstimate::parse("auto:pool=0").unwrap().pool, 0.0);
    let centre = |e: &HighlightEstimate, img: &Image<f64>| {
        let out = e.apply(img, &disp, 0.0, 30.0, &tone()).unwrap();
        tone().linearize(out.data[3 * (16 * w + 16)])
    };
    let faint = scene(0.01);
    // Unpooled: K / x = 20 is capped at 3.5 (the 2x2 blob has no interior: edge
    // pixels get g^0.65).
    let g_plain = centre(&plain, &faint);
    let g_pooled = centre(&pooled, &faint);
    assert!((g_plain - 3.5f64.powf(0.65)).abs() < 1e-6, "{g_plain}");
    assert!((g_pooled - 10f64.powf(0.65)).abs() < 1e-6, "{g_pooled}");
    let bright = scene(0.3);
    let a = plain.apply(&bright, &disp, 0.0, 30.0, &tone()).unwrap();
    let b = pooled.apply(&bright, &disp, 0.0, 30.0, &tone()).unwrap();
    assert_eq!(a.data, b.data);
    // The key parses and is validated.
    let e = HighlightEstimate::parse("auto:pool=0.9,poolq=0.8,poolmax=12,poolk=0.5").unwrap();
    assert_eq!(
        (e.pool, e.pool_quantile, e.pool_max, e.pool_k_power),
        (0.9, 0.8, 12.0, 0.5)
    );
    assert!(HighlightEstimate::parse("auto:pool=0.9,poolmax=2").is_err());
    assert!(HighlightEstimate::parse("auto:poolq=1.5").is_err());
}

#[test]
fn a_region_whose_clipped_pixels_leave_a_channel_unclipped_gets_no_gain() {
    // A warm 4x4 blob clipped in red and green, its blue (0.45) below white at every
    // pixel, with no rim light (the rim cue alone would give the largest gain): its
    // source is at most 1 / 0.45 times white, and it keeps the photo's light (the paper's
    // boost in the model is all it gets). With its blue clipped at one pixel, or with
    // `chan=0`, the rim's gain applies.
    let (w, h) = (20, 20);
    let blob = |blue_clipped_at_one: bool| {
        let mut lin = vec![0.05; w * h * 3];
        for y in 8..12 {
            for x in 8..12 {
                lin[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&[1.0, 1.0, 0.45]);
            }
        }
        if blue_clipped_at_one {
            lin[3 * (10 * w + 10) + 2] = 1.0;
        }
        encode_lin(&lin, w, h)
    };
    let mut disp = Image::<f64>::new(w, h, 1);
    disp.data.iter_mut().for_each(|v| *v = 1.0);
    let est = HighlightEstimate {
        rim_k: 100.0,
        pool: 0.0,
        ..HighlightEstimate::DEFAULT
    };
    assert!(est.unclipped_channel, "on by default");
    let red_at_centre = |e: &HighlightEstimate, img: &Image<f64>| {
        let out = e.apply(img, &disp, 0.0, 30.0, &tone()).unwrap();
        tone().linearize(out.data[3 * (9 * w + 9)])
    };
    let warm = blob(false);
    let out = est.apply(&warm, &disp, 0.0, 30.0, &tone()).unwrap();
    assert_eq!(out, warm, "no gain: the photo as it is");
    let off = HighlightEstimate::parse("auto:chan=0,pool=0,k=100").unwrap();
    assert!(!off.unclipped_channel);
    assert!((red_at_centre(&off, &warm) - off.max_gain).abs() < 1e-9);
    let g = red_at_centre(&est, &blob(true));
    assert!((g - est.max_gain).abs() < 1e-9, "{g}");
    assert!(HighlightEstimate::parse("auto:chan=2").is_err());
}
