//! Bessel functions of the first kind `J_0..J_T` for the Jacobi–Anger (Chebyshev) expansion
//! of MODEL §4, by Miller's downward recurrence. The GPU shader mirrors this exact scheme
//! (`glsl/`), so the CPU model and the shader differ only by float precision.

/// `[J_0(a), J_1(a), …, J_nmax(a)]` for any real `a`.
///
/// Downward recurrence `J_{k−1} = (2k/a) J_k − J_{k+1}` from a start index well above both
/// `nmax` and `|a|` (where `J` is negligible), normalised by `J_0 + 2 Σ J_{2k} = 1`. Stable
/// for all orders because the recurrence runs in the direction in which `J_n` grows.
/// Values are rescaled during the recurrence so nothing overflows. `J_n(−a) = (−1)ⁿ J_n(a)`.
pub fn jn_all(a: f64, nmax: usize) -> Vec<f64> {
    let mut out = vec![0.0; nmax + 1];
    let x = a.abs();
    if x < 1e-300 {
        out[0] = 1.0;
        return out;
    }
    let start = miller_start(x, nmax);
    let mut j_next = 0.0; // J_{k+1}
    let mut j_cur = 1e-30; // J_k, arbitrary tiny seed
    let mut norm = 0.0;
    for k in (1..=start).rev() {
        if k <= nmax {
            out[k] = j_cur;
        }
        if k % 2 == 0 {
            norm += 2.0 * j_cur;
        }
        let j_prev = (2.0 * k as f64 / x) * j_cur - j_next;
        j_next = j_cur;
        j_cur = j_prev;
        if j_cur.abs() > 1e250 {
            // Rescale everything accumulated so far; only ratios matter.
            let s = 1e-250;
            j_cur *= s;
            j_next *= s;
            norm *= s;
            for v in out.iter_mut() {
                *v *= s;
            }
        }
    }
    out[0] = j_cur;
    norm += j_cur;
    let sign_flip = a < 0.0;
    for (n, v) in out.iter_mut().enumerate() {
        *v /= norm;
        if sign_flip && n % 2 == 1 {
            *v = -*v;
        }
    }
    out
}

/// Even start index of the recurrence: above `nmax` and `x` by a margin that makes the
/// truncated tail negligible in f64 (`J_n(x)` decays like `(ex/2n)^n` past `n ≈ x`).
pub fn miller_start(x: f64, nmax: usize) -> usize {
    let m = (nmax as f64).max(x) + 20.0 + 2.0 * x.sqrt() * 3.0;
    let m = m.ceil() as usize;
    m + (m % 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Power series `J_n(x) = Σ_k (−1)^k (x/2)^{2k+n} / (k! (k+n)!)`, accurate for small x.
    fn series(n: usize, x: f64) -> f64 {
        let mut term = (0.5 * x).powi(n as i32) / (1..=n).map(|i| i as f64).product::<f64>();
        let mut sum = term;
        for k in 1..60 {
            term *= -(0.25 * x * x) / (k as f64 * (k + n) as f64);
            sum += term;
        }
        sum
    }

    #[test]
    fn matches_power_series_for_moderate_arguments() {
        for &x in &[0.01, 0.5, 1.0, 2.5, 7.0, 12.0] {
            let j = jn_all(x, 20);
            for (n, jn) in j.iter().enumerate() {
                let s = series(n, x);
                assert!((jn - s).abs() < 1e-12, "J_{n}({x}) = {jn} vs {s}");
            }
        }
    }

    #[test]
    fn known_values_and_symmetry() {
        // J_0(2.404825557695773) = 0 (first zero), J_1(1) = 0.44005058574493355.
        assert!(jn_all(2.404_825_557_695_773, 0)[0].abs() < 1e-14);
        assert!((jn_all(1.0, 1)[1] - 0.440_050_585_744_933_55).abs() < 1e-14);
        let p = jn_all(3.7, 9);
        let m = jn_all(-3.7, 9);
        for n in 0..=9 {
            let s = if n % 2 == 0 { 1.0 } else { -1.0 };
            assert!((m[n] - s * p[n]).abs() < 1e-15);
        }
    }

    #[test]
    fn large_arguments_satisfy_the_sum_rule_and_bounds() {
        for &x in &[30.0, 100.0, 400.0] {
            let j = jn_all(x, 64);
            // |J_n| ≤ 1 and J_0² + 2ΣJ_n² = 1 (with all orders; check the partial sum is ≤ 1).
            assert!(j.iter().all(|v| v.is_finite() && v.abs() <= 1.0));
            let full = jn_all(x, miller_start(x, 64));
            let s: f64 = full[0] * full[0] + 2.0 * full[1..].iter().map(|v| v * v).sum::<f64>();
            assert!((s - 1.0).abs() < 1e-10, "x = {x}: sum rule {s}");
        }
        // J_0(100) = 0.019985850304223122 (tables).
        assert!((jn_all(100.0, 0)[0] - 0.019_985_850_304_223_122).abs() < 1e-13);
    }
}
