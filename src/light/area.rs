//! What a scene file says about lights besides the sun: `[[disc_light]]` tables (any number
//! of disc lights) and an `[environment]` table (an equirectangular map around the scene).
//!
//! Units (MODEL §10): a disc light of intensity `I` delivers irradiance `I` on a surface
//! facing it, like the sun of `[light]`; its radiance is uniform over the disc,
//! `I·colour/Ω` with `Ω = 2π(1 − cos α)` the disc's solid angle (`α` its angular radius),
//! so a map holding the same disc renders the same picture. `colour` is linear sRGB, white
//! `[1, 1, 1]` being D65 like the sun.

use serde::{Deserialize, Serialize};

use super::env::EnvSource;
use super::{sun_disk_samples, DiskSample, MAX_DISK_SAMPLES};

/// Largest angular diameter of a disc light (degrees): a hemisphere.
pub const MAX_DISC_DIAMETER_DEG: f32 = 180.0;

/// Most disc lights in one scene.
pub const MAX_DISC_LIGHTS: usize = 16;

/// One `[[disc_light]]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DiscLight {
    /// The direction the light travels, world space (as the sun's `[light] direction`).
    pub direction: [f32; 3],
    /// Angular diameter of the disc in degrees, 0..=180 (0: a point light).
    pub angular_diameter_deg: f32,
    /// Linear-sRGB colour; `[1, 1, 1]` is D65 white.
    pub colour: [f32; 3],
    /// Irradiance on a surface facing the light (≥ 0).
    pub intensity: f32,
    /// Directions the disc is summed over where it is not sampled, 1..=256.
    pub disk_samples: u32,
}

impl Default for DiscLight {
    fn default() -> Self {
        Self {
            direction: [0.0, -1.0, 0.0],
            angular_diameter_deg: 10.0,
            colour: [1.0, 1.0, 1.0],
            intensity: 1.0,
            disk_samples: 16,
        }
    }
}

impl DiscLight {
    /// Unit vector towards the light's centre, `−normalize(direction)`.
    pub fn towards_light(&self) -> [f64; 3] {
        let d = self.direction.map(f64::from);
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        [-d[0] / l, -d[1] / l, -d[2] / l]
    }

    /// Half the angular diameter, radians.
    pub fn angular_radius(&self) -> f64 {
        f64::from(self.angular_diameter_deg).to_radians() / 2.0
    }

    /// Solid angle of the disc, `2π(1 − cos α)`; 0 for a point light.
    pub fn solid_angle(&self) -> f64 {
        2.0 * std::f64::consts::PI * (1.0 - self.angular_radius().cos())
    }

    /// Directions over the disc with weights summing to 1 (the sun's sunflower spiral).
    pub fn disk_samples(&self) -> Vec<DiskSample> {
        let t = self.towards_light().map(|x| x as f32);
        sun_disk_samples(t, self.angular_diameter_deg, self.disk_samples)
    }

    /// Checks one light; `index` is its place among the `[[disc_light]]` tables (from 1).
    pub fn validate(&self, index: usize) -> Result<(), String> {
        let what = format!("[disc_light] {index}:");
        let d = self.direction;
        if !d.iter().all(|c| c.is_finite()) || d.iter().all(|c| *c == 0.0) {
            return Err(format!(
                "{what} direction = {d:?}: must be finite and not the zero vector"
            ));
        }
        if !(0.0..=MAX_DISC_DIAMETER_DEG).contains(&self.angular_diameter_deg) {
            return Err(format!(
                "{what} angular_diameter_deg = {}: expected 0 to {MAX_DISC_DIAMETER_DEG} degrees",
                self.angular_diameter_deg
            ));
        }
        if !self.colour.iter().all(|c| c.is_finite() && *c >= 0.0) {
            return Err(format!(
                "{what} colour = {:?}: every component must be finite and ≥ 0",
                self.colour
            ));
        }
        if !(self.intensity.is_finite() && self.intensity >= 0.0) {
            return Err(format!(
                "{what} intensity = {}: must be finite and ≥ 0",
                self.intensity
            ));
        }
        self.check_float32(&what)?;
        if !(1..=MAX_DISK_SAMPLES).contains(&self.disk_samples) {
            return Err(format!(
                "{what} disk_samples = {}: expected 1 to {MAX_DISK_SAMPLES}",
                self.disk_samples
            ));
        }
        Ok(())
    }
}

impl DiscLight {
    /// The irradiance `I·colour` and, for a disc of non-zero size, the radiance
    /// `I·colour/Ω` the device carries must fit float32 ([`super::check_radiometric`]).
    fn check_float32(&self, what: &str) -> Result<(), String> {
        let peak = f64::from(self.intensity)
            * self.colour.iter().fold(0.0f64, |m, &c| m.max(f64::from(c)));
        super::check_radiometric(&format!("{what} intensity × colour"), peak)?;
        let omega = self.solid_angle();
        if omega > 0.0 {
            super::check_radiometric(
                &format!("{what} radiance intensity × colour / solid angle"),
                peak / omega,
            )?;
        }
        Ok(())
    }
}

/// The `[environment]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentSpec {
    /// `builtin:white|sky|studio` or an `.hdr`/`.exr` path (relative to the scene file).
    pub map: String,
    /// Radiance scale (≥ 0).
    #[serde(default = "one")]
    pub intensity: f64,
    /// Rotation of the map about `+Y`, degrees.
    #[serde(default)]
    pub rotate_deg: f64,
}

