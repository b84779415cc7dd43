//! Every light of a picture behind one interface. A [`Light`] gives the radiance that
//! arrives along a direction, draws directions and states the density it draws them with,
//! in f64: the environment ([`EnvLight`]), a disc light ([`SampledDisc`]) and the mixture
//! of them that a picture is lit by ([`LightSet`]). The scene's ambient is a uniform
//! environment ([`crate::light::sky`], drawn as a map by the compute stages). Point lights
//! (the directions of the sun's pre-filtered disc, a disc light of no size) carry no
//! radiance along any one direction: they are evaluated in full ([`PointLight`]).
//!
//! The compute stages' light sampler (glsl/env_common.glsl: `radianceAt`, `sampleLight`,
//! `sampleCone`) is [`LightSet`] in float32: the same lights, packed by
//! [`Lights::buffer`], chosen with the probabilities of [`Lights::probabilities`], each
//! drawn as [`Light::sample`] draws it. The f64 references integrate any [`Light`]
//! ([`crate::brdf::env_reference::env_radiance`]).

use std::f64::consts::PI;
use std::sync::OnceLock;

use crate::colour::linear_srgb_to_xyz;
use crate::light::env::{EnvMap, EnvSampler};

/// A light seen from a surface point: radiance along each direction, a sampler of
/// directions and its density. Directions are world-space unit vectors towards the light.
pub trait Light {
    /// The radiance (XYZ) arriving along `towards`.
    fn radiance(&self, towards: [f64; 3]) -> [f64; 3];
    /// A direction drawn from `xi ∈ [0, 1)²` with its density in solid angle; `None` for a
    /// light that carries nothing.
    fn sample(&self, xi: [f64; 2]) -> Option<([f64; 3], f64)>;
    /// The density in solid angle with which [`Self::sample`] draws `towards`.
    fn pdf(&self, towards: [f64; 3]) -> f64;
    /// The luminance moments `(∫ Y dω, ∫ Y² dω)` over the sphere: how bright the light is
    /// and how much of the sphere it fills.
    fn moments(&self) -> (f64, f64);
}

/// An environment map as a light: its radiance in XYZ, drawn by luminance
/// ([`EnvSampler`], made at the first draw: a light only evaluated needs none).
pub struct EnvLight<'a> {
    pub map: &'a EnvMap,
    sampler: OnceLock<EnvSampler>,
}

impl<'a> EnvLight<'a> {
    pub fn new(map: &'a EnvMap) -> Self {
        EnvLight {
            map,
            sampler: OnceLock::new(),
        }
    }

    pub fn sampler(&self) -> &EnvSampler {
        self.sampler.get_or_init(|| EnvSampler::new(self.map))
    }
}

impl Light for EnvLight<'_> {
    fn radiance(&self, towards: [f64; 3]) -> [f64; 3] {
        linear_srgb_to_xyz(self.map.radiance(towards))
    }

    fn sample(&self, xi: [f64; 2]) -> Option<([f64; 3], f64)> {
        self.sampler().sample(xi[0], xi[1])
    }

    fn pdf(&self, towards: [f64; 3]) -> f64 {
        self.sampler().pdf(towards)
    }

    fn moments(&self) -> (f64, f64) {
        self.map.moments()
    }
}

/// A light evaluated once per pixel, in full: a direction of the sun's disc, or a disc
/// light of no angular size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLight {
    /// Towards the light, world space, unit.
    pub towards: [f64; 3],
    /// Irradiance on a surface facing it, XYZ.
    pub irradiance_xyz: [f64; 3],
}

/// A disc light sampled uniformly in its cone (MODEL §10: radiance `I·colour/Ω`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampledDisc {
    /// Towards the disc's centre, world space, unit.
    pub towards: [f64; 3],
    /// Cosine of the angular radius.
    pub cos_radius: f64,
    /// Solid angle `2π(1 − cos α)`.
    pub solid_angle: f64,
    /// Radiance, XYZ.
    pub radiance_xyz: [f64; 3],
}

/// Least and most share of light samples among the BRDF's.
pub const LIGHT_SHARE: (f64, f64) = (1.0 / 8.0, 1.0);

