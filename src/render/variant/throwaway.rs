//! A throwaway variant, registered only in the library's own tests: `volume`'s table and
//! shader under another name, with a CPU model and a float32 mirror of its own that count
//! their calls. Its test shows that a variant's file and its registry line put it in
//! `diffract variants`, in the profiler's rows, in the stability matrix (each time scored
//! against its own model), in the viewer's `V` cycle, and under an environment (its own
//! fragment file compiled into the compute stages, drawing `volume`'s picture).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use super::table::{prepare, Layout, TableLayout, TableTraits};
use super::{
    CpuModel, DrawSetup, Family, FetchInputs, Mirrored, PreparedVariant, Preset, Stability,
    Variant, VariantStats,
};
use crate::brdf::table;
use crate::gpu::Device;
use crate::material::PreparedMaterial;
use crate::Result;

pub(crate) struct Throwaway;

/// Calls of the throwaway's CPU model.
static MODEL_CALLS: AtomicUsize = AtomicUsize::new(0);
/// Evaluations of the throwaway's float32 mirror.
static MIRROR_CALLS: AtomicUsize = AtomicUsize::new(0);

impl Variant for Throwaway {
    fn name(&self) -> &'static str {
        "throwaway"
    }

    fn summary(&self) -> &'static str {
        "a test's variant: volume's table and shader under another name"
    }

    fn family(&self) -> Family {
        Family::Table
    }

    fn fragment(&self) -> &'static str {
        "volume.frag"
    }

    fn table_traits(&self) -> Option<TableTraits> {
        Some(TableTraits {
            w_nodes: 8,
            follows_field: false,
            layout: TableLayout {
                layout: Layout::Volume,
                ghosts: 0,
                fitted: false,
            },
        })
    }

    fn fetches(&self, f: &FetchInputs<'_>) -> usize {
        super::table::fetches(Self::KIND, f)
    }

    fn fetch_formula(&self) -> &'static str {
        "1"
    }

    fn profile_presets(&self) -> &'static [Preset] {
        const ROWS: &[Preset] = &[Preset::named("throwaway")];
        ROWS
    }

    fn stability(&self) -> Stability {
        Stability::Table(|hf, coherence_um, spec, _| {
            let v = table::Volume::build(hf, coherence_um, spec, &|| ())?;
            Ok(Mirrored::Eval(Box::new(move |t, w| {
                MIRROR_CALLS.fetch_add(1, Ordering::Relaxed);
                super::volume::g_f32(&v, t, w)
            })))
        })
    }

    fn prepare(
        &self,
        dev: &Arc<Device>,
        setup: &DrawSetup<'_>,
    ) -> Result<Box<dyn PreparedVariant>> {
        let inner = prepare(
            Self::KIND,
            dev,
            setup,
            Layout::Volume,
            table::Volume::nodes,
            |r, s| Ok((table::Volume::from_slices(r, s), None)),
        )?;
        Ok(Box::new(ThrowawayGpu(inner)))
    }
}

struct ThrowawayGpu(Box<dyn PreparedVariant>);

impl PreparedVariant for ThrowawayGpu {
    fn base(&self) -> Option<&dyn PreparedVariant> {
        Some(&*self.0)
    }

    fn stats(&self) -> VariantStats {
        self.0.stats()
    }

    fn model(&self) -> Option<&dyn CpuModel> {
        self.0.model().map(|_| self as &dyn CpuModel)
    }
}

impl CpuModel for ThrowawayGpu {
    fn xyz(
        &self,
        prepared: &PreparedMaterial,
        colour: &crate::colour::ColourTable,
        wi: [f64; 3],
        wr: [f64; 3],
    ) -> Result<[f64; 3]> {
        MODEL_CALLS.fetch_add(1, Ordering::Relaxed);
        self.0
            .model()
            .map_or(Ok([f64::NAN; 3]), |m| m.xyz(prepared, colour, wi, wr))
    }

