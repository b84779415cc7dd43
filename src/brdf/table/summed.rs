//! Summed-area planes of a `chebyshev-w` table, for reading the mean of `G` over a pixel's
//! footprint in one lookup whatever its size and aspect. A pixel of a curved surface covers
//! a patch of `(u, v)` that spans many lobes 0.005 wide; the shader takes the patch as the
//! axis-aligned box with its variance along `u` and along `v` and reads the mean of each
//! coefficient plane over it from four texels of the plane's summed-area table (Crow 1984).
//! The coefficient planes are linear in `G`, so the series of the means is the mean of `G`.
//!
//! The mean is that of the node values held constant over their cells (node `i` over
//! `[i − ½, i + ½]` spacings), with `G` zero outside the table, as the variant draws it
//! there. Boxes of the pixels that tile a picture tile the patch, so their means add up to
//! the patch's light wherever the glints fall (the Gaussian kernels of [`super::Levelled`]
//! do not: their sum over a row of pixels ripples).

use rayon::prelude::*;

use super::region::Region;
use super::representation::{ChebyshevW, GTable};

/// A `chebyshev-w` table with the summed-area planes of its coefficients. As a [`GTable`] it
/// is the table itself (what the maps and the CPU model read, and what the GPU reads at a
/// point); [`GTable::summed`] gives the planes the GPU reads boxes from.
#[derive(Debug, Clone, PartialEq)]
pub struct Summed {
    pub base: ChebyshevW,
}

impl Summed {
    pub fn new(base: ChebyshevW) -> Self {
        Self { base }
    }

    /// Summed-area planes of the coefficient planes' node values: texel `(a, b)` of plane
    /// `j` (row-major, `(nu + 1) × (nv + 1)`) is the sum of the nodes `i < a`, `k < b`. Read
    /// linearly, texel coordinate `c + ½` is the integral (in node spacings) of the nodes
    /// held constant over their cells from the corner `(−½, −½)` to node coordinate `c`.
    pub fn planes_summed(&self) -> Vec<Vec<[f64; 3]>> {
        let (nu, nv) = (self.base.nu, self.base.nv);
        let w = nu + 1;
        self.base
            .coeffs
            .par_iter()
            .map(|c| {
                let mut s = vec![[0.0; 3]; w * (nv + 1)];
                for b in 1..=nv {
                    let mut row = [0.0; 3];
                    for a in 1..=nu {
                        let g = c[(b - 1) * nu + a - 1];
                        for k in 0..3 {
                            row[k] += g[k];
                            s[b * w + a][k] = s[(b - 1) * w + a][k] + row[k];
                        }
                    }
                }
                s
            })
            .collect()
    }

    /// The mean of `G` (before the clamp to `G ≥ 0`) over the box of half-widths `r` node
    /// spacings (each at least ½) about `(u, v)`, at `w`, as the shader reads it: the nodes
    /// held constant over their cells, zero outside the table. `None` where `(u, v, w)` is
    /// outside the region. Direct sums in f64 (the reference the summed planes must meet).
    pub fn box_mean(&self, [u, v, w]: [f64; 3], r: [f64; 2]) -> Option<[f64; 3]> {
        let t = &self.base;
        let reg = &t.region;
        let f = |x: f64, k: usize| (x - reg.lo[k]) / (reg.hi[k] - reg.lo[k]);
        let (fu, fv) = (f(u, 0), f(v, 1));
        let inside = (0.0..=1.0).contains(&fu) && (0.0..=1.0).contains(&fv);
        if !(inside && w >= reg.lo[2] && w <= reg.hi[2]) {
            return None;
        }
        let r = r.map(|x| x.max(0.5));
        let centre = [fu * (t.nu - 1) as f64, fv * (t.nv - 1) as f64];
        // Overlap of node i's cell [i − ½, i + ½] with [lo, hi].
        let overlap = |i: usize, lo: f64, hi: f64| {
            let (a, b) = (i as f64 - 0.5, i as f64 + 0.5);
            (hi.min(b) - lo.max(a)).max(0.0)
        };
        let (ulo, uhi) = (centre[0] - r[0], centre[0] + r[0]);
        let (vlo, vhi) = (centre[1] - r[1], centre[1] + r[1]);
        let area = 4.0 * r[0] * r[1];
        let means: Vec<[f64; 3]> = t
            .coeffs
            .iter()
            .map(|c| {
                let mut sum = [0.0; 3];
                for k in 0..t.nv {
                    let wv = overlap(k, vlo, vhi);
                    if wv == 0.0 {
                        continue;
                    }
                    for i in 0..t.nu {
                        let wu = overlap(i, ulo, uhi);
                        for ch in 0..3 {
                            sum[ch] += wu * wv * c[k * t.nu + i][ch];
                        }
                    }
                }
                sum.map(|s| s / area)
            })
            .collect();
        Some(super::representation::clenshaw(&means, t.w_hat(w)))
    }
}

