//! The standard benchmark: seeded procedural five-billboard scenes.
//!
//! Every scene is a [`SceneSpec`] that depends only on (seed, index, size, spp), so shards
//! can generate disjoint subsets independently and a scene's `scene.json` regenerates it
//! exactly with `drbokeh trace`.
//!
//! Design (see `docs/ground-truth.md`):
//! - Lens: biconvex, Rc = 50 mm, Ra = 10 mm, eta = 1.5 (f = 50.3 mm); aperture stop radius
//!   chosen per scene (at most [`MAX_APERTURE_RADIUS_MM`], about f/8.4, so spherical
//!   aberration stays well under a pixel while defocus reaches 40 px).
//! - Horizontal field of view [`FOV_DEG`]; square images.
//! - Billboards: an opaque procedural background at 3 to 8 m and four procedural
//!   foregrounds (foliage, strands, fence, fluff, in a random order) at distinct depths
//!   from about 0.1 m to half the background's depth.
//! - Focus: scene `i` focuses on the nearest foreground (`i % 3 == 0`), a middle one
//!   (`1`) or the farthest billboard (`2`).
//! - Largest paraxial circle of confusion: 4 to 40 px (at 512 px wide), log-spaced over
//!   the 100 scenes in a scrambled order; smaller images scale it with their width.

use super::procedural::{HighlightRange, ProceduralKind};
use super::sampling::Rng;
use super::scene::{
    normalised_disparity, BillboardSpec, CameraSpec, LensSpec, RenderSpec, SceneSpec, TextureSpec,
    STANDARD_AIF_SPP,
};
use crate::Result;

/// Horizontal field of view of the benchmark camera, degrees.
pub const FOV_DEG: f64 = 10.0;
/// Largest aperture stop radius used by the benchmark, mm.
pub const MAX_APERTURE_RADIUS_MM: f64 = 3.0;
/// Benchmark lens radius of curvature, mm.
pub const CURVATURE_RADIUS_MM: f64 = 50.0;
/// Benchmark lens rim radius, mm.
pub const RIM_RADIUS_MM: f64 = 10.0;
/// Benchmark lens refractive index.
pub const ETA: f64 = 1.5;
/// Smallest and largest target blur radius (px at 512 px width).
pub const BLUR_RANGE_PX: (f64, f64) = (4.0, 40.0);

/// Where a scene focuses.
pub fn focus_target(index: usize) -> &'static str {
    ["near", "middle", "far"][index % 3]
}

/// The spec of benchmark scene `index` (of `count`) for master `seed`, `size` x `size`
/// pixels, `spp` samples per pixel, highlights in the default range.
pub fn scene_spec(
    seed: u64,
    index: usize,
    count: usize,
    size: usize,
    spp: usize,
) -> Result<SceneSpec> {
    scene_spec_with_content(seed, index, count, size, spp, Content::default())
}

/// What a benchmark's scenes show beyond their depths: the highlights' range, the
/// background's fine detail, and whether the foregrounds' layout in the frame follows their
/// depth. None of them changes the depths, focus, blur or random draws.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Content {
    /// Range of the highlights' linear gains.
    pub highlights: HighlightRange,
    /// Strength in [0, 1] of the fine detail on the background
    /// ([`super::procedural::generate_with`]); 0, the default, for none.
    pub background_detail: f64,
    /// Foregrounds laid out as a camera sees objects of about one size standing on a
    /// ground ([`perspective_layout`]): the nearer, the larger and the lower in the frame.
    /// Off (the default), each foreground's size and place are drawn independently of its
    /// depth, so that the all-in-focus image says nothing about how far a billboard is.
    pub perspective: bool,
}

impl Default for Content {
    fn default() -> Self {
        Content {
            highlights: HighlightRange::default(),
            background_detail: 0.0,
            perspective: false,
        }
    }
}

/// Side of a foreground billboard (fraction of the frame width) at normalised disparity 0
/// and 1 under [`Content::perspective`].
pub const PERSPECTIVE_SIDE: (f64, f64) = (0.25, 0.85);
/// Vertical centre (fraction of the frame height, 0 at the top) of a foreground billboard
/// at normalised disparity 0 and 1 under [`Content::perspective`].
pub const PERSPECTIVE_HEIGHT: (f64, f64) = (0.35, 0.75);