    fn table(&self) -> Option<&dyn table::GTable> {
        self.0.model()?.table()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::VariantKind;

    #[test]
    fn a_new_variant_is_listed_profiled_and_in_the_stability_matrix_against_its_own_model() {
        let kind = VariantKind::Throwaway;
        assert_eq!(VariantKind::named("throwaway"), Some(kind));
        assert!(super::super::list().contains("throwaway"));
        assert!(super::super::markdown_table().contains("| `throwaway` |"));

        // The stability matrix's table cases evaluate its own float32 mirror.
        let (field, period) = crate::stability::default_field().unwrap();
        let mut spec = crate::stability::MatrixSpec::full(field, "sinusoid", Some(period));
        spec.h_max_um = vec![0.25];
        let before = MIRROR_CALLS.load(Ordering::Relaxed);
        let cells = crate::stability::run_table_cases(&spec).unwrap();
        let mine: Vec<_> = cells.iter().filter(|c| c.variant == kind).collect();
        assert_eq!(mine.len(), crate::stability::TABLE_CASES.len());
        assert!(mine
            .iter()
            .all(|c| c.status == crate::stability::Status::Pass));
        assert!(MIRROR_CALLS.load(Ordering::Relaxed) > before);
        let md = crate::stability::table_cases_markdown(&spec, &cells);
        assert!(md.contains(" throwaway |"), "{md}");

        // The profiler has its row, and scores its map against its own model.
        let mut rows: Vec<_> = crate::profile::standard_variants(4)
            .into_iter()
            .filter(|r| r.kind == kind)
            .collect();
        assert_eq!(rows.len(), 1);
        rows[0].table.texel_uv = Some(0.05);
        rows[0].table.step_nm = Some(20);
        let mut renderer = match crate::render::Renderer::new(true) {
            Ok(r) => r,
            Err(e) if std::env::var_os("DIFFRACT_REQUIRE_VULKAN").is_none() => {
                eprintln!("no Vulkan ({e}): the profile half is not run");
                return;
            }
            Err(e) => panic!("{e}"),
        };
        let setup = crate::profile::ProfileSetup {
            base: crate::material::Material {
                heightfield: "builtin:sinusoidal".into(),
                ..Default::default()
            },
            variants: rows,
            theta_i_deg: 30.0,
            phi_i_deg: 0.0,
            size: 15,
            pixels: 4,
            brightest: 4,
            frames: crate::profile::Frames::Fixed(1),
            mesh: None,
            per_vertex: false,
            cache_dir: None,
        };
        let before = MODEL_CALLS.load(Ordering::Relaxed);
        let run = crate::profile::profile(&mut renderer, &setup).unwrap();
        assert_eq!(renderer.validation_messages(), 0);
        assert!(run.skipped.is_empty(), "{:?}", run.skipped);
        let r = &run.reports[0];
        assert_eq!(r.variant.kind, kind);
        assert!(MODEL_CALLS.load(Ordering::Relaxed) >= before + 8);
        assert!(r.vs_model.rel_l2 < 1e-4, "{:?}", r.vs_model);

        // The viewer's `V` reaches it.
        let state =
            crate::view::input::ViewState::from_scene(&crate::scene::Scene::default_scene());
        let mut controls = crate::view::input::Controls::new(state, VariantKind::Flss);
        let v = winit::keyboard::Key::Character("v".into());
        let reached = (0..VariantKind::ALL.len()).any(|_| {
            controls.key(&v);
            controls.variant == kind
        });
        assert!(reached, "V never shows {kind}");

        // Under an environment it draws `volume`'s picture: the same table and shader, built
        // for the compute stages from its own registry entry.
        let hf = crate::heightfield::HeightField::new(64, 64, 0.09, vec![0.0; 64 * 64]).unwrap();
        let shading = crate::brdf::Shading::default();
        let spec = table::TableSpec {
            region: table::Region {
                lo: [-0.04, -0.04, -2.0],
                hi: [0.04, 0.04, -0.01],
            },
            texel_uv: 0.002,
            w_nodes: 4,
            step_nm: 20,
            response: table::Response::Relative,
        };
        let lighting = crate::render::env::EnvLighting::build(&hf, 65.0, &shading, &spec).unwrap();
        let material = crate::material::Material {
            lambda_step_nm: 20,
            ..Default::default()
        };
        let prepared = material
            .prepare_anywhere(hf, None, &crate::report::Stderr)
            .unwrap();
        let sky =
            crate::light::env::EnvMap::load(&crate::light::env::EnvSource::Sky, 1.0, 0.0).unwrap();
        let mut draw = |k: VariantKind| {
            renderer.set_variant(k);
            let brdf = renderer.env_brdf(&prepared, &lighting, &shading).unwrap();
            crate::render::env::render_env_brdf_map(
                renderer.device(),
                &lighting,
                &crate::render::env::EnvMapRequest {
                    env: &sky,
                    shading,
                    samples: 64,
                    size: 9,
                    sun: None,
                    seed: 0,
                    brdf: Some(&brdf),
                    per_dispatch: None,
                },
            )
            .unwrap()
            .xyz
        };
        let (mine, volume) = (draw(kind), draw(VariantKind::Volume));
        assert_eq!(renderer.validation_messages(), 0);
        assert!(mine.iter().any(|p| p[1] > 0.0), "an all-black map");
        assert_eq!(
            mine, volume,
            "the throwaway under the sky is volume's picture"
        );
    }
}
