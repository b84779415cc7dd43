//! Error-versus-time profiling of shader variants (MODEL §6–7): every variant renders the
//! same BRDF map on the GPU, is timed with GPU timestamps, and is scored at sampled pixels
//! against the f64 reference (direct sum, 1 nm) and against the f64 model of the same
//! variant, which separates approximation error from float32 and driver error.
//!
//! Metrics per variant (MODEL §6): relative L2 of linear XYZ over the sampled pixels, max
//! |ΔY|, and mean / max CIEDE2000 of the colours after scaling so the brightest reference
//! sample has `Y = 1`.

use std::path::PathBuf;

use crate::brdf::{direction, model, reference};
use crate::colour::{delta_e2000, xyz_to_lab, ColourTable};
use crate::gpu::StorageFormat;
use crate::material::{default_cache_dir, Material, MaterialArgs};
use crate::render::{map_direction, Renderer};
use crate::spectrum::Expansion;
use crate::{Error, Result};

/// One shader variant: the numerical choices of a material plus the term storage format.
#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub name: String,
    pub expansion: Expansion,
    pub terms: usize,
    pub window_radius: usize,
    pub lambda_step_nm: u32,
    pub storage: StorageFormat,
}

impl Variant {
    /// `base` with this variant's numerical choices.
    pub fn material(&self, base: &Material) -> Material {
        Material {
            expansion: self.expansion,
            terms: crate::material::Terms::Fixed(self.terms),
            window_radius: self.window_radius,
            lambda_step_nm: self.lambda_step_nm,
            ..base.clone()
        }
    }
}

/// The standard set: the thesis setting (Taylor, R = 1), the default, larger R, Chebyshev,
/// the compact storage formats, and coarser and finer wavelength steps. `terms` is T of the Taylor
/// variants; Chebyshev gets about two thirds of it (it converges faster, README).
pub fn standard_variants(terms: usize) -> Vec<Variant> {
    let v = |name: &str, expansion, terms, r, step, storage| Variant {
        name: name.to_string(),
        expansion,
        terms,
        window_radius: r,
        lambda_step_nm: step,
        storage,
    };
    let cheb = (2 * terms).div_ceil(3);
    use Expansion::{Chebyshev, Taylor};
    use StorageFormat::{Rg16f, Rg32f, Unorm16};
    vec![
        v("thesis: taylor R=1", Taylor, terms, 1, 5, Rg32f),
        v("taylor R=2", Taylor, terms, 2, 5, Rg32f),
        v("taylor R=3", Taylor, terms, 3, 5, Rg32f),
        v("chebyshev R=2", Chebyshev, cheb, 2, 5, Rg32f),
        v("taylor R=2 rg16f", Taylor, terms, 2, 5, Rg16f),
        v("taylor R=2 unorm16", Taylor, terms, 2, 5, Unorm16),
        v("taylor R=2 10nm", Taylor, terms, 2, 10, Rg32f),
        v("taylor R=2 1nm", Taylor, terms, 2, 1, Rg32f),
    ]
}

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
}

/// Compares `xyz` with `reference` sample by sample.
pub fn error_stats(xyz: &[[f64; 3]], reference: &[[f64; 3]]) -> ErrorStats {
    let y_max = reference.iter().map(|r| r[1]).fold(0.0, f64::max);
    let scale = if y_max > 0.0 { 1.0 / y_max } else { 1.0 };
    let (mut diff2, mut ref2, mut max_abs_y, mut sum_de, mut max_de) = (0.0, 0.0, 0.0, 0.0, 0.0);
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
        sum_de += de;
        max_de = f64::max(max_de, de);
    }
    let n = xyz.len().max(1) as f64;
    ErrorStats {
        rel_l2: if ref2 > 0.0 {
            (diff2 / ref2).sqrt()
        } else {
            diff2.sqrt()
        },
        max_abs_y,
        mean_de: sum_de / n,
        max_de,
    }
}

/// One row of the profile.
#[derive(Debug, Clone, PartialEq)]
pub struct VariantReport {
    pub variant: Variant,
    /// Fastest GPU time over the repeats (ms); `None` where the device has no timestamps.
    pub gpu_ms: Option<f64>,
    /// Fastest wall time of a frame (ms), upload and readback included.
    pub wall_ms: f64,
    /// GPU against the f64 reference.
    pub vs_reference: ErrorStats,
    /// GPU against the f64 model of the same variant (float32 and driver error only).
    pub vs_model: ErrorStats,
}

