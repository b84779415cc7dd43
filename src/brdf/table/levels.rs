//! Pre-filtered levels of a `chebyshev-w` table, for a pixel's footprint: a pixel of a
//! curved surface covers a patch of `(u, v)` that spans many lobes 0.005 wide, and one
//! lookup at its centre aliases. Level `L + 1` is level `L` filtered by the tent
//! `[1, 2, 1]/4` along `u` and `v` (at level `L`'s node spacing), read linearly at nodes
//! about twice as far apart over the same region, and fitted with splines again. The
//! coefficient planes are linear in `G`, so a level is the series of the filtered `G`.
//! Repeated, the kernel of level `L` is close to a Gaussian of standard deviation
//! `h·√((4^L − 1)/6)` (`h` the finest spacing): the shader picks the level whose kernel
//! matches the pixel's footprint ([`Levelled`] stacks the levels in one image).

use rayon::prelude::*;

use super::representation::{ChebyshevW, GTable};
use super::spline::spline_plane;
use super::Region;

/// Most levels a table keeps (the finest included).
pub const MAX_LEVELS: usize = 6;

/// `plane` (`nu × nv`, row-major) filtered by `[1, 2, 1]/4` along each axis, the edges
/// repeated.
pub fn tent_plane(plane: &[[f64; 3]], nu: usize, nv: usize) -> Vec<[f64; 3]> {
    let pass = |src: &[[f64; 3]], along_u: bool| -> Vec<[f64; 3]> {
        let mut out = vec![[0.0; 3]; src.len()];
        for j in 0..nv {
            for i in 0..nu {
                let at = |i: usize, j: usize| src[j * nu + i];
                let (a, b) = if along_u {
                    (at(i.saturating_sub(1), j), at((i + 1).min(nu - 1), j))
                } else {
                    (at(i, j.saturating_sub(1)), at(i, (j + 1).min(nv - 1)))
                };
                let c = at(i, j);
                out[j * nu + i] = [0, 1, 2].map(|k| 0.25 * a[k] + 0.5 * c[k] + 0.25 * b[k]);
            }
        }
        out
    };
    pass(&pass(plane, true), false)
}

/// `plane` (`nu × nv` nodes over a region) read bilinearly at `mu × mv` nodes over the
/// same region.
pub fn resample_plane(
    plane: &[[f64; 3]],
    (nu, nv): (usize, usize),
    (mu, mv): (usize, usize),
) -> Vec<[f64; 3]> {
    let axis = |k: usize, m: usize, n: usize| {
        let x = k as f64 * (n - 1) as f64 / (m - 1).max(1) as f64;
        let i = (x.floor() as usize).min(n.saturating_sub(2));
        (i, x - i as f64)
    };
    let mut out = Vec::with_capacity(mu * mv);
    for b in 0..mv {
        let (j, fy) = axis(b, mv, nv);
        for a in 0..mu {
            let (i, fx) = axis(a, mu, nu);
            let at = |i: usize, j: usize| plane[j.min(nv - 1) * nu + i.min(nu - 1)];
            let (p, q, r, s) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
            out.push([0, 1, 2].map(|k| {
                (1.0 - fy) * ((1.0 - fx) * p[k] + fx * q[k]) + fy * ((1.0 - fx) * r[k] + fx * s[k])
            }));
        }
    }
    out
}

/// The nodes of the level coarser than one of `nu × nv` nodes: about half the spacing's
/// count along each side, both ends kept; `None` once a side has fewer than 4 nodes.
fn coarser_nodes(nu: usize, nv: usize) -> Option<(usize, usize)> {
    (nu >= 4 && nv >= 4).then(|| ((nu - 1).div_ceil(2) + 1, (nv - 1).div_ceil(2) + 1))
}

impl ChebyshevW {
    /// The next coarser level (module notes); `None` once a side has fewer than 4 nodes.
    pub fn coarser(&self) -> Option<ChebyshevW> {
        let (mu, mv) = coarser_nodes(self.nu, self.nv)?;
        let coeffs: Vec<Vec<[f64; 3]>> = self
            .coeffs
            .par_iter()
            .map(|c| {
                resample_plane(
                    &tent_plane(c, self.nu, self.nv),
                    (self.nu, self.nv),
                    (mu, mv),
                )
            })
            .collect();
        let splines = coeffs.par_iter().map(|c| spline_plane(c, mu, mv)).collect();
        Some(ChebyshevW {
            region: self.region,
            nu: mu,
            nv: mv,
            coeffs,
            splines,
        })
    }
}

