//! The sun as a light of finite size: a small deterministic set of directions and weights
//! over its disc, for the renderer to integrate the diffraction term over (the coherence
//! lobes, ~0.005 wide in `u`, are narrower than the sun's 0.53°, 0.0093 rad: a point light
//! draws them as hairlines that a real sun smears out).
//!
//! The disc is a spherical cap of uniform radiance. The directions are a sunflower (Vogel)
//! spiral with equal-area placement on the cap — point `k` of `n` at `1 − cos ρ_k =
//! (k + ½)/n · (1 − cos α)` and azimuth `k·` the golden angle — so equal weights `1/n` are
//! a quadrature of the uniform cap with no clumping and no preferred axis. Pure geometry:
//! no Vulkan, no physics. [`env`] holds the environment maps and their importance sampling,
//! [`sky`] the scene's ambient light as a uniform sky.

use glam::DVec3;

pub mod area;
pub mod env;
pub mod set;
pub mod sky;

/// Largest accepted angular diameter (degrees): beyond it the light is no longer a sun.
pub const MAX_ANGULAR_DIAMETER_DEG: f32 = 20.0;

/// Largest accepted number of directions.
pub const MAX_DISK_SAMPLES: u32 = 256;

/// Largest radiance or irradiance a light may carry to the device. float32 holds 3.4e38;
/// the estimator's sums over its samples and the BRDF's peaks over its sampling density
/// need the other eight decades. Measured: an environment of 1e35
/// still renders in proportion, one of 1e38 is lost in the sums.
pub const MAX_RADIOMETRIC: f64 = 1e30;

/// Smallest non-zero radiance or irradiance a light may carry: the products with a dim
/// BRDF value (1e-6) stay normal float32 numbers (above 1.2e-38), never flushed to zero.
pub const MIN_RADIOMETRIC: f64 = 1e-30;

/// Checks a radiometric value on its way to the device (a light's radiance or irradiance,
/// after every scale it meets on the host): 0, or within [`MIN_RADIOMETRIC`] to
/// [`MAX_RADIOMETRIC`]. `what` names the value as the user wrote it.
pub fn check_radiometric(what: &str, v: f64) -> Result<(), String> {
    if v == 0.0 || (MIN_RADIOMETRIC..=MAX_RADIOMETRIC).contains(&v) {
        return Ok(());
    }
    let v = if v.is_finite() {
        format!("{v:.3e}")
    } else {
        "beyond float64".to_string()
    };
    Err(format!(
        "{what} = {v}: must be 0 or within {MIN_RADIOMETRIC:e} to {MAX_RADIOMETRIC:e} to be \
         carried in float32 on the device"
    ))
}

/// One direction towards a point of the light's disc (unit, world space) and its weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiskSample {
    pub towards_light: [f32; 3],
    pub weight: f32,
}