/// The layout cue of [`Content::perspective`]: a foreground's square side and vertical
/// centre from its normalised disparity `t` in [0, 1] (1 the nearest billboard, 0 the
/// background), interpolated linearly between [`PERSPECTIVE_SIDE`] and
/// [`PERSPECTIVE_HEIGHT`]'s ends. The independent draws (`side_draw` in [0.35, 0.8],
/// `height_draw` in [0.2, 0.8]) only jitter the result (side by -14 % to +11 %, height by
/// +-0.03), so that depth stays readable from size and height.
pub fn perspective_layout(t: f64, side_draw: f64, height_draw: f64) -> (f64, f64) {
    let lerp = |(a, b): (f64, f64)| a + (b - a) * t.clamp(0.0, 1.0);
    // 0.575 is the middle of the side draw's range, so a middle draw leaves the side as is.
    let side = lerp(PERSPECTIVE_SIDE) * (side_draw / 0.575).powf(0.3);
    let height = lerp(PERSPECTIVE_HEIGHT) + 0.1 * (height_draw - 0.5);
    (side, height)
}

/// [`scene_spec`] with `content`'s highlights, background detail and layout: the same
/// depths, focus, blur and random draws for every content (only the highlights'
/// brightness, the background's detail and, with [`Content::perspective`], the
/// foregrounds' sizes and places change). The defaults are not written into the spec, so
/// standard scenes keep their `scene.json`.
pub fn scene_spec_with_content(
    seed: u64,
    index: usize,
    count: usize,
    size: usize,
    spp: usize,
    content: Content,
) -> Result<SceneSpec> {
    let Content {
        highlights,
        background_detail,
        perspective,
    } = content;
    highlights.validate()?;
    super::procedural::validate_background_detail(background_detail)?;
    let highlight_range = (highlights != HighlightRange::default()).then_some(highlights);
    let mut rng = Rng::from_words(&[seed, index as u64, 0xBE4C]);
    let lens_f =
        super::SphericalLens::new(CURVATURE_RADIUS_MM, RIM_RADIUS_MM, ETA)?.focal_length_mm();
    // Target blur: log-spaced over the scenes, scrambled (37 is coprime to most counts).
    let count = count.max(1);
    let slot = if count > 1 { (index * 37) % count } else { 0 };
    let u = if count > 1 {
        slot as f64 / (count - 1) as f64
    } else {
        0.5
    };
    let target_px_512 = BLUR_RANGE_PX.0 * (BLUR_RANGE_PX.1 / BLUR_RANGE_PX.0).powf(u);
    let target_px = target_px_512 * size as f64 / 512.0;
    let px_per_radian = size as f64 / (2.0 * (0.5 * FOV_DEG.to_radians()).tan());

    let mut kinds = ProceduralKind::FOREGROUNDS;
    for k in (1..kinds.len()).rev() {
        kinds.swap(k, rng.below(k + 1));
    }
    // Draw depths until the aperture the target blur needs is small enough.
    let (depths, focus_depth, aperture) = loop {
        let bg = rng.range(3000.0, 8000.0);
        let near = rng.range(100.0, 180.0);
        let far_fg = bg * rng.range(0.25, 0.5);
        let mut fg: Vec<f64> = (0..4)
            .map(|_| near * (far_fg / near).powf(rng.uniform()))
            .collect();
        fg[0] = near;
        fg.sort_by(f64::total_cmp);
        if fg.windows(2).any(|w| w[1] / w[0] < 1.15) {
            continue;
        }
        let focus_depth = match index % 3 {
            0 => fg[0],
            1 => fg[1 + rng.below(2)],
            _ => {
                if rng.uniform() < 0.5 {
                    bg
                } else {
                    fg[3]
                }
            }
        };
        let mut all = fg.clone();
        all.push(bg);
        let delta = all
            .iter()
            .map(|z| (1.0 / z - 1.0 / focus_depth).abs())
            .fold(0.0, f64::max);
        // r_px = A D_I delta / pitch = A delta px_per_radian (D_I cancels).
        let aperture = target_px / (delta * px_per_radian);
        if aperture <= MAX_APERTURE_RADIUS_MM && focus_depth > 1.5 * lens_f {
            break (all, focus_depth, aperture);
        }
    };
    // The nearest and farthest billboards (the foregrounds are sorted; the background is last).
    let (near, far) = (depths[0], depths[4]);
    let mut billboards = Vec::new();
    for (k, &depth) in depths.iter().enumerate() {
        let (name, center, size, kind) = if k == 4 {
            (
                "background".to_string(),
                [0.5, 0.5],
                [1.6, 1.6],
                ProceduralKind::Background,
            )
        } else {
            let s = rng.range(0.35, 0.8);
            let aspect = rng.range(0.75, 1.33);
            let center = [rng.range(0.2, 0.8), rng.range(0.2, 0.8)];
            let (center, size) = if perspective {
                let (side, height) =
                    perspective_layout(normalised_disparity(depth, near, far), s, center[1]);
                ([center[0], height], [side, side])
            } else {
                (center, [s * aspect.sqrt(), s / aspect.sqrt()])
            };
            (
                format!("{:?}", kinds[k]).to_lowercase(),
                center,
                size,
                kinds[k],
            )
        };
        billboards.push(BillboardSpec {
            name,
            depth_mm: depth,
            center,
            size,
            texture: TextureSpec::Procedural {
                kind,
                seed: rng.next_u64() >> 11,
                highlight_range,
                background_detail: (kind == ProceduralKind::Background && background_detail > 0.0)
                    .then_some(background_detail),
            },
        });
    }
    Ok(SceneSpec {
        name: format!("scene_{index:03}"),
        camera: CameraSpec {
            lens: LensSpec::Spherical {
                curvature_radius_mm: CURVATURE_RADIUS_MM,
                rim_radius_mm: RIM_RADIUS_MM,
                eta: ETA,
                aperture_radius_mm: Some(aperture),
            },
            width_px: size,
            height_px: size,
            fov_deg: FOV_DEG,
            sensor_distance_mm: None,
            focus_distance_mm: Some(focus_depth),
        },
        render: RenderSpec {
            spp,
            aif_spp: STANDARD_AIF_SPP,
            seed: rng.next_u64() >> 11,
        },
        billboards,
        derived: None,
    })
}