/// The share of light samples (per BRDF sample) given the lights' luminance integral
/// `power = ∫ Y dω` and `square = ∫ Y² dω` over the sphere. Their ratio `power²/(4π·square)` is the part of
/// the sphere the light effectively fills (1 for a uniform sky, `Ω/4π` for one disc of
/// solid angle `Ω` on black). BRDF samples find light that fills the sphere; only light
/// samples find a small bright source. The share runs from [`LIGHT_SHARE`]'s least to its
/// most as `1 − √ratio` runs from 0.2 to 0.8 (smoothly): measured on the default scene,
/// few light samples serve best under `builtin:sky` (`1 − √ratio` = 0.17), one per BRDF
/// sample under `builtin:studio` (0.79). It never falls to 0, so every direction that
/// carries light can be drawn.
pub fn light_share(power: f64, square: f64) -> f64 {
    let (lo, hi) = LIGHT_SHARE;
    if !(power > 0.0 && square > 0.0) {
        return lo;
    }
    let ratio = (power * power / (4.0 * PI * square)).clamp(0.0, 1.0);
    let x = ((1.0 - ratio.sqrt() - 0.2) / 0.6).clamp(0.0, 1.0);
    lo + (hi - lo) * x * x * (3.0 - 2.0 * x)
}

/// One light sample every `m`-th BRDF sample: the largest power of two up to `1/share`
/// (at most 8, so that pictures read at multiples of 8 samples, as the viewer's are, draw
/// the same samples as offscreen ones) that divides every count in `counts` (the samples
/// at which passes end), so that the light samples are exactly `1/m` of the BRDF's, as the
/// estimator weighs them.
pub fn light_every(share: f64, counts: &[u32]) -> u32 {
    let mut m = 8u32;
    while m > 1 && (f64::from(m) * share > 1.0 + 1e-9 || counts.iter().any(|c| c % m != 0)) {
        m /= 2;
    }
    m
}

/// Every light besides the environment.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Lights {
    pub points: Vec<PointLight>,
    pub discs: Vec<SampledDisc>,
}

impl Lights {
    /// The light sampler's probabilities: the environment's (from its luminance integral
    /// `env_power`) and each disc's, in proportion to `Y·Ω`.
    pub fn probabilities(&self, env_power: f64) -> (f64, Vec<f64>) {
        let powers: Vec<f64> = self.discs.iter().map(|d| d.moments().0).collect();
        let total = env_power.max(0.0) + powers.iter().sum::<f64>();
        if total <= 0.0 {
            return (0.0, vec![0.0; powers.len()]);
        }
        (
            env_power.max(0.0) / total,
            powers.iter().map(|p| p / total).collect(),
        )
    }

    /// The probability that a sample is drawn from the lights rather than from the BRDF
    /// ([`light_share`]), from the environment and these discs.
    pub fn light_share(&self, env: &EnvMap) -> f64 {
        let (power, square) = env.moments();
        self.light_share_with(power, square)
    }

    /// [`Self::light_share`] with the environment's moments `(∫ Y dω, ∫ Y² dω)` given.
    pub fn light_share_with(&self, env_power: f64, env_square: f64) -> f64 {
        let (power, square) = self.moments_with((env_power, env_square));
        light_share(power, square)
    }

    /// The luminance moments of the discs added to the environment's `env`.
    fn moments_with(&self, env: (f64, f64)) -> (f64, f64) {
        self.discs.iter().fold(env, |(power, square), d| {
            let (p, q) = d.moments();
            (power + p, square + q)
        })
    }

    /// The shader's light buffer (glsl/env_common.glsl's `Lights`) with the discs'
    /// probabilities ([`Self::probabilities`]) and, for texture blending, the
    /// environment's irradiance table.
    pub fn buffer(&self, disc_probs: &[f64], irradiance: &[[f64; 3]]) -> Vec<f32> {
        let mut v = Vec::new();
        for p in &self.points {
            v.extend(p.towards.iter().chain(&[0.0]).map(|&x| x as f32));
            v.extend(p.irradiance_xyz.iter().chain(&[0.0]).map(|&x| x as f32));
        }
        for (d, q) in self.discs.iter().zip(disc_probs) {
            v.extend(d.towards.iter().chain(&[d.cos_radius]).map(|&x| x as f32));
            v.extend(
                d.radiance_xyz
                    .iter()
                    .chain(&[d.solid_angle])
                    .map(|&x| x as f32),
            );
            v.extend([*q as f32, 0.0, 0.0, 0.0]);
        }
        for e in irradiance {
            v.extend(e.iter().chain(&[0.0]).map(|&x| x as f32));
        }
        if v.is_empty() {
            v.extend([0.0; 4]);
        }
        v
    }
}

