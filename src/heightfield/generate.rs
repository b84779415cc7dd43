//! Seeded, deterministic synthesis of the MODEL §9 test gratings (no measured AFM data is
//! available). Every periodic pattern is built from integer wave numbers on the patch, so
//! the tiled patch has no seams and its DFT has clean lines: a requested period or angle is
//! snapped to the nearest lattice wave vector ([`GratingSpec::lattice_wave`]).

use std::f64::consts::PI;

use super::{HeightField, MAX_SIDE};
use crate::{Error, Result};

/// Largest pixel size the generators accept: `λ_min/4` for 380 nm (MODEL §3), so every
/// lookup of a visible wavelength stays inside the spectrum.
pub const MAX_GENERATED_DH_UM: f64 = 0.095;

/// Which test grating to synthesise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum GratingKind {
    /// Sawtooth across x (lines along y), the thesis' 2.5 µm blazed grating.
    Blazed,
    /// Raised cosine of any period, height and orientation (analytic checks).
    Sinusoidal,
    /// Elaphe-like: irregular finger segments on ≈1.14 µm ridges.
    Elaphe,
    /// Xenopeltis-like: regular ≈1.55 µm ridges in two domains of different period and angle.
    Xenopeltis,
}

impl GratingKind {
    /// All kinds, in a fixed order.
    pub const ALL: [GratingKind; 4] = [
        GratingKind::Blazed,
        GratingKind::Sinusoidal,
        GratingKind::Elaphe,
        GratingKind::Xenopeltis,
    ];

    /// The lowercase name used on the command line, in `builtin:` specs and asset files.
    pub fn name(self) -> &'static str {
        match self {
            GratingKind::Blazed => "blazed",
            GratingKind::Sinusoidal => "sinusoidal",
            GratingKind::Elaphe => "elaphe",
            GratingKind::Xenopeltis => "xenopeltis",
        }
    }
}

impl std::fmt::Display for GratingKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for GratingKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let lower = s.to_ascii_lowercase();
        GratingKind::ALL
            .into_iter()
            .find(|k| k.name() == lower)
            .ok_or_else(|| {
                Error::invalid(
                    "grating kind",
                    format!("'{s}'; expected blazed, sinusoidal, elaphe or xenopeltis"),
                )
            })
    }
}

/// Parameters of a synthetic grating. Lengths in µm; the patch is square, `N = round(size/dH)`
/// samples a side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GratingSpec {
    pub kind: GratingKind,
    /// Patch side (µm); the coherence length of sunlight by default.
    pub size_um: f64,
    /// Pixel size (µm), at most [`MAX_GENERATED_DH_UM`].
    pub dh_um: f64,
    /// Ridge period (µm). Xenopeltis: the period of the first domain.
    pub period_um: f64,
    /// Peak-to-valley height (µm).
    pub height_um: f64,
    /// Orientation of the wave vector from the x axis (degrees). Xenopeltis: the tilt of the
    /// second domain (the first is at 0°). Elaphe: must be 0.
    pub angle_deg: f64,
    /// Seed of the irregularities (Elaphe fingers, Xenopeltis domain boundary); the regular
    /// kinds ignore it.
    pub seed: u64,
}

/// Default patch side (µm): the ≈65 µm coherence length of sunlight (MODEL §3).
pub const DEFAULT_SIZE_UM: f64 = 65.0;
/// Default pixel size: 704 samples over 65 µm ≈ 92.3 nm, below the 95 nm Nyquist limit.
pub const DEFAULT_DH_UM: f64 = 65.0 / 704.0;
/// Ratio of the Xenopeltis second-domain period to the first (≈1.60/1.55).
const XENO_PERIOD_RATIO: f64 = 1.60 / 1.55;

impl GratingSpec {
    /// The shipped default of each kind (assets/<kind>.png are these, quantised).
    pub fn default_for(kind: GratingKind) -> Self {
        let (period_um, height_um, angle_deg) = match kind {
            GratingKind::Blazed => (2.5, 0.25, 0.0),
            GratingKind::Sinusoidal => (2.5, 0.2, 0.0),
            GratingKind::Elaphe => (1.14, 0.375, 0.0),
            GratingKind::Xenopeltis => (1.55, 0.82, 5.0),
        };
        Self {
            kind,
            size_um: DEFAULT_SIZE_UM,
            dh_um: DEFAULT_DH_UM,
            period_um,
            height_um,
            angle_deg,
            seed: 1,
        }
    }

