//! The sun's disc as a footprint in `(u, v)` and the pre-filter that convolves a table with
//! it.

use rayon::prelude::*;

use super::spline::spline_plane;
use super::{Region, Slices};

/// The sun's disc as a footprint in `(u, v)`: the directions over a disc of angular radius
/// `α` around the light's centre `ωi` move `(u, v) = −(ωi + ωr).xy` by the tangent-plane
/// projection of their offsets, an ellipse with semi-axes `α` (across the plane of incidence)
/// and `α·cosθi` (along it). `axes` maps the unit disc onto it: offset `= axes·p`, `|p| ≤ 1`.
/// A table convolved with it ([`prefilter_disc`]) holds the disc's sum of `G`, so a shader
/// evaluates it once, at the centre direction, instead of once per direction of the disc.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscKernel {
    /// Columns: the images of the unit disc's x and y axes (u, v).
    pub axes: [[f64; 2]; 2],
}

impl DiscKernel {
    /// A circle of radius `radius` in `(u, v)` (the footprint at normal incidence).
    pub fn isotropic(radius: f64) -> Self {
        Self {
            axes: [[radius, 0.0], [0.0, radius]],
        }
    }

    /// The exact footprint of a disc of angular radius `radius` (rad) around `wi` (tangent
    /// frame, unit; small-angle: offsets are tangent to the sphere).
    pub fn footprint(wi: [f64; 3], radius: f64) -> Self {
        let h = (wi[0] * wi[0] + wi[1] * wi[1]).sqrt();
        // a ⊥ ωi and ⊥ N (unit in the plane); b = ωi × a, whose projection is cosθi long.
        let a = if h > 1e-12 {
            [-wi[1] / h, wi[0] / h, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let b = [
            wi[1] * a[2] - wi[2] * a[1],
            wi[2] * a[0] - wi[0] * a[2],
            wi[0] * a[1] - wi[1] * a[0],
        ];
        Self {
            axes: [
                [radius * a[0], radius * b[0]],
                [radius * a[1], radius * b[1]],
            ],
        }
    }

    /// Covariance of the uniform ellipse: `axes·axesᵀ/4`.
    pub fn covariance(&self) -> [[f64; 2]; 2] {
        let m = &self.axes;
        let c = |i: usize, j: usize| 0.25 * (m[i][0] * m[j][0] + m[i][1] * m[j][1]);
        [[c(0, 0), c(0, 1)], [c(1, 0), c(1, 1)]]
    }

    /// The uniform ellipse of covariance `cov` (symmetric, positive semi-definite): axes
    /// `2·√cov` (the symmetric square root).
    pub fn with_covariance(cov: [[f64; 2]; 2]) -> Self {
        let (a, b, d) = (cov[0][0], 0.5 * (cov[0][1] + cov[1][0]), cov[1][1]);
        // √ of a 2×2 SPD matrix: (M + √det·I)/√(tr + 2√det).
        let det = (a * d - b * b).max(0.0).sqrt();
        let t = (a + d + 2.0 * det).max(0.0).sqrt();
        if t <= 0.0 {
            return Self::isotropic(0.0);
        }
        let s = |x: f64| 2.0 * x / t;
        Self {
            axes: [[s(a + det), s(b)], [s(b), s(d + det)]],
        }
    }

    /// The covariance-mean of footprints: one ellipse for many directions of the light.
    pub fn mean(kernels: &[DiscKernel]) -> Option<Self> {
        if kernels.is_empty() {
            return None;
        }
        let mut c = [[0.0; 2]; 2];
        for k in kernels {
            let kc = k.covariance();
            for i in 0..2 {
                for j in 0..2 {
                    c[i][j] += kc[i][j] / kernels.len() as f64;
                }
            }
        }
        Some(Self::with_covariance(c))
    }

    /// The largest offset (the semi-major axis).
    pub fn reach(&self) -> f64 {
        let c = self.covariance();
        let (a, b, d) = (c[0][0], c[0][1], c[1][1]);
        let l = 0.5 * (a + d) + (0.25 * (a - d) * (a - d) + b * b).sqrt();
        2.0 * l.max(0.0).sqrt()
    }

    /// Weights `K(m)` of node offsets `m = (mu, mv)` on a grid of spacing `(du, dv)`:
    /// the disc's mean of the tensor cubic B-spline, `K(m) = E_p[β₃(mu − x_p)·β₃(mv − y_p)]`
    /// with `(x_p, y_p)` = `axes·p / (du, dv)`, `p` uniform on the unit disc. Convolving
    /// the spline coefficients of a plane with it gives the exact disc average of the
    /// spline interpolant at every node. Sums to 1 (partition of unity).
    pub fn taps(&self, du: f64, dv: f64) -> Vec<(i64, i64, f64)> {
        // Uniform points on the unit disc: rings of equal width, points in proportion to
        // each ring's area.
        const RINGS: usize = 24;
        let mut pts = Vec::new();
        for r in 0..RINGS {
            let rho = (r as f64 + 0.5) / RINGS as f64;
            let n = 6 * (2 * r + 1);
            for k in 0..n {
                let phi = 2.0 * std::f64::consts::PI * (k as f64 + 0.5 * (r % 2) as f64) / n as f64;
                let (s, c) = phi.sin_cos();
                let (x, y) = (rho * c, rho * s);
                let m = &self.axes;
                pts.push((
                    (m[0][0] * x + m[0][1] * y) / du,
                    (m[1][0] * x + m[1][1] * y) / dv,
                ));
            }
        }
        let reach_u = (self.axes[0][0].hypot(self.axes[0][1]) / du).ceil() as i64 + 2;
        let reach_v = (self.axes[1][0].hypot(self.axes[1][1]) / dv).ceil() as i64 + 2;
        let b3 = |x: f64| {
            let x = x.abs();
            if x < 1.0 {
                (4.0 - 6.0 * x * x + 3.0 * x * x * x) / 6.0
            } else if x < 2.0 {
                (2.0 - x).powi(3) / 6.0
            } else {
                0.0
            }
        };
        let mut taps = Vec::new();
        for mv in -reach_v..=reach_v {
            for mu in -reach_u..=reach_u {
                let w: f64 = pts
                    .iter()
                    .map(|&(x, y)| b3(mu as f64 - x) * b3(mv as f64 - y))
                    .sum::<f64>()
                    / pts.len() as f64;
                if w > 1e-12 {
                    taps.push((mu, mv, w));
                }
            }
        }
        taps
    }
}

/// Convolves every slice of `slices` (nodes over `region`) with the disc `kernel`: each node
/// becomes the disc's average of the cubic-spline interpolant of its slice around it
/// ([`DiscKernel::taps`]). Near the edges the coefficients are clamped to the border.
pub fn prefilter_disc(slices: &mut Slices, region: &Region, kernel: &DiscKernel) {
    let (nu, nv) = (slices.nu, slices.nv);
    let e = region.extent();
    let (du, dv) = (e[0] / (nu - 1) as f64, e[1] / (nv - 1) as f64);
    let taps = kernel.taps(du, dv);
    slices.data.par_iter_mut().for_each(|plane| {
        let c = spline_plane(plane, nu, nv);
        let su = nu + 2;
        let clamp = |x: i64, n: usize| x.clamp(0, n as i64 + 1) as usize;
        for j in 0..nv {
            for i in 0..nu {
                let mut acc = [0.0; 3];
                for &(mu, mv, w) in &taps {
                    // Node i's coefficient is stored at i + 1 (one ghost before).
                    let ci = clamp(i as i64 + 1 - mu, nu);
                    let cj = clamp(j as i64 + 1 - mv, nv);
                    let x = c[cj * su + ci];
                    for ch in 0..3 {
                        acc[ch] += w * x[ch];
                    }
                }
                plane[j * nu + i] = acc;
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_disc_footprint_is_the_projected_ellipse() {
        let a = 0.0046;
        // At normal incidence a circle; at θi = 60° the axis along the plane of incidence
        // (azimuth 30° here) shrinks to α·cosθi, the other stays α.
        let c0 = DiscKernel::footprint([0.0, 0.0, 1.0], a).covariance();
        assert!((c0[0][0] - a * a / 4.0).abs() < 1e-15 && c0[0][1].abs() < 1e-15);
        let wi = crate::brdf::direction(60.0, 30.0);
        let k = DiscKernel::footprint(wi, a);
        let c = k.covariance();
        let along = [30f64.to_radians().cos(), 30f64.to_radians().sin()];
        let across = [-along[1], along[0]];
        let q = |d: [f64; 2]| {
            d[0] * (c[0][0] * d[0] + c[0][1] * d[1]) + d[1] * (c[1][0] * d[0] + c[1][1] * d[1])
        };
        assert!((q(along) / (a * a / 4.0 * 0.25) - 1.0).abs() < 1e-9);
        assert!((q(across) / (a * a / 4.0) - 1.0).abs() < 1e-9);
        assert!((k.reach() - a).abs() < 1e-12);
        // The ellipse of a covariance has that covariance; the mean of one is itself.
        let back = DiscKernel::with_covariance(c).covariance();
        let m = DiscKernel::mean(&[k, k]).unwrap().covariance();
        for i in 0..2 {
            for j in 0..2 {
                assert!((back[i][j] - c[i][j]).abs() < 1e-15);
                assert!((m[i][j] - c[i][j]).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn blurring_a_delta_gives_the_disc_with_unit_mass() {
        // One node set to 1 on a 41² grid of spacing h: the spline interpolant of a delta
        // (mass h², no second moment), pre-filtered by an ellipse 4 × 2.5 texels across,
        // rotated. Node sums of the result: mass h², and the ellipse's covariance.
        let h = 0.001;
        let n = 41;
        let region = Region {
            lo: [0.0, 0.0, -1.0],
            hi: [h * (n - 1) as f64, h * (n - 1) as f64, -0.5],
        };
        let mut plane = vec![[0.0; 3]; n * n];
        plane[20 * n + 20] = [1.0, 2.0, 0.0];
        let mut slices = Slices {
            nu: n,
            nv: n,
            w: vec![-0.7],
            data: vec![plane],
        };
        let kernel = DiscKernel::footprint(crate::brdf::direction(51.3, 120.0), 4.0 * h);
        let taps = kernel.taps(h, h);
        let total: f64 = taps.iter().map(|t| t.2).sum();
        assert!((total - 1.0).abs() < 1e-12, "{total}");
        prefilter_disc(&mut slices, &region, &kernel);
        let p = &slices.data[0];
        let (mut mass, mut m) = (0.0, [[0.0; 2]; 2]);
        for j in 0..n {
            for i in 0..n {
                let x = [(i as f64 - 20.0) * h, (j as f64 - 20.0) * h];
                let g = p[j * n + i][0];
                mass += g;
                for a in 0..2 {
                    for b in 0..2 {
                        m[a][b] += g * x[a] * x[b];
                    }
                }
                assert!((p[j * n + i][1] - 2.0 * g).abs() < 1e-15);
            }
        }
        assert!((mass - 1.0).abs() < 1e-9, "mass {mass}");
        let c = kernel.covariance();
        for a in 0..2 {
            for b in 0..2 {
                assert!(
                    (m[a][b] - c[a][b]).abs() < 0.01 * c[0][0].max(c[1][1]),
                    "moment {a}{b}: {} vs {}",
                    m[a][b],
                    c[a][b]
                );
            }
        }
        // Nothing beyond the ellipse and the spline's reach.
        for j in 0..n {
            for i in 0..n {
                let r = ((i as f64 - 20.0).hypot(j as f64 - 20.0)) * h;
                if r > kernel.reach() + 6.0 * h {
                    assert!(p[j * n + i][0].abs() < 1e-3, "{i},{j}: {}", p[j * n + i][0]);
                }
            }
        }
    }
}
