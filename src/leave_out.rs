//! Leaving out what a scene does not need, CPU side: which
//! wavelengths' D65·CMF weight cannot matter at a tolerance, which `(u, v)` band of the
//! DFT terms a scene's directions can reach, and the record of what was left out
//! ([`LeftOut`]). The variants use them (`flss`/`nmm` loop over fewer wavelengths and
//! upload fewer texels, the tables skip wavelengths in their build) and `render` reports
//! them; nothing here knows GPUs.
//!
//! Both bounds use `|P̂| ≤ 1`: a wavelength contributes at most `C·w_λ` to a channel
//! (`w_λ` its colour weight, normalised so a mirror has `Y = 1`), and a texel outside the
//! reachable band is never read.

use crate::brdf::table::Region;
use crate::brdf::truncation::TermPlan;
use crate::colour::ColourTable;
use crate::spectrum::num_complex::Complex64;
use crate::spectrum::Band;

/// Wavelengths of a colour table that are kept, and the weight left out.
#[derive(Debug, Clone, PartialEq)]
pub struct WavelengthSelection {
    /// Indices into the table's wavelengths, ascending.
    pub keep: Vec<usize>,
    /// Sum of the left-out weights per channel (X, Y, Z): the largest error of `XYZ/C`
    /// that leaving them out can cause, relative to a mirror's `Y = 1`.
    pub dropped_weight: [f64; 3],
}

impl WavelengthSelection {
    /// Number of wavelengths left out.
    pub fn dropped(&self, table: &ColourTable) -> usize {
        table.lambdas_nm.len() - self.keep.len()
    }
}

/// The wavelengths whose weight matters at `tolerance`: the smallest weights (largest
/// channel first) are left out while their sum stays within `tolerance` in every channel.
pub fn wavelengths_needed(table: &ColourTable, tolerance: f64) -> WavelengthSelection {
    let size = |w: &[f64; 3]| w.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut order: Vec<usize> = (0..table.weights.len()).collect();
    order.sort_by(|&a, &b| size(&table.weights[a]).total_cmp(&size(&table.weights[b])));
    let mut dropped = [0.0f64; 3];
    let mut left_out = vec![false; table.weights.len()];
    for i in order {
        let w = table.weights[i];
        let next = [
            dropped[0] + w[0].abs(),
            dropped[1] + w[1].abs(),
            dropped[2] + w[2].abs(),
        ];
        if next.iter().any(|&d| d > tolerance) {
            break;
        }
        dropped = next;
        left_out[i] = true;
    }
    WavelengthSelection {
        keep: (0..table.weights.len()).filter(|&i| !left_out[i]).collect(),
        dropped_weight: dropped,
    }
}

/// A box of `(u, v)` a scene's directions reach (`(u, v, w) = −ωi − ωr`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UvBox {
    pub u: (f64, f64),
    pub v: (f64, f64),
}

impl UvBox {
    /// Every pair of directions: `|u|, |v| ≤ 2`.
    pub const ALL: UvBox = UvBox {
        u: (-2.0, 2.0),
        v: (-2.0, 2.0),
    };

    /// A BRDF map under light `ωi`: `ωr` covers the unit disk, so `u ∈ −ωi.x + [−1, 1]`.
    pub fn brdf_map(wi: [f64; 3]) -> UvBox {
        UvBox {
            u: (-wi[0] - 1.0, -wi[0] + 1.0),
            v: (-wi[1] - 1.0, -wi[1] + 1.0),
        }
    }

    /// The bounding box of the given `(ωi, ωr)` pairs (e.g. a mesh's vertices under a
    /// light and a camera, in each vertex's tangent frame); `None` when empty.
    pub fn of_pairs(pairs: impl IntoIterator<Item = ([f64; 3], [f64; 3])>) -> Option<UvBox> {
        let mut b: Option<UvBox> = None;
        for (wi, wr) in pairs {
            let (u, v) = (-wi[0] - wr[0], -wi[1] - wr[1]);
            b = Some(match b {
                None => UvBox {
                    u: (u, u),
                    v: (v, v),
                },
                Some(b) => UvBox {
                    u: (b.u.0.min(u), b.u.1.max(u)),
                    v: (b.v.0.min(v), b.v.1.max(v)),
                },
            });
        }
        b
    }

