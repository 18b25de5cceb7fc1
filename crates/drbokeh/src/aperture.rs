//! Aperture shapes. The paper's aperture is the circle: a source of scatter radius `r`
//! lights receivers inside the soft disc `S = 1 / (1 + 10 exp(-3 (r - dist)))`.
//! Other shapes change the shape of that disc; the window clip `M` (`dist < R`) stays.
//!
//! - [`Aperture::Circle`]: `S(r - dist)`, exactly the paper.
//! - [`Aperture::Polygon`]: `S(r - gauge(v))` where `gauge` is the polygon's gauge
//!   function (its "radius" in the direction of the offset `v`), so the bokeh is a regular
//!   n-gon inscribed in the circle of radius `r`, with the same soft edge.
//! - [`Aperture::Kernel`]: a grey image sampled bilinearly at `v / r` (the image spans
//!   [-1, 1] along its longer side), unioned (max) with the in-focus pixel footprint
//!   `S(1 - dist)` so that a ring-shaped kernel still lights in-focus pixels.

use crate::image::Image;
use crate::{Error, Result};

/// The shape of the lens aperture (and so of the bokeh).
#[derive(Clone, Debug, PartialEq, Default)]
pub enum Aperture {
    /// A circle (the paper).
    #[default]
    Circle,
    /// A regular polygon with `blades` sides (>= 3), rotated by `rotation_deg` degrees
    /// (0: a vertex points along +x).
    Polygon {
        /// Number of blades (sides).
        blades: u32,
        /// Rotation in degrees, counter-clockwise in image coordinates (y down).
        rotation_deg: f64,
    },
    /// A custom kernel from a grey image (values in [0, 1], normalised to a maximum of 1).
    Kernel(KernelImage),
}

/// A grey kernel image, normalised so its maximum is 1.
#[derive(Clone, Debug, PartialEq)]
pub struct KernelImage {
    width: usize,
    height: usize,
    values: Vec<f64>,
}

impl KernelImage {
    /// Builds a kernel from a grey image; fails if it is empty, non-finite or all zero.
    pub fn new(grey: &Image<f64>) -> Result<Self> {
        if grey.channels != 1 {
            return Err(Error::input(
                "aperture kernel",
                format!("must be a grey image, got {} channels", grey.channels),
            ));
        }
        grey.check_finite("aperture kernel")?;
        let max = grey.data.iter().cloned().fold(0.0, f64::max);
        if grey.data.iter().any(|v| *v < 0.0) || max <= 0.0 {
            return Err(Error::input(
                "aperture kernel",
                "must be non-negative with at least one non-zero pixel",
            ));
        }
        Ok(KernelImage {
            width: grey.width,
            height: grey.height,
            values: grey.data.iter().map(|v| v / max).collect(),
        })
    }

    /// Width and height in pixels.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Bilinear sample at normalised coordinates (u, v) in [-1, 1] (longer side), 0 outside.
    pub fn sample(&self, u: f64, v: f64) -> f64 {
        self.sample_with_gradient(u, v).0
    }

    /// Bilinear sample and its partial derivatives with respect to u and v (piecewise
    /// linear: the derivative of the cell the point lies in).
    pub fn sample_with_gradient(&self, u: f64, v: f64) -> (f64, f64, f64) {
        let half = self.width.max(self.height) as f64 / 2.0;
        let fx = self.width as f64 / 2.0 + u * half - 0.5;
        let fy = self.height as f64 / 2.0 + v * half - 0.5;
        let (x0, y0) = (fx.floor(), fy.floor());
        let (tx, ty) = (fx - x0, fy - y0);
        let get = |x: f64, y: f64| -> f64 {
            if x < 0.0 || y < 0.0 || x >= self.width as f64 || y >= self.height as f64 {
                0.0
            } else {
                self.values[y as usize * self.width + x as usize]
            }
        };
        let (a, b) = (get(x0, y0), get(x0 + 1.0, y0));
        let (c, d) = (get(x0, y0 + 1.0), get(x0 + 1.0, y0 + 1.0));
        let value = (1.0 - ty) * ((1.0 - tx) * a + tx * b) + ty * ((1.0 - tx) * c + tx * d);
        let d_tx = (1.0 - ty) * (b - a) + ty * (d - c);
        let d_ty = (1.0 - tx) * (c - a) + tx * (d - b);
        (value, d_tx * half, d_ty * half)
    }
}

impl Aperture {
    /// Parses the CLI syntax: `circle`, `polygon:N[:ROT_DEG]` (also `hexagon`, `pentagon`...).
    /// Kernel images are loaded by the I/O layer, not here.
    pub fn parse_shape(s: &str) -> Result<Self> {
        let named = |n| {
            Ok(Aperture::Polygon {
                blades: n,
                rotation_deg: 0.0,
            })
        };
        match s {
            "circle" => Ok(Aperture::Circle),
            "triangle" => named(3),
            "square" => named(4),
            "pentagon" => named(5),
            "hexagon" => named(6),
            "heptagon" => named(7),
            "octagon" => named(8),
            _ => {
                let parts: Vec<&str> = s.split(':').collect();
                if parts[0] == "polygon" && (2..=3).contains(&parts.len()) {
                    let blades: u32 = parts[1].parse().map_err(|_| {
                        Error::param("aperture", format!("bad blade count in '{s}'"))
                    })?;
                    let rotation_deg: f64 = match parts.get(2) {
                        Some(r) => r.parse().map_err(|_| {
                            Error::param("aperture", format!("bad rotation in '{s}'"))
                        })?,
                        None => 0.0,
                    };
                    let a = Aperture::Polygon {
                        blades,
                        rotation_deg,
                    };
                    a.validate()?;
                    Ok(a)
                } else {
                    Err(Error::param(
                        "aperture",
                        format!(
                            "unknown aperture '{s}': use circle, polygon:N[:DEG], hexagon, ... or kernel:IMAGE"
                        ),
                    ))
                }
            }
        }
    }

    /// Checks parameters (blade count 3..=64, finite rotation).
    pub fn validate(&self) -> Result<()> {
        if let Aperture::Polygon {
            blades,
            rotation_deg,
        } = self
        {
            if !(3..=64).contains(blades) {
                return Err(Error::param(
                    "aperture",
                    format!("polygon needs 3 to 64 blades, got {blades}"),
                ));
            }
            if !rotation_deg.is_finite() {
                return Err(Error::param("aperture", "rotation must be finite"));
            }
        }
        Ok(())
    }

    /// The gauge ("radius") of offset (dx, dy): the r at which the offset lies on the
    /// shape's boundary. Euclidean distance for the circle; for the polygon,
    /// `|v| cos(delta) / cos(pi/n)` with `delta` the angle to the nearest edge normal.
    /// Not used by kernel apertures (which are not scaled copies of a convex shape).
    /// Equation M5 of docs/model.md.
    pub fn gauge(&self, dx: f64, dy: f64) -> f64 {
        let dist = (dx * dx + dy * dy).sqrt();
        match self {
            Aperture::Polygon {
                blades,
                rotation_deg,
            } if dist > 0.0 => {
                let n = *blades as f64;
                let sector = 2.0 * std::f64::consts::PI / n;
                let half = sector / 2.0;
                let theta = dy.atan2(dx) - rotation_deg.to_radians() - half;
                let delta = theta.rem_euclid(sector) - half;
                dist * delta.cos() / half.cos()
            }
            _ => dist,
        }
    }
}