/// What to profile.
#[derive(Debug, Clone)]
pub struct ProfileSetup {
    pub base: Material,
    pub variants: Vec<Variant>,
    pub theta_i_deg: f64,
    pub phi_i_deg: f64,
    /// BRDF map side in pixels.
    pub size: u32,
    /// Pixels scored: half the brightest of the first variant's map, half spread evenly.
    pub pixels: usize,
    /// Frames per variant; the fastest is reported.
    pub repeats: usize,
    pub cache_dir: Option<PathBuf>,
}

/// Scored pixels and the reference XYZ at each.
type Samples = (Vec<(u32, u32)>, Vec<[f64; 3]>);

/// Pixels to score: the brightest `n/2` of `map` (where the diffraction is) and `n − n/2`
/// spread evenly over the rest of the disk (where errors in dark regions would show).
fn pick_pixels(map: &[[f32; 3]], size: u32, n: usize) -> Vec<(u32, u32)> {
    let mut inside: Vec<(u32, u32, f32)> = (0..size * size)
        .filter_map(|k| {
            let (i, j) = (k % size, k / size);
            map_direction(i, j, size).map(|_| (i, j, map[k as usize][1]))
        })
        .collect();
    inside.sort_by(|a, b| b.2.total_cmp(&a.2));
    let bright = (n / 2).min(inside.len());
    let mut picked: Vec<(u32, u32)> = inside[..bright].iter().map(|p| (p.0, p.1)).collect();
    let rest = &inside[bright..];
    let spread = (n - bright).min(rest.len());
    for s in 0..spread {
        let p = rest[s * rest.len() / spread];
        picked.push((p.0, p.1));
    }
    picked
}

/// Renders and scores every variant. The reference (1 nm, direct sum) is computed once at
/// the sampled pixels, so its cost is `pixels × N² × 401` complex exponentials.
pub fn profile(renderer: &mut Renderer, setup: &ProfileSetup) -> Result<Vec<VariantReport>> {
    if setup.variants.is_empty() {
        return Err(Error::invalid("variants", "none to profile"));
    }
    if setup.pixels == 0 || setup.repeats == 0 {
        return Err(Error::invalid(
            "profile",
            "pixels and repeats must be at least 1",
        ));
    }
    let wi = direction(setup.theta_i_deg, setup.phi_i_deg);
    // ωi as uploaded (float32), so the model sees what the shader saw.
    let wi32 = wi.map(|c| c as f32 as f64);
    let mut reports = Vec::with_capacity(setup.variants.len());
    // Scored pixels and their reference XYZ, fixed by the first variant's map.
    let mut samples: Option<Samples> = None;
    let table_1nm = ColourTable::new(1)?;
    for variant in &setup.variants {
        let material = variant.material(&setup.base);
        let prepared = material.prepare(setup.cache_dir.as_deref())?;
        renderer.set_storage_format(variant.storage);
        let mut best_gpu: Option<f64> = None;
        let mut best_wall = f64::INFINITY;
        let mut frame = None;
        for _ in 0..setup.repeats {
            let f = renderer.render_brdf_map(
                &prepared,
                setup.theta_i_deg,
                setup.phi_i_deg,
                setup.size,
                None,
            )?;
            best_gpu = match (best_gpu, f.gpu_ms) {
                (Some(a), Some(b)) => Some(a.min(b)),
                (a, b) => a.or(b),
            };
            best_wall = best_wall.min(f.wall_ms);
            frame = Some(f);
        }
        let Some(frame) = frame else {
            continue;
        };
        let (pixels, refs) = samples.get_or_insert_with(|| {
            let pixels = pick_pixels(&frame.rgb, setup.size, setup.pixels);
            let refs = pixels
                .iter()
                .map(|&(i, j)| {
                    let wr = map_direction(i, j, setup.size).unwrap_or([0.0, 0.0, 1.0]);
                    reference::xyz(
                        &prepared.heightfield,
                        material.coherence_um,
                        &prepared.shading,
                        &table_1nm,
                        wi,
                        wr,
                    )
                })
                .collect();
            (pixels, refs)
        });
        let gpu: Vec<[f64; 3]> = pixels
            .iter()
            .map(|&(i, j)| frame.at(i, j).map(f64::from))
            .collect();
        let modelled: Vec<[f64; 3]> = pixels
            .iter()
            .map(|&(i, j)| {
                let wr = map_direction(i, j, setup.size).unwrap_or([0.0, 0.0, 1.0]);
                model::xyz(
                    &prepared.stack,
                    prepared.terms(),
                    &prepared.window,
                    &prepared.shading,
                    &prepared.colour,
                    wi32,
                    wr,
                )
            })
            .collect();
        reports.push(VariantReport {
            variant: variant.clone(),
            gpu_ms: best_gpu,
            wall_ms: best_wall,
            vs_reference: error_stats(&gpu, refs),
            vs_model: error_stats(&gpu, &modelled),
        });
    }
    Ok(reports)
}