    /// Widens the box by `margin` on every side (interpolated directions between the
    /// pairs given to [`UvBox::of_pairs`] can reach slightly beyond them).
    pub fn widened(self, margin: f64) -> UvBox {
        UvBox {
            u: (self.u.0 - margin, self.u.1 + margin),
            v: (self.v.0 - margin, self.v.1 + margin),
        }
    }

    /// The texels of an `nx × ny` spectrum (pixel `dh_um`) that lookups from this box can
    /// read for wavelengths in `[lambda_min_um, lambda_max_um]` with gather radius `radius`:
    /// `b + u·N·dH/λ ± (R + 1)` (MODEL §3), clamped to the spectrum.
    pub fn band(
        &self,
        nx: usize,
        ny: usize,
        dh_um: f64,
        lambda_min_um: f64,
        lambda_max_um: f64,
        radius: usize,
    ) -> Band {
        let axis = |n: usize, (lo, hi): (f64, f64)| -> (usize, usize) {
            let scale = n as f64 * dh_um;
            let ends = [
                lo / lambda_min_um,
                lo / lambda_max_um,
                hi / lambda_min_um,
                hi / lambda_max_um,
            ];
            let m_lo = ends.iter().copied().fold(f64::INFINITY, f64::min) * scale;
            let m_hi = ends.iter().copied().fold(f64::NEG_INFINITY, f64::max) * scale;
            let b = (n / 2) as f64;
            let pad = radius as f64 + 1.0;
            let first = b + m_lo.floor() - pad;
            let last = b + m_hi.ceil() + pad;
            // Lookups past either end wrap around the periodic spectrum: only the whole
            // axis holds them then (a clamped band would read zeros where they land).
            if !(first.is_finite() && last.is_finite())
                || first < 0.0
                || last > n as f64 - 1.0
                || first > last
            {
                (0, n)
            } else {
                (first as usize, (last - first) as usize + 1)
            }
        };
        let (x0, width) = axis(nx, self.u);
        let (y0, height) = axis(ny, self.v);
        Band {
            x0,
            y0,
            width,
            height,
        }
    }
}

impl UvBox {
    /// The `(u, v)` of a `(u, v, w)` region (a BRDF map's, or a mesh's under its light and
    /// camera, as the table variants use it).
    pub fn of_region(region: &Region) -> UvBox {
        UvBox {
            u: (region.lo[0], region.hi[0]),
            v: (region.lo[1], region.hi[1]),
        }
    }
}

/// The texels both bands hold (`a` when they do not overlap, which cannot happen for a
/// band computed from lookups that the stored band holds).
pub fn intersect(a: &Band, b: &Band) -> Band {
    let axis = |a0: usize, aw: usize, b0: usize, bw: usize| {
        let lo = a0.max(b0);
        let hi = (a0 + aw).min(b0 + bw);
        (lo < hi).then_some((lo, hi - lo))
    };
    match (
        axis(a.x0, a.width, b.x0, b.width),
        axis(a.y0, a.height, b.y0, b.height),
    ) {
        (Some((x0, width)), Some((y0, height))) => Band {
            x0,
            y0,
            width,
            height,
        },
        _ => *a,
    }
}

/// Term `terms` (stored over `stored`, row-major) cropped to `kept` ⊆ `stored`.
pub fn crop(terms: &[Complex64], stored: &Band, kept: &Band) -> Vec<Complex64> {
    let (dx, dy) = (kept.x0 - stored.x0, kept.y0 - stored.y0);
    (0..kept.height)
        .flat_map(|y| {
            let row = (dy + y) * stored.width + dx;
            terms[row..row + kept.width].iter().copied()
        })
        .collect()
}

/// What a prepared variant left out (the renderer reports it; see `render`).
#[derive(Debug, Clone, PartialEq)]
pub struct LeftOut {
    /// The wavelengths of the per-pixel loop (`flss`, `nmm`) or of the offline table build.
    pub wavelengths: Option<WavelengthsLeft>,
    /// The DFT texels uploaded (`flss`, `nmm`).
    pub texels: Option<TexelsLeft>,
    /// The series terms of a table kept (`chebyshev-w`'s Chebyshev terms in `w`).
    pub terms: Option<TermsLeft>,
    /// GPU memory of the variant's resources as built, and keeping everything (bytes).
    pub gpu_bytes: usize,
    pub gpu_bytes_keep_all: usize,
}