    /// Samples a side, `round(size/dH)`, validated against [`MAX_SIDE`].
    pub fn samples(&self) -> Result<usize> {
        positive("patch size", self.size_um)?;
        positive("dH", self.dh_um)?;
        let n = (self.size_um / self.dh_um).round();
        if n > MAX_SIDE as f64 {
            return Err(Error::invalid(
                "patch size",
                format!(
                    "{} µm at dH = {} µm is {n} samples a side; at most {MAX_SIDE}",
                    self.size_um, self.dh_um
                ),
            ));
        }
        if n < 8.0 {
            return Err(Error::invalid(
                "patch size",
                format!(
                    "{} µm at dH = {} µm is {n} samples a side; at least 8",
                    self.size_um, self.dh_um
                ),
            ));
        }
        Ok(n as usize)
    }

    /// Patch side actually generated: `N·dH` (µm).
    pub fn extent_um(&self) -> Result<f64> {
        Ok(self.samples()? as f64 * self.dh_um)
    }

    /// The integer wave numbers `(m_x, m_y)` (periods across the patch along x and y) nearest
    /// to `period` at `angle`, and the period and angle they really have. Snapping makes the
    /// pattern periodic on the patch, so the DFT tiles it without a seam.
    pub fn lattice_wave(&self, period_um: f64, angle_deg: f64) -> Result<LatticeWave> {
        let extent = self.extent_um()?;
        positive("period", period_um)?;
        if !angle_deg.is_finite() {
            return Err(Error::invalid("angle", format!("{angle_deg}°")));
        }
        // A period under two samples is not resolved; refusing it here also bounds the
        // wave numbers below (|mx|, |my| ≤ half the samples across), so nothing overflows.
        if period_um < 2.0 * self.dh_um {
            return Err(Error::invalid(
                "period",
                format!(
                    "{period_um:e} µm is shorter than two {:.4} µm samples; the grating is not resolved",
                    self.dh_um
                ),
            ));
        }
        let a = angle_deg.to_radians();
        let mx = (extent * a.cos() / period_um).round() as i64;
        let my = (extent * a.sin() / period_um).round() as i64;
        if mx == 0 && my == 0 {
            return Err(Error::invalid(
                "period",
                format!("{period_um} µm does not fit once into the {extent:.3} µm patch"),
            ));
        }
        let len = ((mx * mx + my * my) as f64).sqrt();
        let period = extent / len;
        if self.dh_um > period / 2.0 {
            return Err(Error::invalid(
                "dH",
                format!(
                    "{} µm is more than half the {period:.4} µm period; the grating is not resolved",
                    self.dh_um
                ),
            ));
        }
        Ok(LatticeWave {
            mx,
            my,
            period_um: period,
            angle_deg: (my as f64).atan2(mx as f64).to_degrees(),
        })
    }

    /// Checks every parameter of the spec (the generator calls this first).
    pub fn validate(&self) -> Result<()> {
        self.samples()?;
        if self.dh_um > MAX_GENERATED_DH_UM {
            return Err(Error::invalid(
                "dH",
                format!(
                    "{} µm; generated gratings need dH ≤ {MAX_GENERATED_DH_UM} µm (λ_min/4 for 380 nm)",
                    self.dh_um
                ),
            ));
        }
        if !(self.height_um.is_finite() && self.height_um >= 0.0) {
            return Err(Error::invalid(
                "height",
                format!("{} µm; must be finite and ≥ 0", self.height_um),
            ));
        }
        if self.kind == GratingKind::Elaphe && self.angle_deg != 0.0 {
            return Err(Error::invalid(
                "angle",
                format!(
                    "{}° for elaphe; its fingers run along y, only 0° is supported",
                    self.angle_deg
                ),
            ));
        }
        self.lattice_wave(self.period_um, self.angle_deg_first())?;
        if self.kind == GratingKind::Xenopeltis {
            self.lattice_wave(self.period_um * XENO_PERIOD_RATIO, self.angle_deg)?;
        }
        Ok(())
    }

    /// Orientation of the (first) wave: Xenopeltis' first domain is always at 0°.
    fn angle_deg_first(&self) -> f64 {
        match self.kind {
            GratingKind::Xenopeltis => 0.0,
            _ => self.angle_deg,
        }
    }

