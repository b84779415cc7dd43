//! The error figures of a row (MODEL §6): relative L2 of linear XYZ, max |ΔY| and
//! CIEDE2000 percentiles, with 95 % bootstrap intervals over the scored pixels.

use crate::colour::{delta_e2000, xyz_to_lab};

/// Errors of one set of XYZ samples against another (MODEL §6).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStats {
    /// `‖xyz − ref‖₂ / ‖ref‖₂` over all samples and channels.
    pub rel_l2: f64,
    /// Largest `|Y − Y_ref|`.
    pub max_abs_y: f64,
    /// Mean and largest CIEDE2000 after scaling by `1 / max Y_ref`.
    pub mean_de: f64,
    pub max_de: f64,
    /// Median and 99th percentile of the same CIEDE2000 values.
    pub p50_de: f64,
    pub p99_de: f64,
}

/// Compares `xyz` with `reference` sample by sample.
pub fn error_stats(xyz: &[[f64; 3]], reference: &[[f64; 3]]) -> ErrorStats {
    let y_max = reference.iter().map(|r| r[1]).fold(0.0, f64::max);
    let scale = if y_max > 0.0 { 1.0 / y_max } else { 1.0 };
    let (mut diff2, mut ref2, mut max_abs_y) = (0.0, 0.0, 0.0);
    let mut des = Vec::with_capacity(xyz.len());
    for (a, r) in xyz.iter().zip(reference) {
        for c in 0..3 {
            diff2 += (a[c] - r[c]).powi(2);
            ref2 += r[c] * r[c];
        }
        max_abs_y = f64::max(max_abs_y, (a[1] - r[1]).abs());
        let de = delta_e2000(
            xyz_to_lab(a.map(|v| (v * scale).max(0.0))),
            xyz_to_lab(r.map(|v| (v * scale).max(0.0))),
        );
        des.push(de);
    }
    let n = xyz.len().max(1) as f64;
    des.sort_by(f64::total_cmp);
    let pct = |p: f64| {
        if des.is_empty() {
            0.0
        } else {
            des[((p * (des.len() - 1) as f64).round() as usize).min(des.len() - 1)]
        }
    };
    ErrorStats {
        rel_l2: if ref2 > 0.0 {
            (diff2 / ref2).sqrt()
        } else {
            diff2.sqrt()
        },
        max_abs_y,
        mean_de: des.iter().sum::<f64>() / n,
        max_de: des.last().copied().unwrap_or(0.0),
        p50_de: pct(0.5),
        p99_de: pct(0.99),
    }
}

/// A 95 % interval of an error figure: the 2.5th and 97.5th percentiles of the figure
/// over bootstrap resamples of the scored pixels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Interval {
    pub lo: f64,
    pub hi: f64,
}

impl Interval {
    /// Whether the two intervals share a value.
    pub fn overlaps(&self, other: &Interval) -> bool {
        self.lo <= other.hi && other.lo <= self.hi
    }
}

/// The bootstrap intervals of a row's errors against the reference.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ErrorIntervals {
    pub rel_l2: Interval,
    pub p99_de: Interval,
}

/// Resamples in [`bootstrap`]: enough for the 2.5th and 97.5th percentiles to move by
/// less than the intervals' own width between runs.
const RESAMPLES: usize = 400;

/// 95 % intervals of `error_stats(xyz, reference)`'s relative L2 and ΔE p99 by the
/// bootstrap over pixels: [`RESAMPLES`] draws of as many pixels with replacement, from a
/// fixed seed (the same pixels give the same interval).
pub fn bootstrap(xyz: &[[f64; 3]], reference: &[[f64; 3]]) -> ErrorIntervals {
    let n = xyz.len().min(reference.len());
    if n == 0 {
        return ErrorIntervals::default();
    }
    // xorshift64*: a fixed, dependency-free stream of indices.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as usize % n
    };
    let (mut l2, mut p99) = (Vec::with_capacity(RESAMPLES), Vec::with_capacity(RESAMPLES));
    let (mut a, mut r) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
    for _ in 0..RESAMPLES {
        for k in 0..n {
            let i = next();
            a[k] = xyz[i];
            r[k] = reference[i];
        }
        let e = error_stats(&a, &r);
        l2.push(e.rel_l2);
        p99.push(e.p99_de);
    }
    let interval = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let at = |p: f64| v[((p * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
        Interval {
            lo: at(0.025),
            hi: at(0.975),
        }
    };
    ErrorIntervals {
        rel_l2: interval(l2),
        p99_de: interval(p99),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_samples_have_zero_error_and_differences_show() {
        let r = vec![[0.2, 0.3, 0.1], [0.01, 0.02, 0.03]];
        let e = error_stats(&r, &r);
        assert_eq!((e.rel_l2, e.max_abs_y, e.max_de), (0.0, 0.0, 0.0));
        let a = vec![[0.2, 0.33, 0.1], [0.01, 0.02, 0.03]];
        let e = error_stats(&a, &r);
        assert!((e.max_abs_y - 0.03).abs() < 1e-12);
        assert!(e.rel_l2 > 0.05 && e.rel_l2 < 0.1, "{}", e.rel_l2);
        assert!(e.max_de > 1.0);
    }

    #[test]
    fn bootstrap_intervals_hold_the_figure_and_narrow_with_more_pixels() {
        // Errors of 1 % to 9 % of a varying signal: the interval holds the figure itself
        // and shrinks as the pixels it resamples grow in number.
        let sample = |n: usize| -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
            let r: Vec<[f64; 3]> = (0..n)
                .map(|k| [0.2 + 0.1 * ((k * 7) % 11) as f64 / 11.0; 3])
                .collect();
            let a = r
                .iter()
                .enumerate()
                .map(|(k, v)| v.map(|x| x * (1.0 + 0.01 * (1 + (k * 5) % 9) as f64)))
                .collect();
            (a, r)
        };
        let (a, r) = sample(32);
        let e = error_stats(&a, &r);
        let i = bootstrap(&a, &r);
        assert!(
            i.rel_l2.lo <= e.rel_l2 && e.rel_l2 <= i.rel_l2.hi,
            "{i:?} {e:?}"
        );
        assert!(i.rel_l2.lo < i.rel_l2.hi);
        assert_eq!(bootstrap(&a, &r), i, "a fixed seed");
        let (a4, r4) = sample(512);
        let wide = bootstrap(&a, &r).rel_l2;
        let narrow = bootstrap(&a4, &r4).rel_l2;
        assert!(
            narrow.hi - narrow.lo < 0.5 * (wide.hi - wide.lo),
            "{wide:?} {narrow:?}"
        );
    }
}