/// A table's series terms kept and left out at `tolerance` (the material's, relative to
/// the table's largest `|c_0|`): the terms left out add at most `tail · peak` to `G` at a
/// node ([`crate::brdf::table::Truncation`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TermsLeft {
    pub truncation: crate::brdf::table::Truncation,
    pub tolerance: f64,
}

/// Wavelengths kept and left out.
#[derive(Debug, Clone, PartialEq)]
pub struct WavelengthsLeft {
    /// Where they are left out: `"per pixel"` or `"in the table build"`.
    pub place: &'static str,
    pub step_nm: u32,
    pub kept_nm: Vec<f64>,
    pub dropped_nm: Vec<f64>,
    /// Left-out weight per channel (bound on the error of `XYZ/C`, relative to a mirror's
    /// `Y = 1`), and the tolerance it was chosen for.
    pub dropped_weight: [f64; 3],
    pub tolerance: f64,
}

impl WavelengthsLeft {
    /// The selection of `table` at `tolerance` (or everything, `None`), described.
    pub fn of(
        table: &ColourTable,
        tolerance: Option<f64>,
        place: &'static str,
    ) -> (WavelengthSelection, WavelengthsLeft) {
        let sel = match tolerance {
            Some(t) => wavelengths_needed(table, t),
            None => WavelengthSelection {
                keep: (0..table.len()).collect(),
                dropped_weight: [0.0; 3],
            },
        };
        let kept_nm: Vec<f64> = sel.keep.iter().map(|&i| table.lambdas_nm[i]).collect();
        let dropped_nm = table
            .lambdas_nm
            .iter()
            .enumerate()
            .filter(|(i, _)| sel.keep.binary_search(i).is_err())
            .map(|(_, l)| *l)
            .collect();
        let left = WavelengthsLeft {
            place,
            step_nm: table.step_nm,
            kept_nm,
            dropped_nm,
            dropped_weight: sel.dropped_weight,
            tolerance: tolerance.unwrap_or(0.0),
        };
        (sel, left)
    }

    /// Largest left-out weight over the channels.
    pub fn max_dropped_weight(&self) -> f64 {
        self.dropped_weight.iter().fold(0.0f64, |m, v| m.max(*v))
    }

    /// Shortest and longest kept wavelength (nm).
    pub fn kept_range_nm(&self) -> (f64, f64) {
        (
            self.kept_nm.first().copied().unwrap_or(f64::NAN),
            self.kept_nm.last().copied().unwrap_or(f64::NAN),
        )
    }
}

/// DFT texels kept and stored.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TexelsLeft {
    /// The `(u, v)` box the band was computed for, and its wavelength range (nm).
    pub uv: UvBox,
    pub lambda_nm: (f64, f64),
    /// Uploaded texels, and the band the precomputed terms hold (all directions).
    pub kept: Band,
    pub stored: Band,
}

/// `[a, b, c, e, f]` → `"a–c, e–f"` for wavelengths `step` apart.
pub fn ranges_nm(lambdas: &[f64], step: f64) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < lambdas.len() {
        let mut j = i;
        while j + 1 < lambdas.len() && (lambdas[j + 1] - lambdas[j] - step).abs() < 1e-9 {
            j += 1;
        }
        out.push(if i == j {
            format!("{}", lambdas[i])
        } else {
            format!("{}–{}", lambdas[i], lambdas[j])
        });
        i = j + 1;
    }
    if out.is_empty() {
        "none".into()
    } else {
        out.join(", ")
    }
}

/// What `render` reports about a frame: the one line and, with `--verbose`, the details.
#[derive(Debug, Clone)]
pub struct Report<'a> {
    /// What the variant recorded (`None`: a variant that records nothing).
    pub left: Option<&'a LeftOut>,
    /// The variant's name.
    pub variant: &'a str,
    /// The material's term plan (the series variants use `T + 1` terms of it).
    pub plan: &'a TermPlan,
    /// The optional shader features (specialisation constants), and whether the frame uses
    /// each.
    pub features: Vec<(&'static str, bool)>,
    /// GPU memory of the variant's resources as drawn (bytes).
    pub gpu_bytes: usize,
    /// `--keep-all` was given.
    pub keep_all: bool,
}