    /// The dominant wave(s) the generator will use: the (first-domain) wave, and for
    /// Xenopeltis the second domain's.
    pub fn waves(&self) -> Result<(LatticeWave, Option<LatticeWave>)> {
        self.validate()?;
        let first = self.lattice_wave(self.period_um, self.angle_deg_first())?;
        let second = match self.kind {
            GratingKind::Xenopeltis => {
                Some(self.lattice_wave(self.period_um * XENO_PERIOD_RATIO, self.angle_deg)?)
            }
            _ => None,
        };
        Ok((first, second))
    }
}

/// A plane wave with integer wave numbers on the patch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatticeWave {
    /// Periods across the patch along x.
    pub mx: i64,
    /// Periods across the patch along y.
    pub my: i64,
    /// Real period (µm) along the wave vector.
    pub period_um: f64,
    /// Real orientation of the wave vector from x (degrees).
    pub angle_deg: f64,
}

impl LatticeWave {
    /// Phase in periods, in `[0, 1)`, at sample `(c, r)` of an `n`-sample patch. Exact
    /// integer arithmetic, so the pattern repeats bit for bit across the patch border.
    fn phase(&self, c: usize, r: usize, n: usize) -> f64 {
        let n = n as i64;
        let k = (self.mx * c as i64 + self.my * r as i64).rem_euclid(n);
        k as f64 / n as f64
    }
}

fn positive(what: &'static str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            what,
            format!("{v} µm; must be a finite positive length"),
        ))
    }
}

/// SplitMix64 (Steele, Lea & Flood 2014): tiny, fast, and good enough for jitter. Owned
/// here so the gratings never change with a dependency's version.
#[derive(Debug, Clone)]
pub(super) struct Rng(u64);

