//! Lens optics for the path tracer: a thick biconvex spherical lens traced with Snell's law
//! at both surfaces, and an ideal thin lens kept beside it for validation.
//!
//! Coordinates are in millimetres. The optical axis is `z`; the lens centre is at the origin;
//! the scene lies at negative `z` and the sensor at positive `z`, so light from the scene
//! travels towards `+z`. Rays are traced *backwards*, from the sensor into the scene.

use crate::{Error, Result};
use glam::DVec3;

/// A ray: origin and unit direction (millimetres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin, mm.
    pub origin: DVec3,
    /// Unit direction.
    pub dir: DVec3,
}

/// Refracts unit direction `d` at a surface with unit normal `n` facing the incoming ray
/// (`n . d < 0`), going from index `eta_from` into `eta_to` (Snell's law in vector form).
/// Returns `None` on total internal reflection.
pub fn refract(d: DVec3, n: DVec3, eta_from: f64, eta_to: f64) -> Option<DVec3> {
    let ratio = eta_from / eta_to;
    let cos_i = -n.dot(d);
    let sin2_t = ratio * ratio * (1.0 - cos_i * cos_i);
    if sin2_t > 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((ratio * d + (ratio * cos_i - cos_t) * n).normalize())
}

/// Parameters along a ray where it meets a sphere (`None` if it misses).
fn sphere_hits(ray: &Ray, centre: DVec3, radius_mm: f64) -> Option<(f64, f64)> {
    let oc = ray.origin - centre;
    let b = oc.dot(ray.dir);
    let c = oc.length_squared() - radius_mm * radius_mm;
    let disc = b * b - c;
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    Some((-b - s, -b + s))
}

/// A biconvex lens: the intersection of two balls of radius `Rc` whose rim (where the two
/// spheres meet) has radius `Ra`; refractive index `eta`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SphericalLens {
    /// Radius of curvature `Rc` of both surfaces, mm.
    pub curvature_radius_mm: f64,
    /// Rim (aperture) radius `Ra` of the lens, mm.
    pub rim_radius_mm: f64,
    /// Refractive index of the glass.
    pub eta: f64,
}

impl SphericalLens {
    /// A validated lens. Fails (naming the parameter) unless `0 < Ra < Rc` and `1 < eta <= 4`.
    pub fn new(curvature_radius_mm: f64, rim_radius_mm: f64, eta: f64) -> Result<Self> {
        let finite_pos = |v: f64| v.is_finite() && v > 0.0;
        if !finite_pos(curvature_radius_mm) {
            return Err(Error::param(
                "lens.curvature_radius_mm",
                format!("must be a positive number, got {curvature_radius_mm}"),
            ));
        }
        if !finite_pos(rim_radius_mm) {
            return Err(Error::param(
                "lens.rim_radius_mm",
                format!("must be a positive number, got {rim_radius_mm}"),
            ));
        }
        if rim_radius_mm >= curvature_radius_mm {
            return Err(Error::param(
                "lens.rim_radius_mm",
                format!(
                    "rim radius Ra = {rim_radius_mm} mm must be smaller than the curvature radius Rc = {curvature_radius_mm} mm (two spheres of radius Rc cannot meet in a wider rim)"
                ),
            ));
        }
        if !eta.is_finite() || eta <= 1.0 || eta > 4.0 {
            return Err(Error::param(
                "lens.eta",
                format!("refractive index must be in (1, 4], got {eta}"),
            ));
        }
        Ok(SphericalLens {
            curvature_radius_mm,
            rim_radius_mm,
            eta,
        })
    }

    /// Distance from the lens centre to each sphere centre, `sqrt(Rc^2 - Ra^2)` (the centres
    /// are twice this apart).
    pub fn half_centre_distance_mm(&self) -> f64 {
        let (rc, ra) = (self.curvature_radius_mm, self.rim_radius_mm);
        (rc * rc - ra * ra).sqrt()
    }

    /// Distance between the two sphere centres, `2 sqrt(Rc^2 - Ra^2)`.
    pub fn centre_distance_mm(&self) -> f64 {
        2.0 * self.half_centre_distance_mm()
    }

    /// Axial thickness `t = 2 (Rc - sqrt(Rc^2 - Ra^2))`.
    pub fn thickness_mm(&self) -> f64 {
        2.0 * (self.curvature_radius_mm - self.half_centre_distance_mm())
    }

