//! Where the `w` nodes of a table lie, and how many a Chebyshev series in `w` needs.

use super::MAX_NODES_W;

/// Largest `|c_K|/|c_0|` the default `chebyshev-w` coefficient count allows.
pub const CHEBYSHEV_W_TOLERANCE: f64 = 1e-4;

/// Fewest `chebyshev-w` coefficients fitted to a narrow `w` range.
pub const MIN_CHEBYSHEV_W_NODES: usize = 4;

/// Uniform `w` nodes over `[lo, hi]`, both ends included (volume slices).
pub fn uniform_nodes(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| lo + (hi - lo) * k as f64 / (n - 1).max(1) as f64)
        .collect()
}

/// Chebyshev nodes of the first kind mapped to `[lo, hi]`:
/// `w_k = mid + half·cos(π(k + ½)/K)`.
pub fn chebyshev_nodes(lo: f64, hi: f64, k: usize) -> Vec<f64> {
    let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo));
    (0..k)
        .map(|i| mid + half * (std::f64::consts::PI * (i as f64 + 0.5) / k as f64).cos())
        .collect()
}

/// Chebyshev coefficients in `w` a height range `h_range_um` needs over `w ∈ [w0, w1]` to
/// meet [`CHEBYSHEV_W_TOLERANCE`] (at least [`MIN_CHEBYSHEV_W_NODES`], at most
/// [`MAX_NODES_W`]). `G = Σ_λ |P̂|²` varies with `w` through phases `s·(h − h')`,
/// `s = 2πw/λ`, so its Chebyshev coefficients in `ŵ` decay like the Bessel functions
/// `J_j(a)` of `a = (2π/λ_min)·(h_max − h_min)·(w1 − w0)/2`; K is two more than the first
/// `j` with `|J_j(a)| ≤` the tolerance.
pub fn chebyshev_w_nodes(h_range_um: f64, w: [f64; 2]) -> usize {
    let k_max = 2.0 * std::f64::consts::PI / (crate::colour::LAMBDA_MIN_NM as f64 * 1e-3);
    let a = k_max * h_range_um.max(0.0) * 0.5 * (w[1] - w[0]).abs();
    let max = MAX_NODES_W;
    let j = crate::brdf::bessel::jn_all(a, max);
    let first = (0..=max)
        .find(|&n| n as f64 > a && j[n..].iter().all(|x| x.abs() <= CHEBYSHEV_W_TOLERANCE))
        .unwrap_or(max);
    (first + 2).clamp(MIN_CHEBYSHEV_W_NODES, max)
}