impl SampledDisc {
    fn holds(&self, towards: [f64; 3]) -> bool {
        dot(towards, self.towards) >= self.cos_radius
    }
}

/// Drawn uniformly in its cone, as `sampleCone` in glsl/env_common.glsl.
impl Light for SampledDisc {
    fn radiance(&self, towards: [f64; 3]) -> [f64; 3] {
        if self.holds(towards) {
            self.radiance_xyz
        } else {
            [0.0; 3]
        }
    }

    fn sample(&self, xi: [f64; 2]) -> Option<([f64; 3], f64)> {
        if self.solid_angle.is_nan() || self.solid_angle <= 0.0 {
            return None;
        }
        let a = self.towards;
        let ct = 1.0 - xi[0] * (1.0 - self.cos_radius);
        let st = (1.0 - ct * ct).max(0.0).sqrt();
        let phi = 2.0 * PI * xi[1];
        let helper = if a[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let e1 = normalised(cross(a, helper));
        let e2 = cross(a, e1);
        let (s, c) = phi.sin_cos();
        let d = std::array::from_fn(|k| ct * a[k] + st * (c * e1[k] + s * e2[k]));
        Some((d, 1.0 / self.solid_angle))
    }

    fn pdf(&self, towards: [f64; 3]) -> f64 {
        if self.solid_angle > 0.0 && self.holds(towards) {
            1.0 / self.solid_angle
        } else {
            0.0
        }
    }

    fn moments(&self) -> (f64, f64) {
        let y = self.radiance_xyz[1].max(0.0);
        (y * self.solid_angle, y * y * self.solid_angle)
    }
}

/// The lights a picture's samples draw from: the environment (if any) and the disc
/// lights, each chosen with its probability ([`Lights::probabilities`]); the density of a
/// direction is the mixture's, summed over every light that holds it. `lights.points` are
/// not part of it (evaluated in full).
pub struct LightSet<'a> {
    pub env: Option<EnvLight<'a>>,
    pub lights: &'a Lights,
    /// The environment's and each disc's probability.
    probabilities: (f64, Vec<f64>),
}

impl<'a> LightSet<'a> {
    pub fn new(env: Option<&'a EnvMap>, lights: &'a Lights) -> Self {
        let env = env.map(EnvLight::new);
        let power = env.as_ref().map_or(0.0, |e| e.moments().0);
        LightSet {
            probabilities: lights.probabilities(power),
            env,
            lights,
        }
    }
}