    /// Effective focal length from the thick-lens lensmaker's equation with R1 = Rc,
    /// R2 = -Rc: `1/f = (eta - 1) (2/Rc - (eta - 1) t / (eta Rc^2))`.
    pub fn focal_length_mm(&self) -> f64 {
        let (n, rc, t) = (self.eta, self.curvature_radius_mm, self.thickness_mm());
        1.0 / ((n - 1.0) * (2.0 / rc - (n - 1.0) * t / (n * rc * rc)))
    }

    /// The focal length as the published supplement prints it (`+` before the thickness
    /// term). Wrong; kept only so a test can show that tracing disagrees with it.
    pub fn focal_length_printed_variant_mm(&self) -> f64 {
        let (n, rc, t) = (self.eta, self.curvature_radius_mm, self.thickness_mm());
        1.0 / ((n - 1.0) * (2.0 / rc + (n - 1.0) * t / (n * rc * rc)))
    }

    /// How far each principal plane lies inside the lens from its vertex:
    /// `f (eta - 1) t / (eta Rc)` (paraxial thick-lens theory).
    pub fn principal_plane_inset_mm(&self) -> f64 {
        let (n, rc, t) = (self.eta, self.curvature_radius_mm, self.thickness_mm());
        self.focal_length_mm() * (n - 1.0) * t / (n * rc)
    }

    /// `z` of the object-side (front) principal plane H; object distances are measured from it.
    pub fn front_principal_plane_z_mm(&self) -> f64 {
        -0.5 * self.thickness_mm() + self.principal_plane_inset_mm()
    }

    /// `z` of the image-side (rear) principal plane H'; the sensor distance is measured from it.
    pub fn rear_principal_plane_z_mm(&self) -> f64 {
        0.5 * self.thickness_mm() - self.principal_plane_inset_mm()
    }

    /// `z` of the rear (sensor-side) vertex, where the aperture stop sits.
    pub fn rear_vertex_z_mm(&self) -> f64 {
        0.5 * self.thickness_mm()
    }

    /// Centre of the rear (sensor-side) surface's sphere.
    fn rear_centre(&self) -> DVec3 {
        DVec3::new(0.0, 0.0, -self.half_centre_distance_mm())
    }

    /// Centre of the front (scene-side) surface's sphere.
    fn front_centre(&self) -> DVec3 {
        DVec3::new(0.0, 0.0, self.half_centre_distance_mm())
    }

    /// Traces a ray coming from the sensor side (travelling towards `-z`) through the lens:
    /// refraction into the rear surface, through the glass, refraction out of the front
    /// surface. `stop_radius_mm` limits where the ray may enter the rear surface (the
    /// aperture stop at the rear vertex). Returns the ray leaving into the scene, or `None`
    /// if it misses the lens, is stopped, leaves through the rim or is totally reflected.
    pub fn trace_from_sensor_side(&self, ray: &Ray, stop_radius_mm: f64) -> Option<Ray> {
        let rc = self.curvature_radius_mm;
        let (c_rear, c_front) = (self.rear_centre(), self.front_centre());
        // Enter the rear surface: the near intersection with the rear ball, on its +z cap.
        let (t0, _) = sphere_hits(ray, c_rear, rc)?;
        if t0 < 0.0 {
            return None;
        }
        let p = ray.origin + t0 * ray.dir;
        if p.x * p.x + p.y * p.y > stop_radius_mm * stop_radius_mm || p.z < 0.0 {
            return None;
        }
        let n_rear = (p - c_rear) / rc; // outward, faces the incoming ray
        let d_glass = refract(ray.dir, n_rear, 1.0, self.eta)?;
        // Leave through the front ball's far side; it must lie inside the rear ball (the lens).
        let inner = Ray {
            origin: p,
            dir: d_glass,
        };
        let (_, t1) = sphere_hits(&inner, c_front, rc)?;
        let q = p + t1 * d_glass;
        if q.z > 0.0 || (q - c_rear).length_squared() > rc * rc * (1.0 + 1e-12) {
            return None;
        }
        let n_front = (c_front - q) / rc; // faces the ray travelling inside the glass
        let d_out = refract(d_glass, n_front, self.eta, 1.0)?;
        Some(Ray {
            origin: q,
            dir: d_out,
        })
    }
}

/// Where a lens brings paraxial light to a focus, found by tracing (no formulas): parallel
/// rays at small heights enter from the sensor side and leave into the scene side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracedFocus {
    /// Effective focal length, mm: distance from the traced principal plane to the traced
    /// best focus (equivalently, entrance height over exit slope).
    pub focal_length_mm: f64,
    /// `z` of the best (least-squares) paraxial focus.
    pub best_focus_z_mm: f64,
    /// `z` of the principal plane, where the exit rays' extensions reach the entry heights.
    pub principal_plane_z_mm: f64,
}