/// The manifest entry of a scene (computed from its spec, without rendering).
pub fn manifest_entry(spec: &SceneSpec, index: usize, dir_name: &str) -> Result<serde_json::Value> {
    let optics = spec.optics()?;
    let depths: Vec<f64> = spec.billboards.iter().map(|b| b.depth_mm).collect();
    let near = depths.iter().cloned().fold(f64::INFINITY, f64::min);
    let far = depths.iter().cloned().fold(0.0, f64::max);
    let zf = optics.focus_distance_mm();
    let k = optics.aperture_radius_mm * optics.sensor_distance_mm * (1.0 / near - 1.0 / far)
        / optics.pixel_pitch_mm;
    let focus = super::scene::snap_unit((1.0 / zf - 1.0 / far) / (1.0 / near - 1.0 / far));
    let max_coc = depths
        .iter()
        .map(|&z| optics.coc_radius_px(z))
        .fold(0.0, f64::max);
    Ok(serde_json::json!({
        "index": index,
        "dir": dir_name,
        "focus_target": focus_target(index),
        "focus_distance_mm": zf,
        "aperture_radius_mm": optics.aperture_radius_mm,
        "blur": k,
        "focus": focus,
        "max_coc_radius_px": max_coc,
        "render_seed": spec.render.seed,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scenes_are_deterministic_and_span_blur_and_focus() {
        let a = scene_spec(5, 7, 100, 512, 1024).unwrap();
        assert_eq!(a, scene_spec(5, 7, 100, 512, 1024).unwrap());
        assert_ne!(a, scene_spec(6, 7, 100, 512, 1024).unwrap());
        let mut blurs = Vec::new();
        for i in 0..30 {
            let s = scene_spec(1, i, 30, 512, 1024).unwrap();
            s.validate().unwrap();
            let m = manifest_entry(&s, i, "x").unwrap();
            let r = m["max_coc_radius_px"].as_f64().unwrap();
            assert!((3.9..=40.1).contains(&r), "scene {i}: max blur {r}");
            let focus = m["focus"].as_f64().unwrap();
            assert!((-1e-9..=1.0 + 1e-9).contains(&focus));
            blurs.push(r);
        }
        assert!(blurs.iter().any(|&r| r < 6.0) && blurs.iter().any(|&r| r > 30.0));
    }

    #[test]
    fn highlight_range_changes_only_the_highlights() {
        let std = scene_spec(5, 7, 20, 64, 16).unwrap();
        let with = |highlights| {
            let content = Content {
                highlights,
                ..Content::default()
            };
            scene_spec_with_content(5, 7, 20, 64, 16, content).unwrap()
        };
        assert_eq!(std, with(HighlightRange::default()));
        let bright = HighlightRange { lo: 5.0, hi: 50.0 };
        let b = with(bright);
        assert_ne!(std, b);
        for (x, y) in std.billboards.iter().zip(&b.billboards) {
            assert_eq!(
                (x.depth_mm, x.center, x.size),
                (y.depth_mm, y.center, y.size)
            );
            match &y.texture {
                TextureSpec::Procedural {
                    highlight_range, ..
                } => assert_eq!(*highlight_range, Some(bright)),
                t => panic!("unexpected texture {t:?}"),
            }
        }
        // The brighter range paints brighter highlights at the same places.
        let kind = ProceduralKind::Background;
        let t0 = super::super::procedural::generate(kind, 3, 96, 96);
        let t1 = super::super::procedural::generate_with_highlights(kind, 3, 96, 96, bright);
        let peak =
            |t: &super::super::texture::Texture| t.data.iter().map(|p| p[0]).fold(0.0f32, f32::max);
        assert!(
            peak(&t1) > peak(&t0) * 1.5,
            "{} vs {}",
            peak(&t1),
            peak(&t0)
        );
        assert!(HighlightRange::parse("5:50").unwrap() == bright);
        assert!(HighlightRange::parse("50:5").is_err());
        assert!(HighlightRange::parse("0:5").is_err());
        assert!(HighlightRange::parse("x").is_err());
    }

    #[test]
    fn perspective_lays_foregrounds_out_by_depth_and_changes_nothing_else() {
        let mut sides = Vec::new();
        for index in 0..12 {
            let std = scene_spec(9, index, 12, 64, 16).unwrap();
            let content = Content {
                perspective: true,
                ..Content::default()
            };
            let p = scene_spec_with_content(9, index, 12, 64, 16, content).unwrap();
            p.validate().unwrap();
            assert_eq!(std.camera, p.camera);
            let (near, far) = (p.billboards[0].depth_mm, p.billboards[4].depth_mm);
            for (x, y) in std.billboards.iter().zip(&p.billboards) {
                assert_eq!(
                    (&x.name, x.depth_mm, &x.texture),
                    (&y.name, y.depth_mm, &y.texture)
                );
                if y.name == "background" {
                    assert_eq!((x.center, x.size), (y.center, y.size));
                    continue;
                }
                // Same horizontal place; side and height from the normalised disparity.
                assert_eq!(x.center[0], y.center[0]);
                let t = (1.0 / y.depth_mm - 1.0 / far) / (1.0 / near - 1.0 / far);
                let side = PERSPECTIVE_SIDE.0 + (PERSPECTIVE_SIDE.1 - PERSPECTIVE_SIDE.0) * t;
                let height =
                    PERSPECTIVE_HEIGHT.0 + (PERSPECTIVE_HEIGHT.1 - PERSPECTIVE_HEIGHT.0) * t;
                assert_eq!(y.size[0], y.size[1]);
                assert!(
                    y.size[0] > side * 0.85 && y.size[0] < side * 1.12,
                    "{index} {}",
                    y.name
                );
                assert!((y.center[1] - height).abs() <= 0.03 + 1e-12);
                sides.push((t, y.size[0]));
            }
        }
        // Nearer foregrounds are larger: every pair more than 0.5 apart in disparity is
        // ordered by size (the jitter cannot undo that much).
        for &(ta, sa) in &sides {
            for &(tb, sb) in &sides {
                if ta > tb + 0.5 {
                    assert!(sa > sb, "t {ta} side {sa} against t {tb} side {sb}");
                }
            }
        }
        assert!(sides.iter().any(|s| s.0 > 0.99) && sides.iter().any(|s| s.0 < 0.3));
    }

    #[test]
    fn background_detail_changes_only_the_background_texture() {
        let std = scene_spec(5, 7, 20, 64, 16).unwrap();
        let detail = |d: f64| {
            scene_spec_with_content(
                5,
                7,
                20,
                64,
                16,
                Content {
                    background_detail: d,
                    ..Content::default()
                },
            )
        };
        assert_eq!(std, detail(0.0).unwrap());
        let d = detail(0.5).unwrap();
        d.validate().unwrap();
        for (x, y) in std.billboards.iter().zip(&d.billboards) {
            assert_eq!(
                (x.depth_mm, x.center, x.size),
                (y.depth_mm, y.center, y.size)
            );
            let want = (y.name == "background").then_some(0.5);
            match &y.texture {
                TextureSpec::Procedural {
                    background_detail, ..
                } => assert_eq!(*background_detail, want, "{}", y.name),
                t => panic!("unexpected texture {t:?}"),
            }
        }
        for bad in [-0.1, 1.5, f64::NAN] {
            let e = detail(bad).unwrap_err().to_string();
            assert!(e.contains("background_detail"), "{e}");
        }
        // Detail adds fine variation (neighbour differences) to the same layout.
        use super::super::procedural::{generate, generate_with};
        let kind = ProceduralKind::Background;
        let plain = generate(kind, 3, 128, 128);
        assert_eq!(
            plain.data,
            generate_with(kind, 3, 128, 128, HighlightRange::default(), 0.0).data
        );
        let fine = generate_with(kind, 3, 128, 128, HighlightRange::default(), 1.0);
        let roughness = |t: &super::super::texture::Texture| {
            let mut sum = 0.0f64;
            for y in 0..t.height {
                for x in 1..t.width {
                    let (a, b) = (t.data[y * t.width + x], t.data[y * t.width + x - 1]);
                    // Below 1: the surfaces, not the highlights.
                    if a[1] < 1.0 && b[1] < 1.0 {
                        sum += (a[1] - b[1]).abs() as f64;
                    }
                }
            }
            sum
        };
        assert!(
            roughness(&fine) > 2.0 * roughness(&plain),
            "{} vs {}",
            roughness(&fine),
            roughness(&plain)
        );
    }
}