impl Light for LightSet<'_> {
    fn radiance(&self, towards: [f64; 3]) -> [f64; 3] {
        let mut l = self.env.as_ref().map_or([0.0; 3], |e| e.radiance(towards));
        for d in &self.lights.discs {
            let r = d.radiance(towards);
            l = std::array::from_fn(|k| l[k] + r[k]);
        }
        l
    }

    /// The environment when `xi[0]` falls in its probability, else the disc whose
    /// probability it falls in, `xi[0]` rescaled to that interval (as `sampleLight`).
    fn sample(&self, xi: [f64; 2]) -> Option<([f64; 3], f64)> {
        let (q_env, q_discs) = &self.probabilities;
        let pick = |lo: f64, q: f64| ((xi[0] - lo) / q.max(1e-300)).clamp(0.0, 1.0);
        let d = match &self.env {
            Some(e) if xi[0] < *q_env => e.sample([pick(0.0, *q_env), xi[1]])?.0,
            _ => {
                let mut acc = *q_env;
                let last = self.lights.discs.len().checked_sub(1)?;
                let j = q_discs
                    .iter()
                    .position(|q| {
                        acc += q;
                        xi[0] < acc
                    })
                    .unwrap_or(last);
                let lo = *q_env + q_discs[..j].iter().sum::<f64>();
                self.lights.discs[j]
                    .sample([pick(lo, q_discs[j]), xi[1]])?
                    .0
            }
        };
        let p = self.pdf(d);
        (p > 0.0).then_some((d, p))
    }

    fn pdf(&self, towards: [f64; 3]) -> f64 {
        let (q_env, q_discs) = &self.probabilities;
        let env = self.env.as_ref().map_or(0.0, |e| q_env * e.pdf(towards));
        let discs: f64 = self
            .lights
            .discs
            .iter()
            .zip(q_discs)
            .map(|(d, q)| q * d.pdf(towards))
            .sum();
        env + discs
    }

    fn moments(&self) -> (f64, f64) {
        let env = self.env.as_ref().map_or((0.0, 0.0), |e| e.moments());
        self.lights.moments_with(env)
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalised(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    a.map(|x| x / n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::light::env::EnvSource;

    #[test]
    fn the_light_share_follows_how_much_of_the_sphere_the_light_fills() {
        let white = EnvMap::load(&EnvSource::White, 1.0, 0.0).unwrap();
        let none = Lights::default();
        // A uniform sphere: ratio 1, the least share.
        assert!((none.light_share(&white) - LIGHT_SHARE.0).abs() < 1e-9);
        // One small disc on black: ratio Ω/4π, the most.
        let black = EnvMap::from_pixels(2, 1, vec![[0.0; 3]; 2], "black").unwrap();
        let alpha = 0.5f64.to_radians();
        let omega = 2.0 * PI * (1.0 - alpha.cos());
        let disc = Lights {
            points: Vec::new(),
            discs: vec![SampledDisc {
                towards: [0.0, 1.0, 0.0],
                cos_radius: alpha.cos(),
                solid_angle: omega,
                radiance_xyz: [1.0 / omega; 3],
            }],
        };
        assert!((disc.light_share(&black) - LIGHT_SHARE.1).abs() < 1e-9);
        // The built-in maps in between, in order; nothing lit at all: the least.
        let sky = EnvMap::load(&EnvSource::Sky, 1.0, 0.0).unwrap();
        let studio = EnvMap::load(&EnvSource::Studio, 1.0, 0.0).unwrap();
        let (a, b) = (none.light_share(&sky), none.light_share(&studio));
        assert!(LIGHT_SHARE.0 <= a && a < b && b <= LIGHT_SHARE.1, "{a} {b}");
        assert_eq!(light_share(0.0, 0.0), LIGHT_SHARE.0);
        // The ratio itself: half the sphere at radiance 1, the other half black: 1/2.
        let x = ((1.0 - 0.5f64.sqrt() - 0.2) / 0.6).clamp(0.0, 1.0);
        let want = LIGHT_SHARE.0 + (LIGHT_SHARE.1 - LIGHT_SHARE.0) * x * x * (3.0 - 2.0 * x);
        assert!((light_share(2.0 * PI, 2.0 * PI) - want).abs() < 1e-12);
    }

    #[test]
    fn light_samples_come_every_mth_sample_where_m_divides_the_counts() {
        assert_eq!(light_every(1.0 / 8.0, &[1024, 16]), 8);
        assert_eq!(light_every(1.0 / 8.0, &[1024, 4]), 4);
        assert_eq!(light_every(0.3, &[256]), 2);
        assert_eq!(light_every(1.0, &[256]), 1);
        assert_eq!(light_every(0.01, &[7]), 1);
        assert_eq!(light_every(0.01, &[96, 64]), 8);
    }

    /// A warm 20° disc and a cool 6° one over the sky.
    fn two_discs() -> Lights {
        let disc = |towards: [f64; 3], deg: f64, xyz: [f64; 3]| {
            let alpha = (deg / 2.0).to_radians();
            let omega = 2.0 * PI * (1.0 - alpha.cos());
            SampledDisc {
                towards: normalised(towards),
                cos_radius: alpha.cos(),
                solid_angle: omega,
                radiance_xyz: xyz.map(|c| c / omega),
            }
        };
        Lights {
            points: Vec::new(),
            discs: vec![
                disc([0.3, 0.8, -0.2], 20.0, [2.0, 1.8, 1.2]),
                disc([-0.6, 0.5, 0.4], 6.0, [0.5, 0.6, 0.9]),
            ],
        }
    }

    /// A direction uniform on the sphere from `xi`.
    fn sphere(xi: [f64; 2]) -> [f64; 3] {
        let z = 1.0 - 2.0 * xi[0];
        let r = (1.0 - z * z).max(0.0).sqrt();
        let (s, c) = (2.0 * PI * xi[1]).sin_cos();
        [r * c, z, r * s]
    }

    /// The 2-D Halton point `i` (bases 2 and 3).
    fn halton(i: u64) -> [f64; 2] {
        let radical = |mut n: u64, b: u64| {
            let (mut x, mut f) = (0.0, 1.0 / b as f64);
            while n > 0 {
                x += (n % b) as f64 * f;
                n /= b;
                f /= b as f64;
            }
            x
        };
        [radical(i, 2), radical(i, 3)]
    }

    #[test]
    fn the_mixture_density_integrates_to_one_and_its_samples_are_unbiased() {
        let sky = EnvMap::load(&EnvSource::Sky, 1.0, 25.0).unwrap();
        let lights = two_discs();
        let set = LightSet::new(Some(&sky), &lights);
        let (q_env, q_discs) = lights.probabilities(sky.moments().0);
        assert!((q_env + q_discs.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        // ∫ pdf dω and ∫ L dω by uniform directions on the sphere (independent of the
        // sampler), against the closed forms: 1, and the map's integral plus each disc's
        // radiance × solid angle.
        let n = 1 << 21;
        let (mut pdf_sum, mut l_sum) = (0.0, [0.0; 3]);
        for i in 0..n {
            let d = sphere(halton(i + 1));
            pdf_sum += set.pdf(d);
            let l = set.radiance(d);
            l_sum = std::array::from_fn(|k| l_sum[k] + l[k]);
        }
        let area = 4.0 * PI / n as f64;
        let integral = pdf_sum * area;
        assert!((integral - 1.0).abs() < 2e-3, "∫ pdf dω = {integral}");
        let mut want = linear_srgb_to_xyz(sky.integral());
        for d in &lights.discs {
            want = std::array::from_fn(|k| want[k] + d.radiance_xyz[k] * d.solid_angle);
        }
        // The light's own estimator, L/pdf over its samples, converges to the same.
        let m = 1 << 18;
        let mut est = [0.0; 3];
        for i in 0..m {
            let (d, p) = set.sample(halton(i + 1)).expect("a lit set");
            assert!((set.pdf(d) - p).abs() <= 1e-9 * p, "the density it states");
            let l = set.radiance(d);
            est = std::array::from_fn(|k| est[k] + l[k] / p);
        }
        for k in 0..3 {
            let by_sphere = l_sum[k] * area;
            let by_samples = est[k] / m as f64;
            assert!(
                (by_sphere / want[k] - 1.0).abs() < 5e-3,
                "channel {k}: uniform directions {by_sphere} vs {}",
                want[k]
            );
            assert!(
                (by_samples / want[k] - 1.0).abs() < 5e-3,
                "channel {k}: the light's samples {by_samples} vs {}",
                want[k]
            );
        }
    }

    #[test]
    fn a_disc_draws_inside_its_cone_at_its_stated_density() {
        let lights = two_discs();
        for d in &lights.discs {
            // Uniform in solid angle: cos of the angle to the axis is uniform on
            // [cos α, 1] (mean and variance), and the azimuth has no preferred side.
            let n = 20_000;
            let (mut mean, mut square, mut side) = (0.0, 0.0, [0.0; 3]);
            for i in 0..n {
                let (w, p) = d.sample(halton(i + 1)).unwrap();
                assert!((dot(w, w) - 1.0).abs() < 1e-12);
                let c = dot(w, d.towards);
                assert!(c >= d.cos_radius - 1e-12);
                assert_eq!(p, 1.0 / d.solid_angle);
                mean += c / n as f64;
                square += c * c / n as f64;
                side = std::array::from_fn(|k| side[k] + (w[k] - c * d.towards[k]) / n as f64);
            }
            let (a, width) = (d.cos_radius, 1.0 - d.cos_radius);
            assert!((mean - (1.0 + a) / 2.0).abs() < 1e-3 * width, "{mean}");
            let var = square - mean * mean;
            assert!((var / (width * width / 12.0) - 1.0).abs() < 1e-2, "{var}");
            assert!(dot(side, side).sqrt() < 1e-3 * width.sqrt(), "{side:?}");
            let outside = [-d.towards[0], -d.towards[1], -d.towards[2]];
            assert_eq!(d.pdf(outside), 0.0);
            assert_eq!(d.radiance(outside), [0.0; 3]);
        }
        // Nothing to draw: no environment and no discs.
        let none = Lights::default();
        assert!(LightSet::new(None, &none).sample([0.5, 0.5]).is_none());
    }
}