impl Report<'_> {
    /// Whether the variant evaluates the series of DFT terms per pixel (it uploaded texels).
    fn uses_terms(&self) -> bool {
        self.left.is_some_and(|l| l.texels.is_some())
    }

    /// One line: terms, wavelengths, texel fraction, features, GPU memory.
    pub fn line(&self) -> String {
        let mut parts = Vec::new();
        if self.uses_terms() {
            parts.push(format!(
                "terms above T = {} ({})",
                self.plan.terms,
                if self.plan.auto { "auto" } else { "--terms" }
            ));
        } else if let Some(TermsLeft {
            truncation: t,
            tolerance,
        }) = self.left.and_then(|l| l.terms)
        {
            parts.push(if t.kept < t.of {
                format!(
                    "{} of {} series terms in w (adding ≤ {:.1e} of the peak ≤ {tolerance:.0e})",
                    t.of - t.kept,
                    t.of,
                    t.tail,
                )
            } else {
                format!("no series terms (all {} needed at {tolerance:.0e})", t.of)
            });
        } else if self.left.is_some() {
            parts.push("no series terms (exact table)".to_string());
        }
        match self.left {
            Some(l) => {
                if let Some(w) = &l.wavelengths {
                    let (lo, hi) = w.kept_range_nm();
                    let weight = if w.dropped_nm.is_empty() {
                        String::new()
                    } else {
                        format!(
                            "weight {:.1e} ≤ {:.0e}; ",
                            w.max_dropped_weight(),
                            w.tolerance
                        )
                    };
                    parts.push(format!(
                        "{} of {} wavelengths {} ({weight}{lo}–{hi} nm kept)",
                        w.dropped_nm.len(),
                        w.dropped_nm.len() + w.kept_nm.len(),
                        w.place,
                    ));
                }
                if let Some(t) = &l.texels {
                    parts.push(format!(
                        "{:.1}% of the DFT texels ({}×{} of {}×{} kept)",
                        100.0 * (1.0 - texel_fraction(&t.kept, &t.stored)),
                        t.kept.width,
                        t.kept.height,
                        t.stored.width,
                        t.stored.height
                    ));
                }
            }
            None => parts.push(format!("nothing recorded by {}", self.variant)),
        }
        let off: Vec<&str> = self
            .features
            .iter()
            .filter(|(_, on)| !on)
            .map(|(f, _)| *f)
            .collect();
        parts.push(format!(
            "features: {}",
            if off.is_empty() {
                "none".to_string()
            } else {
                off.join(", ")
            }
        ));
        let all = self
            .left
            .map_or(self.gpu_bytes, |l| l.gpu_bytes_keep_all.max(self.gpu_bytes));
        let memory = if self.keep_all {
            format!(
                "GPU memory {:.1} MB (--keep-all)",
                self.gpu_bytes as f64 / 1e6
            )
        } else if all == self.gpu_bytes {
            format!(
                "GPU memory {:.1} MB (the same keeping all)",
                self.gpu_bytes as f64 / 1e6
            )
        } else {
            format!(
                "GPU memory {:.1} MB ({:.1} MB keeping all)",
                self.gpu_bytes as f64 / 1e6,
                all as f64 / 1e6
            )
        };
        format!("left out: {}; {memory}", parts.join("; "))
    }

    /// `--verbose`: which terms, wavelengths, band and features, one line each.
    pub fn details(&self) -> Vec<String> {
        let mut out = Vec::new();
        let p = self.plan;
        if self.uses_terms() {
            out.push(format!(
                "terms: 0..={} of {}, {} (highest allowed T = {}), tolerance {:.0e} on |P̂|²: truncation {:.1e}, float32 rounding {:.1e}",
                p.terms,
                if p.auto { "auto" } else { "fixed by --terms" },
                p.expansion,
                crate::brdf::truncation::MAX_TERMS,
                p.tolerance,
                p.truncation,
                p.rounding
            ));
        }
        if let Some(l) = self.left {
            if let Some(w) = &l.wavelengths {
                let step = w.step_nm as f64;
                out.push(format!(
                    "wavelengths ({} nm, {}): kept {} ({}); left out {} ({}); left-out weight X {:.1e}, Y {:.1e}, Z {:.1e} (tolerance {:.0e}, relative to a mirror's Y = 1)",
                    w.step_nm,
                    w.place,
                    ranges_nm(&w.kept_nm, step),
                    w.kept_nm.len(),
                    ranges_nm(&w.dropped_nm, step),
                    w.dropped_nm.len(),
                    w.dropped_weight[0],
                    w.dropped_weight[1],
                    w.dropped_weight[2],
                    w.tolerance
                ));
            }
            if let Some(TermsLeft {
                truncation: t,
                tolerance,
            }) = l.terms
            {
                out.push(format!(
                    "series terms in w: kept T_0..T_{} of T_0..T_{}; the rest add at most {:.1e} of the table's largest c_0 ({:.3e}) to G (tolerance {tolerance:.0e})",
                    t.kept.saturating_sub(1),
                    t.of.saturating_sub(1),
                    t.tail,
                    t.peak
                ));
            }
            if let Some(t) = &l.texels {
                out.push(format!(
                    "DFT texels: columns {}..{}, rows {}..{} ({}×{}) of the stored {}..{}, {}..{} ({}×{}): lookups from u ∈ [{:.3}, {:.3}], v ∈ [{:.3}, {:.3}] at {}–{} nm",
                    t.kept.x0,
                    t.kept.x0 + t.kept.width,
                    t.kept.y0,
                    t.kept.y0 + t.kept.height,
                    t.kept.width,
                    t.kept.height,
                    t.stored.x0,
                    t.stored.x0 + t.stored.width,
                    t.stored.y0,
                    t.stored.y0 + t.stored.height,
                    t.stored.width,
                    t.stored.height,
                    t.uv.u.0,
                    t.uv.u.1,
                    t.uv.v.0,
                    t.uv.v.1,
                    t.lambda_nm.0,
                    t.lambda_nm.1
                ));
            }
        }
        out.push(format!(
            "features (specialisation constants): {}",
            self.features
                .iter()
                .map(|(f, on)| format!("{f} {}", if *on { "on" } else { "left out" }))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        out.into_iter()
            .map(|l| format!("left out:   {l}"))
            .collect()
    }
}

/// Fraction of `outer`'s texels that `inner` keeps.
pub fn texel_fraction(inner: &Band, outer: &Band) -> f64 {
    (inner.width * inner.height) as f64 / (outer.width * outer.height).max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf::direction;
    use crate::spectrum::lookup_coord;

    #[test]
    fn left_out_wavelengths_change_a_white_spectrum_by_at_most_the_tolerance() {
        for step in [1, 5] {
            let t = ColourTable::new(step).unwrap();
            for tol in [1e-2, 1e-3, 1e-4] {
                let s = wavelengths_needed(&t, tol);
                let full = t.integrate(|_| 1.0);
                let mut kept = [0.0; 3];
                for &i in &s.keep {
                    for (k, w) in kept.iter_mut().zip(t.weights[i]) {
                        *k += w;
                    }
                }
                for c in 0..3 {
                    assert!((full[c] - kept[c]).abs() <= tol + 1e-12, "{step} nm, {tol}");
                }
                assert!(s.dropped(&t) > 0, "{step} nm, {tol}: nothing left out");
                println!(
                    "{step} nm, tolerance {tol:.0e}: {} of {} wavelengths kept ({}–{} nm), dropped weight {:.1e}",
                    s.keep.len(),
                    t.lambdas_nm.len(),
                    t.lambdas_nm[s.keep[0]],
                    t.lambdas_nm[*s.keep.last().unwrap()],
                    s.dropped_weight.iter().fold(0.0f64, |m, v| m.max(*v))
                );
                // The far ends of the spectrum go first.
                assert!(!s.keep.contains(&(t.lambdas_nm.len() - 1)));
            }
        }
    }

    #[test]
    fn brdf_map_band_holds_every_lookup_and_is_smaller_than_the_full_reach() {
        let (n, dh, r) = (704usize, 0.0923, 2usize);
        for (theta, phi) in [(0.0, 0.0), (60.0, 0.0), (85.0, 40.0)] {
            let wi = direction(theta, phi);
            let band = UvBox::brdf_map(wi).band(n, n, dh, 0.38, 0.78, r);
            let all = UvBox::ALL.band(n, n, dh, 0.38, 0.78, r);
            let f = texel_fraction(&band, &all);
            assert!(f < 0.35, "θi {theta}: fraction {f}");
            println!(
                "BRDF map θi {theta}°: {}×{} of {}×{} texels ({f:.2})",
                band.width, band.height, all.width, all.height
            );
            for k in 0..=64 {
                for l in [380.0, 500.0, 780.0] {
                    let a = k as f64 / 64.0 * std::f64::consts::TAU;
                    let s = (k % 7) as f64 / 6.0;
                    let wr = [s * a.cos(), s * a.sin(), (1.0 - s * s).sqrt()];
                    let q = [
                        lookup_coord(n / 2, -wi[0] - wr[0], n, dh, l * 1e-3),
                        lookup_coord(n / 2, -wi[1] - wr[1], n, dh, l * 1e-3),
                    ];
                    for (qa, (lo, w)) in q
                        .iter()
                        .zip([(band.x0, band.width), (band.y0, band.height)])
                    {
                        let (first, last) =
                            (qa.floor() as i64 - r as i64, qa.floor() as i64 + r as i64);
                        assert!(
                            first >= lo as i64 && last < (lo + w) as i64,
                            "θi {theta}: q {qa} outside {lo}+{w}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn crop_intersect_and_ranges() {
        let stored = Band {
            x0: 2,
            y0: 1,
            width: 4,
            height: 3,
        };
        let terms: Vec<Complex64> = (0..12).map(|i| Complex64::new(i as f64, 0.0)).collect();
        let kept = intersect(
            &Band {
                x0: 3,
                y0: 2,
                width: 10,
                height: 1,
            },
            &stored,
        );
        assert_eq!(
            kept,
            Band {
                x0: 3,
                y0: 2,
                width: 3,
                height: 1
            }
        );
        let c: Vec<f64> = crop(&terms, &stored, &kept).iter().map(|z| z.re).collect();
        assert_eq!(c, [5.0, 6.0, 7.0]);
        assert_eq!(
            ranges_nm(&[380.0, 385.0, 390.0, 700.0, 780.0], 5.0),
            "380–390, 700, 780"
        );
        assert_eq!(ranges_nm(&[], 5.0), "none");
    }

    #[test]
    fn the_line_says_which_series_terms_were_left_out() {
        let plan = TermPlan {
            expansion: crate::spectrum::Expansion::Chebyshev,
            terms: 10,
            auto: true,
            tolerance: 1e-3,
            precision: crate::brdf::truncation::Precision::F32,
            reach: crate::brdf::truncation::Reach::ALL,
            a: 1.0,
            truncation: 1e-4,
            rounding: 1e-5,
            window: 0.0,
            warnings: Vec::new(),
        };
        let left = |kept: usize| LeftOut {
            wavelengths: None,
            texels: None,
            terms: Some(TermsLeft {
                truncation: crate::brdf::table::Truncation {
                    kept,
                    of: 12,
                    tail: if kept < 12 { 6.7e-4 } else { 0.0 },
                    peak: 0.31,
                },
                tolerance: 1e-3,
            }),
            gpu_bytes: 3,
            gpu_bytes_keep_all: 9,
        };
        let report = |l: &LeftOut| {
            let r = Report {
                left: Some(l),
                variant: "chebyshev-w",
                plan: &plan,
                features: Vec::new(),
                gpu_bytes: l.gpu_bytes,
                keep_all: false,
            };
            (r.line(), r.details())
        };
        let (line, details) = report(&left(4));
        assert!(
            line.contains("8 of 12 series terms in w (adding ≤ 6.7e-4 of the peak ≤ 1e-3)"),
            "{line}"
        );
        assert!(
            details
                .iter()
                .any(|d| d.contains("kept T_0..T_3 of T_0..T_11")),
            "{details:?}"
        );
        let (line, _) = report(&left(12));
        assert!(
            line.contains("no series terms (all 12 needed at 1e-3)"),
            "{line}"
        );
    }

    #[test]
    fn a_band_that_would_wrap_keeps_the_whole_axis() {
        // dH above λ/4: lookups pass the spectrum's ends and wrap around.
        let b = UvBox::brdf_map([0.0, 0.0, 1.0]).band(64, 64, 0.2, 0.38, 0.78, 2);
        assert_eq!((b.x0, b.width), (0, 64));
    }

    #[test]
    fn pairs_box_is_their_bounding_box() {
        let b = UvBox::of_pairs([
            ([0.0, 0.0, 1.0], [0.5, 0.0, 0.866]),
            ([0.0, 0.0, 1.0], [-0.2, 0.3, 0.93]),
        ])
        .unwrap();
        assert_eq!(b.u, (-0.5, 0.2));
        assert_eq!(b.v, (-0.3, 0.0));
        assert!(UvBox::of_pairs(std::iter::empty()).is_none());
    }
}