/// Finds the paraxial best focus of `lens` by tracing a fan of parallel rays at heights up
/// to `max_height_mm` (choose well below the rim for the paraxial limit). The lens is
/// symmetric, so the focus found on the scene side equals the one on the sensor side.
pub fn trace_paraxial_focus(
    lens: &SphericalLens,
    max_height_mm: f64,
    rays: usize,
) -> Result<TracedFocus> {
    let z_start = lens.rear_vertex_z_mm() + 10.0;
    // Least squares over z: minimise sum_i (x_i + s_i (z - z0_i))^2 on the exit rays.
    let (mut num, mut den) = (0.0, 0.0);
    let mut exits = Vec::with_capacity(rays);
    for i in 1..=rays {
        let h = max_height_mm * i as f64 / rays as f64;
        let ray = Ray {
            origin: DVec3::new(h, 0.0, z_start),
            dir: DVec3::new(0.0, 0.0, -1.0),
        };
        let out = lens
            .trace_from_sensor_side(&ray, lens.rim_radius_mm)
            .ok_or_else(|| {
                Error::param(
                    "paraxial trace",
                    format!("ray at height {h} mm was blocked"),
                )
            })?;
        let slope = out.dir.x / out.dir.z; // dx/dz
        let x_at_zero = out.origin.x - slope * out.origin.z; // x at z = 0
        num += x_at_zero * slope;
        den += slope * slope;
        exits.push((h, slope, x_at_zero));
    }
    let best_focus_z_mm = -num / den;
    // Principal plane: where the exit ray's extension has the entry height h.
    let mut plane = 0.0;
    for &(h, slope, x0) in &exits {
        plane += (h - x0) / slope;
    }
    let principal_plane_z_mm = plane / exits.len() as f64;
    Ok(TracedFocus {
        focal_length_mm: principal_plane_z_mm - best_focus_z_mm,
        best_focus_z_mm,
        principal_plane_z_mm,
    })
}

/// Which lens forms the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LensModel {
    /// The thick spherical lens, traced with Snell's law.
    Spherical(SphericalLens),
    /// An ideal thin lens of this focal length (mm) at `z = 0`: every ray through a pupil
    /// point is aimed at the point of the focus plane that the chief ray meets.
    Thin {
        /// Focal length, mm.
        focal_length_mm: f64,
    },
}

/// A complete camera: lens, aperture stop, sensor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Optics {
    /// The lens.
    pub lens: LensModel,
    /// Radius of the aperture stop (entrance of rays at the lens), mm.
    pub aperture_radius_mm: f64,
    /// Distance `D_I` from the rear principal plane to the sensor, mm.
    pub sensor_distance_mm: f64,
    /// Pixel pitch on the sensor, mm.
    pub pixel_pitch_mm: f64,
    /// Image width, pixels.
    pub width_px: usize,
    /// Image height, pixels.
    pub height_px: usize,
}

impl Optics {
    /// A validated camera. `D_I` must exceed the focal length (else nothing is in focus).
    pub fn new(
        lens: LensModel,
        aperture_radius_mm: f64,
        sensor_distance_mm: f64,
        pixel_pitch_mm: f64,
        width_px: usize,
        height_px: usize,
    ) -> Result<Self> {
        let f = match lens {
            LensModel::Spherical(l) => {
                if aperture_radius_mm > l.rim_radius_mm {
                    return Err(Error::param(
                        "lens.aperture_radius_mm",
                        format!(
                            "aperture stop radius {aperture_radius_mm} mm exceeds the lens rim radius {} mm",
                            l.rim_radius_mm
                        ),
                    ));
                }
                l.focal_length_mm()
            }
            LensModel::Thin { focal_length_mm } => {
                if !focal_length_mm.is_finite() || focal_length_mm <= 0.0 {
                    return Err(Error::param(
                        "lens.focal_length_mm",
                        format!("must be a positive number, got {focal_length_mm}"),
                    ));
                }
                focal_length_mm
            }
        };
        if !aperture_radius_mm.is_finite() || aperture_radius_mm <= 0.0 {
            return Err(Error::param(
                "lens.aperture_radius_mm",
                format!("must be a positive number, got {aperture_radius_mm}"),
            ));
        }
        if !sensor_distance_mm.is_finite() || sensor_distance_mm <= f {
            return Err(Error::param(
                "camera.sensor_distance_mm",
                format!(
                    "sensor distance D_I = {sensor_distance_mm} mm must exceed the focal length f = {f:.4} mm (otherwise no object is in focus)"
                ),
            ));
        }
        if !pixel_pitch_mm.is_finite() || pixel_pitch_mm <= 0.0 {
            return Err(Error::param(
                "camera.fov_deg",
                format!("gives an invalid pixel pitch {pixel_pitch_mm} mm"),
            ));
        }
        crate::image::check_dimensions("camera", width_px, height_px)?;
        Ok(Optics {
            lens,
            aperture_radius_mm,
            sensor_distance_mm,
            pixel_pitch_mm,
            width_px,
            height_px,
        })
    }