impl GTable for Summed {
    fn region(&self) -> &Region {
        self.base.region()
    }
    fn g_unclamped(&self, uvw: [f64; 3]) -> Option<[f64; 3]> {
        self.base.g_unclamped(uvw)
    }
    fn planes(&self) -> &[Vec<[f64; 3]>] {
        self.base.planes()
    }
    fn nodes_uv(&self) -> (usize, usize) {
        self.base.nodes_uv()
    }
    fn plane_dims(&self) -> (usize, usize) {
        self.base.plane_dims()
    }
    fn summed(&self) -> Option<Vec<Vec<[f64; 3]>>> {
        Some(self.planes_summed())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A test table whose two coefficient planes are `f(i, k)` at node `(i, k)` and a
    /// tenth of it.
    fn table(nu: usize, nv: usize, f: impl Fn(usize, usize) -> f64) -> Summed {
        Summed::new(super::super::representation::test_chebyshev_w(
            nu,
            nv,
            |i, k, j| f(i, k) / (1 + 9 * j) as f64,
        ))
    }

    /// `(u, v)` of node coordinate `(a, b)` (fractions of a spacing allowed).
    fn uv_at(t: &Summed, a: f64, b: f64) -> (f64, f64) {
        let r = &t.base.region;
        let u = r.lo[0] + a * (r.hi[0] - r.lo[0]) / (t.base.nu - 1) as f64;
        let v = r.lo[1] + b * (r.hi[1] - r.lo[1]) / (t.base.nv - 1) as f64;
        (u, v)
    }

    /// The box mean as glsl/chebyshev_w.frag's `boxAt` reads it: the summed planes rounded
    /// to float32, each corner read bilinearly at its texel coordinate, the four corners
    /// differenced and divided by the box's area in float32, then Clenshaw in `w`.
    fn gpu_box_mean(t: &Summed, planes: &[Vec<[f32; 3]>], uvw: [f64; 3], r: [f64; 2]) -> [f64; 3] {
        let (nu, nv) = (t.base.nu, t.base.nv);
        let reg = &t.base.region;
        let frac = |x: f64, k: usize| (x - reg.lo[k]) / (reg.hi[k] - reg.lo[k]);
        let c = [
            frac(uvw[0], 0) * (nu - 1) as f64,
            frac(uvw[1], 1) * (nv - 1) as f64,
        ];
        let r = r.map(|x| x.max(0.5));
        let corner = |x: f64, n: usize| x.clamp(-0.5, n as f64 - 0.5) + 0.5;
        let read = |p: &[[f32; 3]], x: f64, y: f64| -> [f32; 3] {
            let (i, j) = (
                (x.floor() as usize).min(nu - 1),
                (y.floor() as usize).min(nv - 1),
            );
            let (fx, fy) = ((x - i as f64) as f32, (y - j as f64) as f32);
            let at = |i: usize, j: usize| p[j.min(nv) * (nu + 1) + i.min(nu)];
            let (a, b, cc, d) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
            std::array::from_fn(|k| {
                (1.0 - fy) * ((1.0 - fx) * a[k] + fx * b[k]) + fy * ((1.0 - fx) * cc[k] + fx * d[k])
            })
        };
        let (x0, x1) = (corner(c[0] - r[0], nu), corner(c[0] + r[0], nu));
        let (y0, y1) = (corner(c[1] - r[1], nv), corner(c[1] + r[1], nv));
        let inv = (0.25 / (r[0] * r[1])) as f32;
        let means: Vec<[f64; 3]> = planes
            .iter()
            .map(|p| {
                let (a, b, cc, d) = (
                    read(p, x1, y1),
                    read(p, x0, y1),
                    read(p, x1, y0),
                    read(p, x0, y0),
                );
                std::array::from_fn(|k| (inv * (a[k] - b[k] - cc[k] + d[k])) as f64)
            })
            .collect();
        super::super::representation::clenshaw(&means, t.base.w_hat(uvw[2]))
    }

    fn f32_planes(t: &Summed) -> Vec<Vec<[f32; 3]>> {
        t.planes_summed()
            .iter()
            .map(|p| p.iter().map(|x| x.map(|c| c as f32)).collect())
            .collect()
    }

    /// A box of exactly one cell is its node; the whole table's box is the table's mean.
    #[test]
    fn a_cell_is_its_node_and_the_table_its_mean() {
        let t = table(9, 7, |i, k| (1 + i + 10 * k) as f64);
        for (i, k) in [(1, 1), (3, 2), (7, 5)] {
            let (u, v) = uv_at(&t, i as f64, k as f64);
            let g = t.box_mean([u, v, -1.0], [0.5, 0.5]).unwrap();
            let want = t.base.g_unclamped([u, v, -1.0]).unwrap();
            for c in 0..3 {
                assert!(
                    (g[c] - want[c]).abs() < 1e-12 * want[c].abs(),
                    "{g:?} vs {want:?}"
                );
            }
        }
        let (u, v) = uv_at(&t, 4.0, 3.0);
        let all = t.box_mean([u, v, -1.0], [4.5, 3.5]).unwrap();
        let mean = (0..63)
            .map(|p| (1 + p % 9 + 10 * (p / 9)) as f64)
            .sum::<f64>()
            / 63.0;
        // At w = −1 (ŵ = 0) the series is c0 − c2 + …: here c0 = g, c1 = g/10, no c2.
        assert!((all[0] - mean).abs() < 1e-12 * mean, "{} vs {mean}", all[0]);
    }

    /// A flat-topped lobe: `G = 1` on the cells of nodes 10..=19 along u and 5..=14 along v,
    /// 0 elsewhere. The mean over a box is the area of its overlap with that square of cells
    /// over its own area, in closed form; the GPU's float32 read meets it to 1e-6.
    #[test]
    fn a_flat_lobe_averages_to_its_overlap() {
        let t = table(40, 24, |i, k| {
            ((10..=19).contains(&i) && (5..=14).contains(&k)) as u8 as f64
        });
        let planes = f32_planes(&t);
        let (plateau_u, plateau_v) = ((9.5, 19.5), (4.5, 14.5));
        let overlap = |lo: f64, hi: f64, (a, b): (f64, f64)| (hi.min(b) - lo.max(a)).max(0.0);
        for (cu, cv, ru, rv) in [
            (15.0, 10.0, 2.0, 3.0),
            (9.3, 4.1, 1.7, 0.9),
            (19.8, 14.6, 6.25, 0.5),
            (30.0, 3.0, 11.0, 2.5),
            (25.0, 20.0, 1.0, 1.0),
        ] {
            let (u, v) = uv_at(&t, cu, cv);
            let want = overlap(cu - ru, cu + ru, plateau_u) * overlap(cv - rv, cv + rv, plateau_v)
                / (4.0 * ru * rv);
            let exact = t.box_mean([u, v, -1.0], [ru, rv]).unwrap()[0];
            let gpu = gpu_box_mean(&t, &planes, [u, v, -1.0], [ru, rv])[0];
            assert!(
                (exact - want).abs() < 1e-12,
                "({cu}, {cv}): {exact} vs {want}"
            );
            assert!(
                (gpu - want).abs() < 1e-6,
                "({cu}, {cv}): float32 {gpu} vs {want}"
            );
        }
    }

    /// The float32 read of a table the size of the default scene's (440 × 997 nodes) with a
    /// peak 10⁴ times its floor: against the f64 box mean, within 1e-4 of the box's mean of
    /// |G| plus 2e-7 of the table's total sum over the box's area (the rounding of the sums
    /// the corners hold), at boxes 1 to 60 spacings wide, on the peak and far from it.
    #[test]
    fn float32_sums_read_boxes_to_their_stated_error() {
        let (nu, nv) = (440, 997);
        let peak = |i: usize, k: usize| {
            let (x, y) = (i as f64 - 220.0, k as f64 - 500.0);
            1e4 * (-(x * x + y * y) / 8.0).exp() + 1.0 + 0.5 * ((i * 7 + k * 13) % 11) as f64
        };
        let t = table(nu, nv, peak);
        let planes = f32_planes(&t);
        let total: f64 = (0..nu * nv).map(|p| peak(p % nu, p / nu)).sum();
        let mut worst: f64 = 0.0;
        for (cu, cv) in [
            (220.0, 500.0),
            (221.3, 497.6),
            (30.5, 40.2),
            (400.0, 900.0),
            (5.0, 990.0),
        ] {
            for (ru, rv) in [
                (0.5, 0.5),
                (1.3, 0.7),
                (4.0, 9.0),
                (30.0, 2.0),
                (12.5, 30.0),
            ] {
                let (u, v) = uv_at(&t, cu, cv);
                let exact = t.box_mean([u, v, -1.0], [ru, rv]).unwrap()[0];
                let gpu = gpu_box_mean(&t, &planes, [u, v, -1.0], [ru, rv])[0];
                let bound = 1e-4 * exact.abs() + 2e-7 * total / (4.0 * ru * rv);
                let err = (gpu - exact).abs();
                worst = worst.max(err / bound);
                assert!(
                    err <= bound,
                    "box ({cu}, {cv}) ± ({ru}, {rv}): {gpu} vs {exact}, bound {bound}"
                );
            }
        }
        eprintln!("worst error / bound: {worst:.3}");
    }
}