/// A `chebyshev-w` table with its pre-filtered levels in one image: the finest level's
/// spline planes (`(nu + 2) × (nv + 2)` texels) at the origin, the coarser ones in a column
/// to its right, each at `(x, y)` ([`Levelled::layout_of`]). As a [`GTable`] it is the
/// finest level (what the maps and the CPU model read); its planes are the combined ones,
/// which the GPU uploads as they are.
#[derive(Debug, Clone, PartialEq)]
pub struct Levelled {
    pub base: ChebyshevW,
    /// `(nu, nv, x, y)` of each level, the finest first.
    pub levels: Vec<[usize; 4]>,
    width: usize,
    height: usize,
    planes: Vec<Vec<[f64; 3]>>,
}

impl Levelled {
    /// `base` and up to `count − 1` coarser levels (fewer where the table is small).
    pub fn new(base: ChebyshevW, count: usize) -> Self {
        let mut all = vec![base];
        while all.len() < count.clamp(1, MAX_LEVELS) {
            match all.last().and_then(ChebyshevW::coarser) {
                Some(next) => all.push(next),
                None => break,
            }
        }
        // The same rule of nodes as `coarser`'s: the layout a cached table is read back by.
        let levels = Self::layout_of(all[0].nu, all[0].nv, all.len());
        let (width, height) = Self::dims(&levels);
        let planes = (0..all[0].splines.len())
            .map(|j| {
                let mut plane = vec![[0.0; 3]; width * height];
                for (t, &[nu, nv, x, y]) in all.iter().zip(&levels) {
                    for r in 0..nv + 2 {
                        let src = &t.splines[j][r * (nu + 2)..(r + 1) * (nu + 2)];
                        let at = (y + r) * width + x;
                        plane[at..at + nu + 2].copy_from_slice(src);
                    }
                }
                plane
            })
            .collect();
        let base = all.swap_remove(0);
        Levelled {
            base,
            levels,
            width,
            height,
            planes,
        }
    }

    /// Where the levels of a table of `nu × nv` nodes lie, `(nu, nv, x, y)` each, for up to
    /// `count` levels: the finest at the origin, each coarser one (a side halved, while a
    /// side keeps at least 4 nodes) below the previous in a column right of the finest.
    pub fn layout_of(nu: usize, nv: usize, count: usize) -> Vec<[usize; 4]> {
        let mut levels = vec![[nu, nv, 0, 0]];
        let (mut u, mut v, mut y) = (nu, nv, 0);
        while levels.len() < count.clamp(1, MAX_LEVELS) {
            let Some(next) = coarser_nodes(u, v) else {
                break;
            };
            (u, v) = next;
            levels.push([u, v, nu + 2, y]);
            y += v + 2;
        }
        levels
    }

    /// The texels of the combined image for `levels`.
    pub fn dims(levels: &[[usize; 4]]) -> (usize, usize) {
        let w = levels.iter().map(|l| l[2] + l[0] + 2).max().unwrap_or(0);
        let h = levels.iter().map(|l| l[3] + l[1] + 2).max().unwrap_or(0);
        (w, h)
    }
}