    /// Focal length, mm.
    pub fn focal_length_mm(&self) -> f64 {
        match self.lens {
            LensModel::Spherical(l) => l.focal_length_mm(),
            LensModel::Thin { focal_length_mm } => focal_length_mm,
        }
    }

    /// Object distance (from the front principal plane) that is in focus:
    /// `z_f = 1 / (1/f - 1/D_I)`.
    pub fn focus_distance_mm(&self) -> f64 {
        1.0 / (1.0 / self.focal_length_mm() - 1.0 / self.sensor_distance_mm)
    }

    /// `z` of the front principal plane (object distances are measured from it).
    pub fn front_principal_plane_z_mm(&self) -> f64 {
        match self.lens {
            LensModel::Spherical(l) => l.front_principal_plane_z_mm(),
            LensModel::Thin { .. } => 0.0,
        }
    }

    /// `z` of the sensor plane.
    pub fn sensor_z_mm(&self) -> f64 {
        let rear = match self.lens {
            LensModel::Spherical(l) => l.rear_principal_plane_z_mm(),
            LensModel::Thin { .. } => 0.0,
        };
        rear + self.sensor_distance_mm
    }

    /// `z` of the plane at object distance `depth_mm` in front of the lens.
    pub fn object_plane_z_mm(&self, depth_mm: f64) -> f64 {
        self.front_principal_plane_z_mm() - depth_mm
    }

    /// Paraxial circle-of-confusion radius on the sensor, in pixels:
    /// `r_px = Ra D_I |1/z - 1/z_f| / pixel_pitch` (Ra = aperture stop radius).
    pub fn coc_radius_px(&self, depth_mm: f64) -> f64 {
        self.aperture_radius_mm
            * self.sensor_distance_mm
            * (1.0 / depth_mm - 1.0 / self.focus_distance_mm()).abs()
            / self.pixel_pitch_mm
    }

    /// Sensor width, mm.
    pub fn sensor_width_mm(&self) -> f64 {
        self.width_px as f64 * self.pixel_pitch_mm
    }

    /// Sensor height, mm.
    pub fn sensor_height_mm(&self) -> f64 {
        self.height_px as f64 * self.pixel_pitch_mm
    }

    /// The sensor point for image position (`x_px`, `y_px`) (continuous, pixel centres at
    /// +0.5). The image is rotated by 180 degrees on the sensor so that the lens's inverted
    /// image reads upright: image x grows with scene x, image y with scene y.
    pub fn sensor_point(&self, x_px: f64, y_px: f64) -> DVec3 {
        let sx = (x_px - 0.5 * self.width_px as f64) * self.pixel_pitch_mm;
        let sy = (y_px - 0.5 * self.height_px as f64) * self.pixel_pitch_mm;
        DVec3::new(-sx, -sy, self.sensor_z_mm())
    }

    /// The scene ray for a sensor point and a pupil point `(px, py)` on the unit disc
    /// (scaled by the aperture stop radius). `None` if the lens blocks it.
    pub fn trace(&self, sensor: DVec3, pupil: (f64, f64)) -> Option<Ray> {
        let a = self.aperture_radius_mm;
        match self.lens {
            LensModel::Spherical(lens) => {
                let (x, y) = (pupil.0 * a, pupil.1 * a);
                let rc = lens.curvature_radius_mm;
                let z = -lens.half_centre_distance_mm() + (rc * rc - x * x - y * y).sqrt();
                let target = DVec3::new(x, y, z);
                let ray = Ray {
                    origin: sensor,
                    dir: (target - sensor).normalize(),
                };
                // A hair of slack so the sampled rim point itself is accepted.
                lens.trace_from_sensor_side(&ray, a * (1.0 + 1e-9))
            }
            LensModel::Thin { .. } => {
                let p = DVec3::new(pupil.0 * a, pupil.1 * a, 0.0);
                // The chief ray through the centre meets the focus plane at `focus`.
                let zf = self.focus_distance_mm();
                let focus = -sensor * (zf / sensor.z);
                Some(Ray {
                    origin: p,
                    dir: (focus - p).normalize(),
                })
            }
        }
    }