/// Formats the reports as a Markdown table.
pub fn format_table(device: &str, setup: &ProfileSetup, reports: &[VariantReport]) -> String {
    let mut s = format!(
        "device: {device}; BRDF map {}² at θi = {}°, φi = {}°, {} scored pixels, best of {}; reference: f64 direct sum at 1 nm\n\n",
        setup.size, setup.theta_i_deg, setup.phi_i_deg, setup.pixels, setup.repeats
    );
    s.push_str("| variant | T | GPU ms | wall ms | rel L2 vs ref | max ΔY vs ref | mean ΔE | max ΔE | rel L2 vs f64 model |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|\n");
    for r in reports {
        let gpu = r.gpu_ms.map_or("n/a".into(), |g| format!("{g:.2}"));
        s.push_str(&format!(
            "| {} | {} | {gpu} | {:.1} | {:.2e} | {:.2e} | {:.3} | {:.3} | {:.2e} |\n",
            r.variant.name,
            r.variant.terms,
            r.wall_ms,
            r.vs_reference.rel_l2,
            r.vs_reference.max_abs_y,
            r.vs_reference.mean_de,
            r.vs_reference.max_de,
            r.vs_model.rel_l2
        ));
    }
    s
}

/// `diffract profile` options.
#[derive(Debug, Clone, clap::Args)]
pub struct ProfileArgs {
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Taylor terms T of the standard variants (Chebyshev gets ⌈2T/3⌉).
    #[arg(long = "variant-terms", default_value_t = 30)]
    pub variant_terms: usize,
    /// Polar angle of the light (degrees).
    #[arg(long, default_value_t = 60.0)]
    pub theta_i: f64,
    /// Azimuth of the light (degrees).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub phi_i: f64,
    /// BRDF map side in pixels.
    #[arg(long, default_value_t = 128)]
    pub size: u32,
    /// Pixels scored against the reference (each costs N²·401 complex exponentials).
    #[arg(long, default_value_t = 16)]
    pub pixels: usize,
    /// Frames per variant (the fastest is reported).
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// Also write the table as CSV.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Directory of the DFT-term cache.
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
}

/// Runs `diffract profile`.
pub fn run(args: &ProfileArgs) -> Result<()> {
    if let Some(p) = &args.csv {
        if p.file_name().is_none() {
            return Err(Error::invalid(
                "csv",
                format!("{} is not a file", p.display()),
            ));
        }
    }
    let mut renderer = Renderer::new(crate::render::validation_requested())?;
    let base = args.material.apply(Material::default());
    let setup = ProfileSetup {
        base,
        variants: standard_variants(args.variant_terms),
        theta_i_deg: args.theta_i,
        phi_i_deg: args.phi_i,
        size: args.size,
        pixels: args.pixels,
        repeats: args.repeats,
        cache_dir: args.cache_dir.clone().or_else(default_cache_dir),
    };
    let reports = profile(&mut renderer, &setup)?;
    print!("{}", format_table(renderer.device_name(), &setup, &reports));
    if let Some(path) = &args.csv {
        let mut csv = String::from("variant,expansion,terms,window_radius,lambda_step_nm,storage,gpu_ms,wall_ms,rel_l2_ref,max_abs_y_ref,mean_de_ref,max_de_ref,rel_l2_model\n");
        for r in &reports {
            let v = &r.variant;
            csv.push_str(&format!(
                "{},{},{},{},{},{:?},{},{},{},{},{},{},{}\n",
                v.name,
                v.expansion,
                v.terms,
                v.window_radius,
                v.lambda_step_nm,
                v.storage,
                r.gpu_ms.map_or(String::new(), |g| g.to_string()),
                r.wall_ms,
                r.vs_reference.rel_l2,
                r.vs_reference.max_abs_y,
                r.vs_reference.mean_de,
                r.vs_reference.max_de,
                r.vs_model.rel_l2
            ));
        }
        crate::fsutil::write_atomic(path, csv.as_bytes())?;
    }
    let n = renderer.validation_messages();
    if n > 0 {
        return Err(Error::Validation(n));
    }
    Ok(())
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
}