impl GTable for Levelled {
    fn region(&self) -> &Region {
        self.base.region()
    }
    fn g_unclamped(&self, uvw: [f64; 3]) -> Option<[f64; 3]> {
        self.base.g_unclamped(uvw)
    }
    fn planes(&self) -> &[Vec<[f64; 3]>] {
        &self.planes
    }
    fn nodes_uv(&self) -> (usize, usize) {
        self.base.nodes_uv()
    }
    fn plane_dims(&self) -> (usize, usize) {
        (self.width, self.height)
    }
    fn footprint_levels(&self) -> usize {
        self.levels.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A test table whose planes are `f(u, v)` and half of it.
    fn table(nu: usize, nv: usize, f: impl Fn(f64, f64) -> f64) -> ChebyshevW {
        super::super::representation::test_chebyshev_w(nu, nv, |i, k, j| {
            let u = -0.1 + i as f64 * 0.2 / (nu - 1) as f64;
            let v = -0.05 + k as f64 * 0.1 / (nv - 1) as f64;
            f(u, v) / (j + 1) as f64
        })
    }

    /// A level holds, at its nodes, the tent average of the finer level's nodes, read
    /// linearly where its nodes fall between them: checked at every node of the first
    /// level against a direct sum of the finer nodes with the tent's weights.
    #[test]
    fn a_level_is_the_tent_average_of_the_finer_one() {
        let t = table(41, 21, |u, v| {
            (-((u - 0.01) * (u - 0.01) + v * v) / 2e-4).exp()
        });
        let c = t.coarser().expect("a coarser level");
        assert_eq!((c.nu, c.nv), (21, 11));
        let at = |i: isize, j: isize| {
            let (i, j) = (i.clamp(0, 40) as usize, j.clamp(0, 20) as usize);
            t.coeffs[0][j * 41 + i][1]
        };
        for b in 0..11 {
            for a in 0..21 {
                let (i, j) = (2 * a as isize, 2 * b as isize);
                let mut want = 0.0;
                for (dj, wj) in [(-1, 0.25), (0, 0.5), (1, 0.25)] {
                    for (di, wi) in [(-1, 0.25), (0, 0.5), (1, 0.25)] {
                        want += wi * wj * at(i + di, j + dj);
                    }
                }
                let got = c.coeffs[0][b * 21 + a][1];
                assert!(
                    (got - want).abs() < 1e-12,
                    "node ({a}, {b}): {got} vs {want}"
                );
            }
        }
        // The levels keep G's integral over the region's interior, and a constant stays.
        let flat = table(17, 17, |_, _| 0.7);
        let mut l = flat.clone();
        while let Some(next) = l.coarser() {
            l = next;
            assert!(l.coeffs[0].iter().all(|c| (c[0] - 0.7).abs() < 1e-12));
        }
    }

    /// A Gaussian lobe in `u` filtered down the levels widens as the kernel's variance
    /// adds to its own: after level `L` its variance is `σ² + h²(4^L − 1)/6`, within 5 %.
    #[test]
    fn a_lobe_widens_by_the_stated_kernel() {
        let (n, sigma) = (801usize, 0.004);
        let t = table(n, 33, |u, _| (-u * u / (2.0 * sigma * sigma)).exp());
        let h = 0.2 / (n - 1) as f64;
        let mut level = t;
        for l in 1..=4 {
            level = level.coarser().expect("coarser");
            let nu = level.nu;
            let row = &level.coeffs[0][nu..2 * nu];
            let us: Vec<f64> = (0..nu)
                .map(|i| -0.1 + i as f64 * 0.2 / (nu - 1) as f64)
                .collect();
            let mass: f64 = row.iter().map(|c| c[0]).sum();
            let var: f64 = row.iter().zip(&us).map(|(c, u)| c[0] * u * u).sum::<f64>() / mass;
            let want = sigma * sigma + h * h * (4f64.powi(l) - 1.0) / 6.0;
            assert!(
                (var / want - 1.0).abs() < 0.05,
                "level {l}: variance {var:e} against {want:e}"
            );
        }
    }

    /// The combined image holds each level's planes where its layout says, and the layout
    /// follows from the nodes and the count alone.
    #[test]
    fn the_levels_lie_where_the_layout_says() {
        let t = table(33, 17, |u, v| (u * 40.0).sin() + v);
        let l = Levelled::new(t.clone(), 4);
        assert_eq!(l.levels, Levelled::layout_of(33, 17, 4));
        assert_eq!(l.footprint_levels(), 4);
        assert_eq!(l.levels.len(), 4);
        let (w, h) = l.plane_dims();
        assert_eq!((w, h), Levelled::dims(&l.levels));
        assert!(
            w == 35 + 19 && h >= 19,
            "{w}×{h}: the coarser levels lie beside the finest"
        );
        let c = t.coarser().unwrap();
        let [nu, nv, x, y] = l.levels[1];
        assert_eq!((nu, nv), (c.nu, c.nv));
        for r in 0..nv + 2 {
            for i in 0..nu + 2 {
                assert_eq!(
                    l.planes()[1][(y + r) * w + x + i],
                    c.splines[1][r * (nu + 2) + i]
                );
            }
        }
        assert_eq!(l.g([0.01, 0.0, -1.0]), t.g([0.01, 0.0, -1.0]));
        // One level is the table itself.
        let one = Levelled::new(t.clone(), 1);
        assert_eq!(one.plane_dims(), (35, 19));
        assert_eq!(one.planes(), &t.splines[..]);
    }
}