fn one() -> f64 {
    1.0
}

impl EnvironmentSpec {
    /// Where the map comes from.
    pub fn source(&self) -> crate::Result<EnvSource> {
        EnvSource::parse(&self.map)
    }

    /// Checks the table (not the map's pixels: those are checked when it is loaded).
    pub fn validate(&self) -> Result<(), String> {
        if let Err(e) = self.source() {
            return Err(format!("[environment] map = \"{}\": {e}", self.map));
        }
        if !(self.intensity.is_finite() && self.intensity >= 0.0) {
            return Err(format!(
                "[environment] intensity = {}: must be finite and ≥ 0",
                self.intensity
            ));
        }
        // The map's pixels scale it further; that product is checked when the map loads.
        super::check_radiometric("[environment] intensity", self.intensity)?;
        if !self.rotate_deg.is_finite() {
            return Err(format!(
                "[environment] rotate_deg = {}: must be finite",
                self.rotate_deg
            ));
        }
        Ok(())
    }
}

/// Checks a scene's disc lights: each one, and how many there are.
pub fn validate_disc_lights(lights: &[DiscLight]) -> Result<(), String> {
    if lights.len() > MAX_DISC_LIGHTS {
        return Err(format!(
            "[disc_light]: {} lights; at most {MAX_DISC_LIGHTS}",
            lights.len()
        ));
    }
    for (i, l) in lights.iter().enumerate() {
        l.validate(i + 1)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disc_lights_check_their_numbers() {
        assert!(validate_disc_lights(&[DiscLight::default()]).is_ok());
        let bad = [
            DiscLight {
                direction: [0.0; 3],
                ..Default::default()
            },
            DiscLight {
                angular_diameter_deg: 200.0,
                ..Default::default()
            },
            DiscLight {
                colour: [1.0, -1.0, 0.0],
                ..Default::default()
            },
            DiscLight {
                intensity: f32::NAN,
                ..Default::default()
            },
            DiscLight {
                disk_samples: 0,
                ..Default::default()
            },
        ];
        for b in bad {
            let e = validate_disc_lights(&[DiscLight::default(), b]).unwrap_err();
            assert!(e.starts_with("[disc_light] 2:"), "{e}");
        }
        let many = vec![DiscLight::default(); MAX_DISC_LIGHTS + 1];
        assert!(validate_disc_lights(&many).unwrap_err().contains("at most"));
        let l = DiscLight {
            angular_diameter_deg: 60.0,
            ..Default::default()
        };
        // A 60° disc: 2π(1 − cos 30°).
        assert!(
            (l.solid_angle() - 2.0 * std::f64::consts::PI * (1.0 - 0.75f64.sqrt())).abs() < 1e-12
        );
        assert_eq!(l.towards_light(), [0.0, 1.0, 0.0]);
    }

    #[test]
    fn environment_tables_check_their_numbers() {
        let ok = EnvironmentSpec {
            map: "builtin:sky".into(),
            intensity: 2.0,
            rotate_deg: 90.0,
        };
        assert!(ok.validate().is_ok());
        for (e, want) in [
            (
                EnvironmentSpec {
                    map: "sky.png".into(),
                    ..ok.clone()
                },
                "map",
            ),
            (
                EnvironmentSpec {
                    intensity: -1.0,
                    ..ok.clone()
                },
                "intensity",
            ),
            (
                EnvironmentSpec {
                    rotate_deg: f64::INFINITY,
                    ..ok.clone()
                },
                "rotate_deg",
            ),
        ] {
            let msg = e.validate().unwrap_err();
            assert!(
                msg.starts_with("[environment] ") && msg.contains(want),
                "{msg}"
            );
        }
    }

    #[test]
    fn scenes_hold_disc_lights_and_an_environment() {
        use crate::scene::Scene;
        use std::path::Path;
        let text = "[environment]\nmap = \"maps/sky.hdr\"\nrotate_deg = 30.0\n\
                    [[disc_light]]\ndirection = [0.0, -1.0, 0.0]\n\
                    [[disc_light]]\nintensity = 2.0\ncolour = [1.0, 0.5, 0.25]\n";
        let s = Scene::from_toml_str(text, Path::new("/a/b/scene.toml")).unwrap();
        assert_eq!(s.disc_lights.len(), 2);
        assert_eq!(s.disc_lights[1].intensity, 2.0);
        let e = s.environment.unwrap();
        assert_eq!(e.map, "/a/b/maps/sky.hdr");
        assert_eq!((e.intensity, e.rotate_deg), (1.0, 30.0));
        assert!(Scene::default_scene().environment.is_none());
        assert!(Scene::default_scene().disc_lights.is_empty());
        let bad = Scene::from_toml_str("[[disc_light]]\nintensity = -1.0\n", Path::new("s.toml"));
        let msg = bad.unwrap_err().to_string();
        assert!(
            msg.contains("[disc_light] 1: intensity") && !msg.contains('\n'),
            "{msg}"
        );
        let bad = Scene::from_toml_str(
            "[environment]\nmap = \"builtin:moon\"\n",
            Path::new("s.toml"),
        );
        assert!(bad.unwrap_err().to_string().contains("builtin:moon"));
    }
}
