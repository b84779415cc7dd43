//! `diffract brdf`: batch BRDF queries from a CSV file ([`crate::brdf::query`] reads and
//! writes the files and answers the rows).

use std::path::PathBuf;

use crate::brdf::query::{answer_all, format_answers, parse_queries, Method};
use crate::brdf::{model, reference};
use crate::cli::cache::CacheArgs;
use crate::cli::material::MaterialArgs;
use crate::colour::ColourTable;
use crate::fsutil::write_atomic;
use crate::Result;

/// `diffract brdf` options.
#[derive(Debug, Clone, clap::Args)]
pub struct BrdfArgs {
    #[command(flatten)]
    pub material: MaterialArgs,
    /// Query CSV (theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,lambda_nm).
    #[arg(long)]
    pub queries: PathBuf,
    /// Result CSV (the query columns plus rho,X,Y,Z).
    #[arg(long)]
    pub out: PathBuf,
    /// Evaluator.
    #[arg(long, value_enum, default_value_t = Method::Model)]
    pub method: Method,
    #[command(flatten)]
    pub cache: CacheArgs,
}

/// Runs `diffract brdf`.
pub fn run(args: &BrdfArgs) -> Result<()> {
    let material = args.material.apply(crate::material::Material::default());
    material.validate()?;
    let mut inputs = crate::guard::heightfield_inputs(&material.heightfield);
    inputs.push(("query CSV", args.queries.clone()));
    crate::fsutil::check_outputs(&inputs, &[("--out", args.out.clone())])?;
    let text =
        crate::fsutil::read_text_bounded(&args.queries, "query CSV", crate::fsutil::MAX_CSV_BYTES)?;
    let queries = parse_queries(&args.queries, &text)?;
    let answers = match args.method {
        Method::Reference => {
            let hf = material.load_heightfield(&crate::report::Stderr)?;
            // MODEL §6.1: 1 nm steps unless a step was asked for explicitly.
            let table = ColourTable::new(args.material.lambda_step_nm.unwrap_or(1))?;
            let shading = material.shading();
            let coh = material.coherence_um;
            answer_all(
                &queries,
                |wi, wr, l| reference::rho(&hf, coh, &shading, wi, wr, l),
                |wi, wr| reference::xyz(&hf, coh, &shading, &table, wi, wr),
            )
        }
        Method::Model => {
            let cache = args.cache.dir();
            // The model runs here in f64: its terms are planned for f64 rounding, not for
            // the shaders' float32 (which a one-row field's narrow window cannot meet).
            let p = material.prepare_for(
                cache.as_deref(),
                &crate::brdf::truncation::Reach::ALL,
                crate::brdf::truncation::Precision::F64,
                &crate::report::Stderr,
            )?;
            let (t, stack) = (p.terms(), p.stack.get()?);
            answer_all(
                &queries,
                |wi, wr, l| model::rho(stack, t, &p.window, &p.shading, wi, wr, l),
                |wi, wr| model::xyz(stack, t, &p.window, &p.shading, &p.colour, wi, wr),
            )
        }
    };
    write_atomic(&args.out, format_answers(&queries, &answers).as_bytes())?;
    eprintln!(
        "{} queries answered by the {:?} evaluator → {}",
        answers.len(),
        args.method,
        args.out.display()
    );
    Ok(())
}