impl Rng {
    pub(super) fn new(seed: u64) -> Self {
        Self(seed ^ 0x6a09_e667_f3bc_c909)
    }
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in `[0, 1)` with 53 random bits.
    pub(super) fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

/// Raised-cosine bump of width `duty` (fraction of a period) centred at phase ½: 1 on the
/// ridge crest, 0 between ridges, smooth (C¹) everywhere.
fn ridge(phase: f64, duty: f64) -> f64 {
    let d = (phase - 0.5).abs();
    if d >= duty / 2.0 {
        0.0
    } else {
        0.5 * (1.0 + (2.0 * PI * d / duty).cos())
    }
}

/// Synthesises the grating `spec` describes. Heights are ≥ 0 with minimum exactly 0.
pub fn generate(spec: &GratingSpec) -> Result<HeightField> {
    let (first, second) = spec.waves()?;
    let n = spec.samples()?;
    let mut h = match spec.kind {
        GratingKind::Blazed => plane(n, |c, r| spec.height_um * first.phase(c, r, n)),
        GratingKind::Sinusoidal => plane(n, |c, r| {
            0.5 * spec.height_um * (1.0 + (2.0 * PI * first.phase(c, r, n)).cos())
        }),
        GratingKind::Elaphe => elaphe(spec, first, n),
        GratingKind::Xenopeltis => {
            // `waves` always returns the second domain for Xenopeltis.
            let second = second.ok_or_else(|| Error::invalid("grating", "missing domain"))?;
            xenopeltis(spec, first, second, n)
        }
    };
    let lo = h.iter().copied().fold(f64::INFINITY, f64::min);
    for v in &mut h {
        *v -= lo;
    }
    HeightField::new(n, n, spec.dh_um, h)
}

fn plane(n: usize, f: impl Fn(usize, usize) -> f64) -> Vec<f64> {
    (0..n * n).map(|i| f(i % n, i / n)).collect()
}

/// Elaphe-like fingers: each ridge (a column of the first wave, lines along y) is cut into
/// segments of random length with small random gaps, each with its own height, width and a
/// small lateral offset; segment ends taper with a raised cosine so the field stays smooth.
fn elaphe(spec: &GratingSpec, wave: LatticeWave, n: usize) -> Vec<f64> {
    let extent = n as f64 * spec.dh_um;
    let ridges = wave.mx as usize;
    let period = wave.period_um;
    let mut rng = Rng::new(spec.seed);
    // Per-ridge list of segments along y as (start, length, height, duty, offset) in µm.
    struct Segment {
        start: f64,
        len: f64,
        height: f64,
        duty: f64,
        offset: f64,
    }
    let taper = (0.3 * period).max(2.0 * spec.dh_um);
    let mut columns: Vec<Vec<Segment>> = Vec::with_capacity(ridges);
    for _ in 0..ridges {
        // Draw (finger, gap) pairs until the ridge length is covered, then scale them so
        // they tile it exactly: the pattern is periodic along y too.
        let mut parts = Vec::new();
        let mut total = 0.0;
        while total < extent {
            let len = rng.range(3.0, 12.0);
            let gap = rng.range(0.25, 0.9);
            parts.push((len, gap));
            total += len + gap;
        }
        let scale = extent / total;
        let mut y = rng.range(0.0, extent);
        let mut segs = Vec::with_capacity(parts.len());
        for (len, gap) in parts {
            segs.push(Segment {
                start: y,
                len: len * scale,
                height: spec.height_um * rng.range(0.8, 1.0),
                duty: rng.range(0.6, 0.8),
                offset: rng.range(-0.06, 0.06) * period,
            });
            y += (len + gap) * scale;
        }
        columns.push(segs);
    }
    let mut h = vec![0.0; n * n];
    for r in 0..n {
        let y = r as f64 * spec.dh_um;
        for c in 0..n {
            let phase = wave.phase(c, r, n);
            // Which ridge this sample belongs to: the period index along x.
            let k = (wave.mx * c as i64).div_euclid(n as i64) as usize % ridges;
            let x_in = phase * period;
            let mut v: f64 = 0.0;
            for s in &columns[k] {
                let along = (y - s.start).rem_euclid(extent);
                if along >= s.len {
                    continue;
                }
                let end_dist = along.min(s.len - along);
                let t = if end_dist < taper {
                    0.5 * (1.0 - (PI * end_dist / taper).cos())
                } else {
                    1.0
                };
                let p = (x_in - s.offset) / period;
                v = v.max(s.height * t * ridge(p, s.duty));
            }
            h[r * n + c] = v;
        }
    }
    h
}

/// Xenopeltis-like: regular ridges in two domains (around y = 0 and around y = L/2) of
/// slightly different period and orientation, blended across a smooth boundary that wanders
/// randomly along x. All pieces are periodic on the patch.
fn xenopeltis(spec: &GratingSpec, a: LatticeWave, b: LatticeWave, n: usize) -> Vec<f64> {
    let mut rng = Rng::new(spec.seed);
    // Boundary displacement: a few random harmonics along x (integer wave numbers, so it
    // is periodic), amplitude about a micrometre.
    let harmonics: Vec<(f64, f64, f64)> = (1..=4)
        .map(|m| {
            (
                m as f64,
                rng.range(0.2, 0.6) / m as f64,
                rng.range(0.0, 2.0 * PI),
            )
        })
        .collect();
    let extent = n as f64 * spec.dh_um;
    let duty = 0.8;
    let mut h = vec![0.0; n * n];
    for c in 0..n {
        let u = c as f64 / n as f64;
        let shift_um: f64 = harmonics
            .iter()
            .map(|&(m, amp, ph)| amp * (2.0 * PI * m * u + ph).sin())
            .sum();
        for r in 0..n {
            let y = r as f64 * spec.dh_um + shift_um;
            // cos > 0 near y = 0 (domain a), < 0 near y = L/2 (domain b); the smoothstep
            // over |cos| < 0.15 gives a transition ≈ 3 µm wide.
            let s = (2.0 * PI * y / extent).cos();
            let w = smoothstep(-0.15, 0.15, s);
            let ha = ridge(a.phase(c, r, n), duty);
            let hb = ridge(b.phase(c, r, n), duty);
            h[r * n + c] = spec.height_um * (w * ha + (1.0 - w) * hb);
        }
    }
    h
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(kind: GratingKind) -> GratingSpec {
        GratingSpec {
            size_um: 16.0,
            ..GratingSpec::default_for(kind)
        }
    }

    #[test]
    fn defaults_snap_to_the_documented_periods() {
        let p = |k| {
            GratingSpec::default_for(k)
                .waves()
                .expect("default is valid")
        };
        assert_eq!(
            GratingSpec::default_for(GratingKind::Blazed)
                .samples()
                .unwrap(),
            704
        );
        let (b, _) = p(GratingKind::Blazed);
        assert_eq!((b.mx, b.my), (26, 0));
        assert!((b.period_um - 2.5).abs() < 1e-12);
        let (e, _) = p(GratingKind::Elaphe);
        assert_eq!((e.mx, e.my), (57, 0));
        assert!((e.period_um - 65.0 / 57.0).abs() < 1e-12);
        let (xa, xb) = p(GratingKind::Xenopeltis);
        let xb = xb.unwrap();
        assert_eq!((xa.mx, xa.my), (42, 0));
        assert!(xb.period_um > 1.58 && xb.period_um < 1.65, "{xb:?}");
        assert!(xb.angle_deg > 4.0 && xb.angle_deg < 7.0, "{xb:?}");
    }

    #[test]
    fn rng_is_deterministic_and_spread() {
        let a: Vec<u64> = (0..4)
            .scan(Rng::new(7), |r, _| Some(r.next_u64()))
            .collect();
        let b: Vec<u64> = (0..4)
            .scan(Rng::new(7), |r, _| Some(r.next_u64()))
            .collect();
        let c: Vec<u64> = (0..4)
            .scan(Rng::new(8), |r, _| Some(r.next_u64()))
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
        let mut r = Rng::new(1);
        let mean = (0..10_000).map(|_| r.unit()).sum::<f64>() / 10_000.0;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
    }

    #[test]
    fn heights_are_nonnegative_with_zero_minimum_and_bounded() {
        for k in GratingKind::ALL {
            let s = small(k);
            let hf = generate(&s).unwrap();
            let (lo, hi) = hf.range();
            assert_eq!(lo, 0.0, "{k}");
            assert!(
                hi <= s.height_um + 1e-12 && hi > 0.5 * s.height_um,
                "{k}: {hi}"
            );
        }
    }

    #[test]
    fn patterns_tile_without_seams() {
        // Across the patch border the field must look like it does inside: compare the
        // largest neighbour step across the wrap with the largest step inside.
        for k in [
            GratingKind::Sinusoidal,
            GratingKind::Elaphe,
            GratingKind::Xenopeltis,
        ] {
            let hf = generate(&small(k)).unwrap();
            let n = hf.nx() as i64;
            let mut inner: f64 = 0.0;
            let mut wrap: f64 = 0.0;
            for r in 0..n {
                for c in 0..n {
                    let dx = (hf.at(c + 1, r) - hf.at(c, r)).abs();
                    let dy = (hf.at(c, r + 1) - hf.at(c, r)).abs();
                    if c == n - 1 {
                        wrap = wrap.max(dx);
                    } else {
                        inner = inner.max(dx);
                    }
                    if r == n - 1 {
                        wrap = wrap.max(dy);
                    } else {
                        inner = inner.max(dy);
                    }
                }
            }
            assert!(
                wrap <= inner * 1.25 + 1e-12,
                "{k}: wrap {wrap} inner {inner}"
            );
        }
    }

    #[test]
    fn nonsense_specs_are_rejected() {
        let base = GratingSpec::default_for(GratingKind::Sinusoidal);
        let bad = [
            GratingSpec {
                period_um: -1.0,
                ..base
            },
            GratingSpec {
                period_um: f64::NAN,
                ..base
            },
            GratingSpec {
                period_um: 0.15,
                ..base
            },
            GratingSpec {
                period_um: 500.0,
                ..base
            },
            GratingSpec { dh_um: 0.0, ..base },
            GratingSpec { dh_um: 0.2, ..base },
            GratingSpec {
                size_um: 1000.0,
                ..base
            },
            GratingSpec {
                size_um: f64::INFINITY,
                ..base
            },
            GratingSpec {
                height_um: -0.1,
                ..base
            },
            GratingSpec {
                angle_deg: f64::NAN,
                ..base
            },
            GratingSpec {
                angle_deg: 10.0,
                ..GratingSpec::default_for(GratingKind::Elaphe)
            },
        ];
        for s in bad {
            match generate(&s) {
                Err(Error::Invalid { .. }) => {}
                other => panic!("{s:?} gave {other:?}"),
            }
        }
    }

    #[test]
    fn kind_names_round_trip() {
        for k in GratingKind::ALL {
            assert_eq!(k.to_string().parse::<GratingKind>().unwrap(), k);
        }
        assert!("snake".parse::<GratingKind>().is_err());
    }
}
