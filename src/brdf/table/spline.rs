//! Interpolation on a plane of nodes: grid positions, bilinear interpolation and the cubic
//! B-splines that the spline-interpolated representations store.

use super::Region;

/// Fractional grid position of `x` on `n` nodes spanning `[lo, hi]`, or `None` outside.
pub(super) fn grid_pos(x: f64, lo: f64, hi: f64, n: usize) -> Option<(usize, f64)> {
    if !(x >= lo && x <= hi) {
        return None;
    }
    let t = (x - lo) / (hi - lo) * (n - 1) as f64;
    let i = (t.floor() as usize).min(n - 2);
    Some((i, t - i as f64))
}

/// Bilinear interpolation of `plane` (`nu × nv`, row-major) at `(u, v)` of `region`.
pub(super) fn bilinear(
    plane: &[[f64; 3]],
    nu: usize,
    nv: usize,
    region: &Region,
    u: f64,
    v: f64,
) -> Option<[f64; 3]> {
    let (i, fx) = grid_pos(u, region.lo[0], region.hi[0], nu)?;
    let (j, fy) = grid_pos(v, region.lo[1], region.hi[1], nv)?;
    let at = |i: usize, j: usize| plane[j * nu + i];
    Some([0, 1, 2].map(|c| {
        let a = at(i, j)[c] * (1.0 - fx) + at(i + 1, j)[c] * fx;
        let b = at(i, j + 1)[c] * (1.0 - fx) + at(i + 1, j + 1)[c] * fx;
        a * (1.0 - fy) + b * fy
    }))
}

/// Cubic B-spline coefficients that interpolate `values` (`n` nodes along one axis, any
/// stride): `(c_{i−1} + 4c_i + c_{i+1})/6 = f_i`, with `c_0 = f_0` and `c_{n−1} = f_{n−1}`,
/// returned with one ghost on each side (`c_{−1} = 2c_0 − c_1`, `c_n = 2c_{n−1} − c_{n−2}`,
/// which makes the end nodes exact): `n + 2` values.
fn spline_axis(values: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let n = values.len();
    let mut c = values.to_vec();
    if n > 2 {
        // Thomas algorithm on the interior rows i = 1..n−2 of the (1, 4, 1)/6 system.
        let m = n - 2;
        let mut diag = vec![4.0f64; m];
        let mut rhs: Vec<[f64; 3]> = (1..n - 1).map(|i| values[i].map(|x| 6.0 * x)).collect();
        for ch in 0..3 {
            rhs[0][ch] -= values[0][ch];
            rhs[m - 1][ch] -= values[n - 1][ch];
        }
        for k in 1..m {
            let f = 1.0 / diag[k - 1];
            diag[k] -= f;
            let prev = rhs[k - 1];
            for (r, p) in rhs[k].iter_mut().zip(prev) {
                *r -= f * p;
            }
        }
        let mut x = vec![[0.0; 3]; m];
        x[m - 1] = rhs[m - 1].map(|r| r / diag[m - 1]);
        for k in (0..m - 1).rev() {
            x[k] = [0, 1, 2].map(|ch| (rhs[k][ch] - x[k + 1][ch]) / diag[k]);
        }
        c[1..n - 1].copy_from_slice(&x);
    }
    let ghost = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|ch| 2.0 * a[ch] - b[ch]);
    let mut out = Vec::with_capacity(n + 2);
    out.push(ghost(c[0], c[1]));
    out.extend_from_slice(&c);
    out.push(ghost(c[n - 1], c[n - 2]));
    out
}

/// The `(nu + 2) × (nv + 2)` cubic B-spline coefficients interpolating an `nu × nv` plane
/// (row-major), separably: rows, then columns.
pub fn spline_plane(plane: &[[f64; 3]], nu: usize, nv: usize) -> Vec<[f64; 3]> {
    let rows: Vec<Vec<[f64; 3]>> = plane.chunks_exact(nu).map(spline_axis).collect();
    let (su, sv) = (nu + 2, nv + 2);
    let mut out = vec![[0.0; 3]; su * sv];
    for i in 0..su {
        let column: Vec<[f64; 3]> = rows.iter().map(|r| r[i]).collect();
        for (j, c) in spline_axis(&column).into_iter().enumerate() {
            out[j * su + i] = c;
        }
    }
    out
}

/// The uniform cubic B-spline weights of the four coefficients around fraction `f`.
pub fn spline_weights(f: f64) -> [f64; 4] {
    let (f2, f3) = (f * f, f * f * f);
    [
        (1.0 - f) * (1.0 - f) * (1.0 - f) / 6.0,
        (3.0 * f3 - 6.0 * f2 + 4.0) / 6.0,
        (-3.0 * f3 + 3.0 * f2 + 3.0 * f + 1.0) / 6.0,
        f3 / 6.0,
    ]
}

/// Evaluates the spline of [`spline_plane`] coefficients at `(u, v)` of `region`.
pub(super) fn spline(
    coeffs: &[[f64; 3]],
    nu: usize,
    nv: usize,
    region: &Region,
    u: f64,
    v: f64,
) -> Option<[f64; 3]> {
    let (i, fx) = grid_pos(u, region.lo[0], region.hi[0], nu)?;
    let (j, fy) = grid_pos(v, region.lo[1], region.hi[1], nv)?;
    let (wx, wy) = (spline_weights(fx), spline_weights(fy));
    let su = nu + 2;
    let mut out = [0.0; 3];
    // c_{i−1} sits at stored index i (one ghost before the first node).
    for (b, wyb) in wy.iter().enumerate() {
        for (a, wxa) in wx.iter().enumerate() {
            let c = coeffs[(j + b) * su + i + a];
            for (o, x) in out.iter_mut().zip(c) {
                *o += wxa * wyb * x;
            }
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splines_interpolate_nodes_exactly_and_cubics_everywhere() {
        let region = Region {
            lo: [-1.0, 0.0, -1.0],
            hi: [1.0, 3.0, 0.0],
        };
        let (nu, nv) = (9, 7);
        let f = |u: f64, v: f64| 1.0 + u - 0.5 * u * u * v + 0.25 * v * v * v;
        let node =
            |i: usize, n: usize, lo: f64, hi: f64| lo + (hi - lo) * i as f64 / (n - 1) as f64;
        let plane: Vec<[f64; 3]> = (0..nv)
            .flat_map(|j| (0..nu).map(move |i| (i, j)))
            .map(|(i, j)| {
                let x = f(node(i, nu, -1.0, 1.0), node(j, nv, 0.0, 3.0));
                [x, -x, 0.0]
            })
            .collect();
        let c = spline_plane(&plane, nu, nv);
        assert_eq!(c.len(), (nu + 2) * (nv + 2));
        for j in 0..nv {
            for i in 0..nu {
                let (u, v) = (node(i, nu, -1.0, 1.0), node(j, nv, 0.0, 3.0));
                let g = spline(&c, nu, nv, &region, u, v).unwrap();
                assert!((g[0] - plane[j * nu + i][0]).abs() < 1e-12, "node {i},{j}");
            }
        }
        // Between nodes: a smooth function is matched far better than linearly.
        let (u, v) = (0.37, 1.61);
        let g = spline(&c, nu, nv, &region, u, v).unwrap()[0];
        let lin = bilinear(&plane, nu, nv, &region, u, v).unwrap()[0];
        assert!(
            (g - f(u, v)).abs() < 0.2 * (lin - f(u, v)).abs(),
            "{g} {lin} {}",
            f(u, v)
        );
        assert!(spline(&c, nu, nv, &region, 1.1, 1.0).is_none());
    }
}