/// `n` directions over a disc of `angular_diameter_deg` centred on `towards_light` (the
/// unit vector from the surface to the light's centre; normalised here). Weights sum to 1.
/// `n = 1` or a diameter of 0 give the centre alone (a point light). `n` is clamped to
/// `1..=MAX_DISK_SAMPLES`; a zero or non-finite centre gives `+z`.
pub fn sun_disk_samples(
    towards_light: [f32; 3],
    angular_diameter_deg: f32,
    n: u32,
) -> Vec<DiskSample> {
    let c = DVec3::from(towards_light.map(f64::from))
        .try_normalize()
        .unwrap_or(DVec3::Z);
    let n = n.clamp(1, MAX_DISK_SAMPLES) as usize;
    // NaN → 0 (`max` returns the other operand): a point light.
    let half = f64::from(angular_diameter_deg).to_radians().max(0.0) / 2.0;
    if n == 1 || half <= 0.0 {
        return vec![DiskSample {
            towards_light: c.as_vec3().to_array(),
            weight: 1.0,
        }];
    }
    // Any orthonormal pair perpendicular to the centre.
    let e1 = c.any_orthonormal_vector();
    let e2 = c.cross(e1);
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let one_minus_cos_alpha = 1.0 - half.cos();
    (0..n)
        .map(|k| {
            let t = (k as f64 + 0.5) / n as f64;
            let cos_rho = 1.0 - t * one_minus_cos_alpha;
            let sin_rho = (1.0 - cos_rho * cos_rho).max(0.0).sqrt();
            let (s, co) = (k as f64 * golden).sin_cos();
            let d = c * cos_rho + (e1 * co + e2 * s) * sin_rho;
            DiskSample {
                towards_light: d.normalize().as_vec3().to_array(),
                weight: (1.0 / n as f64) as f32,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn angle(a: [f32; 3], b: DVec3) -> f64 {
        DVec3::from(a.map(f64::from)).dot(b).clamp(-1.0, 1.0).acos()
    }

    #[test]
    fn radiometric_values_must_fit_float32_with_room_for_the_sums() {
        for ok in [0.0, 1e-30, 1.0, 1e30] {
            assert!(check_radiometric("x", ok).is_ok(), "{ok}");
        }
        for bad in [1e-31, 1.1e30, 1e38, 1e300, f64::INFINITY] {
            let e = check_radiometric("intensity", bad).unwrap_err();
            assert!(e.starts_with("intensity = ") && e.contains("1e30"), "{e}");
            assert!(e.len() < 200, "{e}");
        }
    }

    #[test]
    fn weights_sum_to_one_and_directions_stay_in_the_cone() {
        let centre = DVec3::new(0.2, 0.7, -0.3).normalize();
        for (diam, n) in [
            (0.53f32, 8u32),
            (0.53, 16),
            (5.0, 64),
            (20.0, 256),
            (0.53, 3),
        ] {
            let s = sun_disk_samples(centre.as_vec3().to_array(), diam, n);
            assert_eq!(s.len(), n as usize);
            let sum: f64 = s.iter().map(|d| f64::from(d.weight)).sum();
            assert!((sum - 1.0).abs() < 1e-6, "{sum}");
            let half = f64::from(diam).to_radians() / 2.0;
            // f32 directions: an ulp of a unit vector is ~6e-8 rad.
            for d in &s {
                let l = DVec3::from(d.towards_light.map(f64::from)).length();
                assert!((l - 1.0).abs() < 1e-6);
                assert!(angle(d.towards_light, centre) <= half + 1e-6, "{diam} {n}");
            }
            // Equal-area placement: the weighted mean of 1 − cos ρ is that of the uniform
            // cap, (1 − cos α)/2 (exact for the sunflower in exact arithmetic).
            let m: f64 = s
                .iter()
                .map(|d| f64::from(d.weight) * (1.0 - angle(d.towards_light, centre).cos()))
                .sum();
            let want = (1.0 - half.cos()) / 2.0;
            assert!((m / want - 1.0).abs() < 0.05, "{diam} {n}: {m} vs {want}");
            // No preferred side: the centroid of the offsets is small against the radius.
            let mean: DVec3 = s
                .iter()
                .map(|d| DVec3::from(d.towards_light.map(f64::from)) * f64::from(d.weight))
                .sum();
            let off = (mean - centre * mean.dot(centre)).length();
            if n >= 8 {
                assert!(off < 0.15 * half.sin(), "{diam} {n}: {off}");
            }
        }
    }

    #[test]
    fn a_point_light_is_the_centre_alone_and_samples_are_deterministic() {
        let c = [0.0f32, 0.0, 2.0];
        for s in [sun_disk_samples(c, 0.0, 16), sun_disk_samples(c, 0.53, 1)] {
            assert_eq!(
                s,
                vec![DiskSample {
                    towards_light: [0.0, 0.0, 1.0],
                    weight: 1.0
                }]
            );
        }
        assert_eq!(sun_disk_samples(c, 0.53, 0).len(), 1);
        assert_eq!(
            sun_disk_samples(c, 0.53, 9999).len(),
            MAX_DISK_SAMPLES as usize
        );
        assert_eq!(sun_disk_samples(c, 0.53, 12), sun_disk_samples(c, 0.53, 12));
        assert_eq!(
            sun_disk_samples([0.0; 3], 0.0, 1)[0].towards_light,
            [0.0, 0.0, 1.0]
        );
    }
}
