//! Leaving out what a scene does not need (issue #8, item 4), CPU side only: which
//! wavelengths' D65·CMF weight cannot matter at a tolerance, and which `(u, v)` band of the
//! DFT terms a scene's directions can reach. The renderer decides what to do with them
//! (upload fewer wavelengths and texels, report what it left out); nothing here knows GPUs.
//!
//! Both bounds use `|P̂| ≤ 1`: a wavelength contributes at most `C·w_λ` to a channel
//! (`w_λ` its colour weight, normalised so a mirror has `Y = 1`), and a texel outside the
//! reachable band is never read.

use crate::colour::ColourTable;
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
            let first = (b + m_lo.floor() - pad).max(0.0);
            let last = (b + m_hi.ceil() + pad).min(n as f64 - 1.0);
            if last - first + 1.0 >= n as f64 || first > last {
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