    /// The chief ray (the lens stopped down to the centre of its aperture stop).
    pub fn chief_ray(&self, sensor: DVec3) -> Option<Ray> {
        self.trace(sensor, (0.0, 0.0))
    }
}

/// The plane-position of a ray at `z` (`None` if the ray does not travel towards `-z`).
#[inline]
pub fn hit_plane_z(ray: &Ray, z: f64) -> Option<(f64, f64)> {
    if ray.dir.z >= 0.0 {
        return None;
    }
    let t = (z - ray.origin.z) / ray.dir.z;
    if t < 0.0 {
        return None;
    }
    Some((ray.origin.x + t * ray.dir.x, ray.origin.y + t * ray.dir.y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometry_uses_corrected_formulas() {
        let l = SphericalLens::new(50.0, 30.0, 1.5).unwrap();
        assert!((l.centre_distance_mm() - 80.0).abs() < 1e-12);
        assert!((l.thickness_mm() - 20.0).abs() < 1e-12);
        // The rim: both spheres pass through (Ra, 0, 0).
        let rim = DVec3::new(30.0, 0.0, 0.0);
        assert!(((rim - l.front_centre()).length() - 50.0).abs() < 1e-9);
        assert!(((rim - l.rear_centre()).length() - 50.0).abs() < 1e-9);
    }

    #[test]
    fn snell_law_holds() {
        let n = DVec3::new(0.0, 0.0, 1.0);
        let d = DVec3::new(0.6, 0.0, -0.8);
        let t = refract(d, n, 1.0, 1.5).unwrap();
        let sin_i = 0.6;
        let sin_t = t.x;
        assert!((sin_i - 1.5 * sin_t).abs() < 1e-12);
        assert!(refract(DVec3::new(0.9, 0.0, -(1.0f64 - 0.81).sqrt()), n, 1.5, 1.0).is_none());
    }

    #[test]
    fn impossible_lenses_are_rejected() {
        assert!(SphericalLens::new(10.0, 10.0, 1.5).is_err());
        assert!(SphericalLens::new(10.0, 12.0, 1.5).is_err());
        assert!(SphericalLens::new(10.0, 5.0, 1.0).is_err());
        let l = SphericalLens::new(100.0, 10.0, 1.5).unwrap();
        let f = l.focal_length_mm();
        assert!(Optics::new(LensModel::Spherical(l), 5.0, f * 0.99, 0.01, 8, 8).is_err());
        assert!(Optics::new(LensModel::Spherical(l), 11.0, f * 1.1, 0.01, 8, 8).is_err());
        assert!(Optics::new(LensModel::Spherical(l), 5.0, f * 1.1, 0.01, 8, 8).is_ok());
    }

    /// The lensmaker's focal length (minus sign) matches the traced paraxial focus within
    /// 0.5%; the supplement's printed variant (plus sign) does not.
    #[test]
    fn lensmaker_matches_traced_paraxial_focus() {
        for (rc, ra) in [(50.0, 12.5), (100.0, 40.0), (60.0, 45.0)] {
            let l = SphericalLens::new(rc, ra, 1.5).unwrap();
            let traced = trace_paraxial_focus(&l, 1e-3 * ra, 8).unwrap();
            let f = l.focal_length_mm();
            let rel = (traced.focal_length_mm - f).abs() / f;
            assert!(
                rel < 0.005,
                "Rc {rc}, Ra {ra}: traced {} vs lensmaker {f}",
                traced.focal_length_mm
            );
            let printed = l.focal_length_printed_variant_mm();
            let rel_printed = (traced.focal_length_mm - printed).abs() / printed;
            assert!(
                rel_printed > 0.005,
                "Rc {rc}, Ra {ra}: printed variant {printed} also matches"
            );
            // The principal plane the sensor distance is measured from is where tracing puts it.
            let plane = -l.rear_principal_plane_z_mm(); // symmetric lens, scene side
            assert!((traced.principal_plane_z_mm - plane).abs() < 1e-3 * f);
        }
    }
}
