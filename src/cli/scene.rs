//! The scene flags: the scene file and the overrides of its `[output]` table.

use std::path::PathBuf;

use crate::scene::Scene;
use crate::{Error, Result};

/// The scene flags shared by `render` and `view`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct SceneArgs {
    /// Scene file (TOML); the embedded default scene when omitted.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Image width in pixels (overrides the scene; the viewer's window width).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (overrides the scene; the viewer's window height).
    #[arg(long)]
    pub height: Option<u32>,
    /// Exposure (linear multiplier before the sRGB curve): overrides the scene's (the
    /// viewer's first value); for BRDF maps it scales the PNG only (the EXR keeps the raw
    /// values) [default for a map's PNG: chosen from the map, and said].
    #[arg(long, allow_negative_numbers = true)]
    pub exposure: Option<f32>,
}

impl SceneArgs {
    /// The scene (the file, or the embedded default) with the flags applied: an exposure
    /// that is not finite and above zero is refused; the size is checked by the command
    /// (a BRDF map has none).
    pub fn load(&self) -> Result<Scene> {
        let mut scene = match &self.scene {
            Some(p) => Scene::load(p)?,
            None => Scene::default_scene(),
        };
        if let Some(e) = self.exposure {
            use crate::scene::{MAX_EXPOSURE, MIN_EXPOSURE};
            if !(MIN_EXPOSURE..=MAX_EXPOSURE).contains(&e) {
                return Err(Error::invalid(
                    "exposure",
                    format!("{e:e}; expected {MIN_EXPOSURE:e} to {MAX_EXPOSURE:e}"),
                ));
            }
            scene.output.exposure = e;
        }
        if let Some(w) = self.width {
            scene.output.width = w;
        }
        if let Some(h) = self.height {
            scene.output.height = h;
        }
        Ok(scene)
    }
}
