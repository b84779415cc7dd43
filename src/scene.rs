//! Scene files (TOML): camera, directional light, mesh and its placement, the diffraction
//! [`Material`], output size/exposure and optional texture blending. This module parses and
//! validates them, resolves relative paths against the scene file's directory and turns the
//! camera and mesh placement into matrices. It renders nothing.
//!
//! Every section and key is optional; missing ones take the values of the embedded default
//! scene (`assets/default_scene.toml`, which lists every key with a comment). Unknown keys
//! are errors, and every error names the file (and, for syntax and type errors, the line).

use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

use crate::image_io::{apply_tone, box_downsample, Tone, DEFAULT_TONE_WHITE};
use crate::light::area::{validate_disc_lights, DiscLight, EnvironmentSpec};
use crate::light::{MAX_ANGULAR_DIAMETER_DEG, MAX_DISK_SAMPLES};
use crate::material::Material;
use crate::mesh::Mesh;
use crate::skin::{elaphe_skin, ELAPHE_SKIN_BUILTIN, ELAPHE_SKIN_SIZE};
use crate::{Error, Result};

/// The embedded default scene (also the reference for every key's default).
pub const DEFAULT_SCENE_TOML: &str = include_str!("../assets/default_scene.toml");

/// A pinhole camera looking from `eye` at `target`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Camera {
    pub eye: [f32; 3],
    pub target: [f32; 3],
    pub up: [f32; 3],
    /// Vertical field of view in degrees, in (0, 180).
    pub fov_y_deg: f32,
    pub near: f32,
    pub far: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Self {
            eye: [0.0, 2.6, 2.6],
            target: [0.0, 0.05, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 35.0,
            near: 0.01,
            far: 100.0,
        }
    }
}

impl Camera {
    /// World → view matrix (right-handed, looking down −z).
    pub fn view(&self) -> Mat4 {
        Mat4::look_at_rh(self.eye.into(), self.target.into(), self.up.into())
    }

    /// View → Vulkan clip space: right-handed perspective with depth in [0, 1] and clip-space
    /// `y` pointing down (glam's `perspective_rh` with `y` negated).
    pub fn projection(&self, aspect: f32) -> Mat4 {
        let p = Mat4::perspective_rh(self.fov_y_deg.to_radians(), aspect, self.near, self.far);
        Mat4::from_scale(Vec3::new(1.0, -1.0, 1.0)) * p
    }

    /// World → Vulkan clip space (`projection · view`) for a `width / height` aspect ratio.
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        self.projection(aspect) * self.view()
    }

    /// Eye position as a vector.
    pub fn eye(&self) -> Vec3 {
        self.eye.into()
    }
}

/// A directional light.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Light {
    /// The direction the light travels, in world space (need not be normalised).
    pub direction: [f32; 3],
    /// Radiance scale (≥ 0).
    pub intensity: f32,
    /// Angular diameter of the light's disc in degrees, 0..=20 (the sun: 0.53; 0: a point).
    pub angular_diameter_deg: f32,
    /// Directions the disc is integrated over ([`crate::light::sun_disk_samples`]), 1..=256.
    pub disk_samples: u32,
}

/// The sun's angular diameter seen from the Earth (degrees).
pub const SUN_ANGULAR_DIAMETER_DEG: f32 = 0.53;

/// Default number of directions over the sun's disc.
pub const DEFAULT_DISK_SAMPLES: u32 = 8;

impl Default for Light {
    fn default() -> Self {
        Self {
            direction: [0.25, -0.45, 1.0],
            intensity: 1.0,
            angular_diameter_deg: SUN_ANGULAR_DIAMETER_DEG,
            disk_samples: DEFAULT_DISK_SAMPLES,
        }
    }
}

impl Light {
    /// `ωi` in world space: the unit vector from a surface point towards the light,
    /// `−normalize(direction)`.
    pub fn towards_light(&self) -> Vec3 {
        -Vec3::from(self.direction).normalize_or_zero()
    }

    /// The directions `ωi` (world space) over the light's disc with their weights (summing
    /// to 1): what a renderer sums the diffraction term over instead of [`Self::towards_light`]
    /// alone. One direction when the diameter is 0 or `disk_samples` is 1.
    pub fn disk_samples(&self) -> Vec<crate::light::DiskSample> {
        crate::light::sun_disk_samples(
            self.towards_light().to_array(),
            self.angular_diameter_deg,
            self.disk_samples,
        )
    }
}

/// Which mesh to draw and where. A `[mesh]` section gives exactly one of `path` and
/// `builtin`; without a `[mesh]` section the built-in snake is used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshSpec {
    /// OBJ file (made absolute against the scene file's directory on load).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<PathBuf>,
    /// `snake`, `sphere` or `plane` ([`Mesh::builtin`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub builtin: Option<String>,
    #[serde(default)]
    pub translate: [f32; 3],
    /// Euler angles in degrees, applied about world `x`, then `y`, then `z`.
    #[serde(default)]
    pub rotate_deg: [f32; 3],
    /// Uniform scale (> 0).
    #[serde(default = "one")]
    pub scale: f32,
    /// Flat skin scales ([`Mesh::scales`]) rolled about the bitangent by up to this many
    /// degrees. With both scale angles 0 the mesh keeps smooth shading.
    #[serde(default)]
    pub scale_roll_deg: f32,
    /// Flat skin scales pitched about the tangent by up to this many degrees.
    #[serde(default)]
    pub scale_pitch_deg: f32,
    /// `scaly-snake` only: quads along each side of a scale (1..=32, default 6): the mesh
    /// resolution that per-vertex evaluation (thesis §1.5.1) depends on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_quads: Option<u32>,
}

fn one() -> f32 {
    1.0
}

impl Default for MeshSpec {
    fn default() -> Self {
        Self {
            path: None,
            builtin: Some("snake".into()),
            translate: [0.0; 3],
            rotate_deg: [0.0; 3],
            scale: 1.0,
            scale_roll_deg: 0.0,
            scale_pitch_deg: 0.0,
            scale_quads: None,
        }
    }
}

impl MeshSpec {
    /// Object → world matrix: `translate · Rz · Ry · Rx · scale`.
    pub fn model_matrix(&self) -> Mat4 {
        let [rx, ry, rz] = self.rotate_deg.map(f32::to_radians);
        Mat4::from_translation(self.translate.into())
            * Mat4::from_rotation_z(rz)
            * Mat4::from_rotation_y(ry)
            * Mat4::from_rotation_x(rx)
            * Mat4::from_scale(Vec3::splat(self.scale))
    }

    /// The mesh in object space (no transform applied).
    pub fn load_untransformed(&self) -> Result<Mesh> {
        match (&self.path, &self.builtin) {
            (Some(p), None) => Mesh::load_obj(p),
            (None, Some(b)) if b == "scaly-snake" && self.scale_quads.is_some() => Ok(
                Mesh::scaly_snake_with(2.0, 0.08, 64, 18, self.scale_quads.unwrap_or(6)),
            ),
            (None, Some(b)) => Mesh::builtin(b).ok_or_else(|| {
                Error::invalid(
                    "mesh",
                    format!(
                        "unknown builtin `{b}`; expected one of {}",
                        Mesh::BUILTIN_NAMES.join(", ")
                    ),
                )
            }),
            _ => Err(Error::invalid(
                "mesh",
                "give exactly one of `path` and `builtin`",
            )),
        }
    }

    /// The mesh in **world space**: [`Self::model_matrix`] is already applied to positions,
    /// normals and tangents, so draw it with an identity model matrix.
    pub fn load(&self) -> Result<Mesh> {
        let mut mesh = self.load_untransformed()?;
        if self.scale_roll_deg > 0.0 || self.scale_pitch_deg > 0.0 {
            mesh = mesh.scales(self.scale_roll_deg, self.scale_pitch_deg, 1);
        }
        mesh.transform(self.model_matrix());
        Ok(mesh)
    }
}

/// Smallest exposure a scene or `--exposure` takes.
pub const MIN_EXPOSURE: f32 = 1e-6;
/// Largest exposure: a mirror's specular peak (~1e3 on the maps) times this still fits
/// float32 with room to spare, and no scene needs more than a few hundred.
pub const MAX_EXPOSURE: f32 = 1e6;

/// Image size, exposure and background.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Output {
    /// Pixels, 1..=8192.
    pub width: u32,
    /// Pixels, 1..=8192.
    pub height: u32,
    /// Linear multiplier applied before the sRGB curve (> 0).
    pub exposure: f32,
    /// Linear sRGB colour where no surface is hit.
    pub background: [f32; 3],
    /// Anti-aliasing: render `supersample²` samples per pixel (a frame `supersample` times
    /// the size) and box-filter it down ([`crate::image_io::box_downsample`]), 1..=4.
    pub supersample: u32,
    /// Tone curve after the exposure, before the sRGB curve of a PNG (EXR stays linear).
    pub tone: Tone,
    /// White point of the `filmic` tone curve: the linear value (after exposure) shown as 1.
    pub white: f32,
}

impl Default for Output {
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            exposure: 1.0,
            background: [0.02, 0.02, 0.02],
            supersample: 1,
            tone: Tone::Linear,
            white: DEFAULT_TONE_WHITE,
        }
    }
}

/// Largest `[output] supersample`: 16 samples a pixel; an 8192² frame at 4× is already a
/// 32768² render target.
pub const MAX_SUPERSAMPLE: u32 = 4;

impl Output {
    /// `width / height`.
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// Size of the frame to render before [`Self::resolve`]: `supersample` times the output.
    pub fn render_size(&self) -> (u32, u32) {
        (
            self.width * self.supersample.max(1),
            self.height * self.supersample.max(1),
        )
    }

    /// A rendered linear frame of [`Self::render_size`] → the output-sized frame: box
    /// downsampling, then the exposure and the tone curve. What is left is what
    /// `write_png_srgb(…, exposure = 1)` encodes. (For EXR, stop after the downsampling.)
    pub fn resolve(&self, rendered: &[[f32; 3]]) -> Result<Vec<[f32; 3]>> {
        let (w, h) = self.render_size();
        let (_, _, mut px) = box_downsample(w, h, rendered, self.supersample.max(1))?;
        apply_tone(&mut px, self.exposure, self.tone, self.white)?;
        Ok(px)
    }
}

/// Texture blending (thesis Algorithm 4): the texture colour is mixed with the diffraction
/// colour, `c = (1 − w_diffuse)·c_diffraction + (1 − α)·c_texture + w_diffuse·c_texture`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TextureSpec {
    /// sRGB PNG looked up by the mesh UVs (made absolute against the scene file's directory),
    /// or `builtin:elaphe-skin` ([`crate::skin`]).
    pub path: PathBuf,
    /// Weight of the diffuse texture part, in [0, 1].
    #[serde(default = "default_w_diffuse")]
    pub w_diffuse: f32,
    /// The ambient sky: a uniform environment whose irradiance on a surface facing up is
    /// this times the light's intensity ([`crate::light::sky`]), so the skin turned away
    /// from the sun is dim rather than black. 0..=1; 0 is the thesis (the sun alone). An
    /// `--env` map takes its place.
    #[serde(default)]
    pub ambient: f32,
    /// Linear multiplier of the texture colour, > 0 (1: the thesis). The diffraction colour
    /// is relative to a mirror's specular peak, the texture an albedo: in sunlight a first
    /// order at 1/300 of the mirror is still ~1000× brighter than diffuse skin, which is why
    /// the iridescence is striking. With the exposure set for the diffraction colours, a
    /// gain ≪ 1 puts the skin back at a visible level.
    #[serde(default = "one")]
    pub gain: f32,
}

fn default_w_diffuse() -> f32 {
    0.3
}

impl TextureSpec {
    /// The sun's part of one pixel's colour (linear sRGB, before exposure), the CPU
    /// statement of what the fragment shader computes with a texture:
    /// `intensity · max(cos θi, 0) · Algorithm4(c_diffraction, t, F)` with
    /// `t = gain · c_texture` and Algorithm 4 `= (1 − w_d)·c_diffraction + (1 − α)·t + w_d·t`,
    /// `α = min(1, |F|)`, `F` the Schlick reflectance at the half vector. With a finite
    /// light, `c_diffraction` is the weighted sum over [`Light::disk_samples`]. The pixel
    /// is this plus [`TextureSpec::sky`].
    pub fn shade(
        &self,
        c_diffraction: [f32; 3],
        c_texture: [f32; 3],
        fresnel_f: f32,
        cos_theta_i: f32,
        intensity: f32,
    ) -> [f32; 3] {
        let alpha = fresnel_f.abs().min(1.0);
        let lit = intensity * cos_theta_i.max(0.0);
        let w = self.w_diffuse;
        [0, 1, 2].map(|c| {
            let tex = self.gain * c_texture[c];
            let blend = (1.0 - w) * c_diffraction[c] + (1.0 - alpha) * tex + w * tex;
            lit * blend
        })
    }

    /// The ambient sky's part of one pixel's colour (linear sRGB, before exposure) towards
    /// `cos θr`, under a light of `intensity`, in a picture of radiance over `scale`
    /// ([`crate::brdf::table::Response::scale`]): [`crate::light::sky::UniformSky`] with
    /// this texture's `gain`, `w_diffuse` and `ambient`; `fresnel`: Schlick's `R0` and
    /// whether the BRDF has Fresnel on.
    pub fn sky(
        &self,
        c_texture: [f32; 3],
        cos_theta_r: f32,
        intensity: f32,
        fresnel: (f64, bool),
        scale: f64,
    ) -> [f32; 3] {
        let sky = crate::light::sky::UniformSky::of_ambient(
            f64::from(self.ambient),
            f64::from(intensity),
        );
        let t = c_texture.map(|c| f64::from(self.gain * c));
        let w = f64::from(self.w_diffuse);
        sky.reflected(f64::from(cos_theta_r), t, w, fresnel, scale)
            .map(|c| c as f32)
    }

    /// Whether the texture is generated (`builtin:elaphe-skin`), not read from a file.
    pub fn is_builtin(&self) -> bool {
        self.path.as_os_str() == ELAPHE_SKIN_BUILTIN
    }

    /// Reads the texture: `(width, height, sRGB-encoded RGB bytes)`, top row first.
    /// `builtin:elaphe-skin` is the procedural corn-snake skin ([`crate::skin`]), made once
    /// a process (the viewer loads it for the scene and again for each pass).
    pub fn load(&self) -> Result<(u32, u32, Vec<[u8; 3]>)> {
        if self.is_builtin() {
            static SKIN: std::sync::OnceLock<Vec<[u8; 3]>> = std::sync::OnceLock::new();
            let (w, h) = ELAPHE_SKIN_SIZE;
            return Ok((w, h, SKIN.get_or_init(|| elaphe_skin(w, h)).clone()));
        }
        crate::image_io::read_png_rgb8(&self.path)
    }
}

/// A complete scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    #[serde(default)]
    pub camera: Camera,
    #[serde(default)]
    pub light: Light,
    #[serde(default)]
    pub mesh: MeshSpec,
    #[serde(default)]
    pub material: Material,
    #[serde(default)]
    pub output: Output,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<TextureSpec>,
    /// An environment map around the scene (`[environment]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub environment: Option<EnvironmentSpec>,
    /// Disc lights besides the sun (`[[disc_light]]` tables).
    #[serde(default, rename = "disc_light", skip_serializing_if = "Vec::is_empty")]
    pub disc_lights: Vec<DiscLight>,
}

impl Default for Scene {
    /// The embedded default scene ([`Scene::default_scene`]).
    fn default() -> Self {
        Self::default_scene()
    }
}

/// 1-based line and column of a byte offset.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = text.get(..offset).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// Where a semantic error (a message starting `[section] ...`) points in the scene text: the
/// key of that section the message names (`fov_y_deg`, or `coherence` for `coherence_um`),
/// else the section header. `None` when the section is not in the text (a default).
fn locate_semantic(text: &str, msg: &str) -> Option<usize> {
    let rest = msg.strip_prefix('[')?;
    let (section, rest) = rest.split_once(']')?;
    let doc = toml_edit::ImDocument::parse(text).ok()?;
    let item = doc.as_table().get(section)?;
    let table = item.as_table_like()?;
    let words: Vec<&str> = rest
        .split(|c: char| !(c.is_alphanumeric() || c == '_'))
        .filter(|w| !w.is_empty())
        .collect();
    // The first word of the message that is a key, or the first part of one.
    let key = words.iter().find_map(|w| {
        table
            .iter()
            .map(|(k, _)| k)
            .find(|k| k == w || k.split('_').next() == Some(w))
    });
    let key_span = key.and_then(|k| {
        let (key, value) = table.get_key_value(k)?;
        key.span().or_else(|| value.span())
    });
    key_span
        .or_else(|| doc.as_table().get_key_value(section)?.0.span())
        .or_else(|| item.span())
        .map(|r| r.start)
}

impl Scene {
    /// Parses the embedded `assets/default_scene.toml`. It is part of the build and covered
    /// by tests, so it cannot fail at run time; should it ever, the hard-coded section
    /// defaults (which the tests keep identical to it) are used.
    pub fn default_scene() -> Scene {
        Self::from_toml_str(DEFAULT_SCENE_TOML, Path::new("assets/default_scene.toml"))
            .unwrap_or_else(|_| Scene {
                camera: Camera::default(),
                light: Light::default(),
                mesh: MeshSpec::default(),
                material: Material::default(),
                output: Output::default(),
                texture: None,
                environment: None,
                disc_lights: Vec::new(),
            })
    }

    /// Reads and validates a scene file.
    pub fn load(path: &Path) -> Result<Scene> {
        let text = crate::fsutil::read_text_bounded(path, "scene", crate::fsutil::MAX_TOML_BYTES)?;
        Self::from_toml_str(&text, path)
    }

    /// Parses and validates scene text. `origin` is the scene file's path: it names the file
    /// in errors, and relative mesh, texture and height-field paths are resolved against its
    /// directory.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Scene> {
        let mut scene: Scene = toml::from_str(text).map_err(|e| {
            let msg = match e.span() {
                Some(span) => {
                    let (line, col) = line_col(text, span.start);
                    let msg = e.message().trim().replace('\n', "; ");
                    format!("line {line}, column {col}: {msg}")
                }
                // Without a span the full report is the best there is; keep it on one line.
                None => e
                    .to_string()
                    .split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" "),
            };
            Error::parse(origin, msg)
        })?;
        let base = origin.parent().unwrap_or(Path::new(""));
        if let Some(p) = &scene.mesh.path {
            scene.mesh.path = Some(base.join(p));
        }
        if let Some(t) = &mut scene.texture {
            if t.path.as_os_str() != ELAPHE_SKIN_BUILTIN {
                t.path = base.join(&t.path);
            }
        }
        if let Some(e) = &mut scene.environment {
            if !e.map.starts_with(crate::light::env::BUILTIN_PREFIX)
                && Path::new(&e.map).is_relative()
            {
                e.map = base.join(&e.map).to_string_lossy().into_owned();
            }
        }
        let hf = &scene.material.heightfield;
        if !hf.starts_with("builtin:") && !hf.is_empty() && Path::new(hf).is_relative() {
            scene.material.heightfield = base.join(hf).to_string_lossy().into_owned();
        }
        scene.validate().map_err(|msg| {
            let msg = match locate_semantic(text, &msg) {
                Some(offset) => {
                    let (line, col) = line_col(text, offset);
                    format!("line {line}, column {col}: {msg}")
                }
                None => msg,
            };
            Error::parse(origin, msg)
        })?;
        Ok(scene)
    }

    /// Object → world matrix of the mesh ([`MeshSpec::model_matrix`]).
    pub fn model_matrix(&self) -> Mat4 {
        self.mesh.model_matrix()
    }

    /// Semantic checks, section by section; the message names the section and key.
    fn validate(&self) -> std::result::Result<(), String> {
        self.validate_camera()?;
        self.validate_light()?;
        validate_disc_lights(&self.disc_lights)?;
        if let Some(e) = &self.environment {
            e.validate()?;
        }
        self.validate_mesh()?;
        self.validate_output()?;
        if let Some(t) = &self.texture {
            validate_texture(t)?;
        }
        if self.material.heightfield.is_empty() {
            return Err("[material] heightfield is empty".into());
        }
        self.material
            .validate()
            .map_err(|e| format!("[material] {e}"))
    }

    /// `[camera]`: finite vectors, a field of view and clip planes that make sense, and an
    /// up direction not along the view.
    fn validate_camera(&self) -> std::result::Result<(), String> {
        let c = &self.camera;
        finite3("[camera] eye", c.eye)?;
        finite3("[camera] target", c.target)?;
        finite3("[camera] up", c.up)?;
        if !(c.fov_y_deg.is_finite() && c.fov_y_deg > 0.0 && c.fov_y_deg < 180.0) {
            return Err(format!(
                "[camera] fov_y_deg = {}: must be between 0 and 180 degrees (exclusive)",
                c.fov_y_deg
            ));
        }
        positive("[camera] near", c.near)?;
        positive("[camera] far", c.far)?;
        if c.far <= c.near {
            return Err(format!(
                "[camera] far = {} must be greater than near = {}",
                c.far, c.near
            ));
        }
        let view = Vec3::from(c.target) - Vec3::from(c.eye);
        let Some(view) = view.try_normalize() else {
            return Err("[camera] eye and target are the same point".into());
        };
        let Some(up) = Vec3::from(c.up).try_normalize() else {
            return Err("[camera] up is the zero vector".into());
        };
        if view.cross(up).length() < 1e-3 {
            return Err(format!(
                "[camera] up = {:?} is parallel to the view direction (target − eye)",
                c.up
            ));
        }
        Ok(())
    }

    /// `[light]`: a direction, a non-negative intensity and the sun's disc within bounds.
    fn validate_light(&self) -> std::result::Result<(), String> {
        let l = &self.light;
        finite3("[light] direction", l.direction)?;
        if Vec3::from(l.direction).try_normalize().is_none() {
            return Err("[light] direction is the zero vector".into());
        }
        if !(l.intensity.is_finite() && l.intensity >= 0.0) {
            return Err(format!(
                "[light] intensity = {}: must be finite and ≥ 0",
                l.intensity
            ));
        }
        crate::light::check_radiometric("[light] intensity", f64::from(l.intensity))?;
        let sun = crate::light::area::DiscLight {
            angular_diameter_deg: l.angular_diameter_deg,
            ..Default::default()
        };
        if sun.solid_angle() > 0.0 {
            crate::light::check_radiometric(
                "[light] radiance (intensity / the disc's solid angle)",
                f64::from(l.intensity) / sun.solid_angle(),
            )?;
        }
        if !(0.0..=MAX_ANGULAR_DIAMETER_DEG).contains(&l.angular_diameter_deg) {
            return Err(format!(
                "[light] angular_diameter_deg = {}: expected 0 to {MAX_ANGULAR_DIAMETER_DEG} \
                 degrees (the sun: 0.53)",
                l.angular_diameter_deg
            ));
        }
        if !(1..=MAX_DISK_SAMPLES).contains(&l.disk_samples) {
            return Err(format!(
                "[light] disk_samples = {}: expected 1 to {MAX_DISK_SAMPLES}",
                l.disk_samples
            ));
        }
        Ok(())
    }

    /// `[mesh]`: one source, and its placement and scales within bounds.
    fn validate_mesh(&self) -> std::result::Result<(), String> {
        let m = &self.mesh;
        match (&m.path, &m.builtin) {
            (Some(_), Some(_)) => {
                return Err("[mesh] give either `path` or `builtin`, not both".into())
            }
            (None, None) => return Err("[mesh] needs `path` or `builtin`".into()),
            (None, Some(b)) if !Mesh::BUILTIN_NAMES.contains(&b.as_str()) => {
                return Err(format!(
                    "[mesh] builtin = \"{b}\": expected one of {}",
                    Mesh::BUILTIN_NAMES.join(", ")
                ))
            }
            _ => {}
        }
        if let Some(q) = m.scale_quads {
            if m.builtin.as_deref() != Some("scaly-snake") {
                return Err("[mesh] scale_quads applies to builtin = \"scaly-snake\" only".into());
            }
            if !(1..=32).contains(&q) {
                return Err(format!("[mesh] scale_quads = {q}: expected 1 to 32"));
            }
        }
        finite3("[mesh] translate", m.translate)?;
        finite3("[mesh] rotate_deg", m.rotate_deg)?;
        positive("[mesh] scale", m.scale)?;
        for (name, a) in [
            ("scale_roll_deg", m.scale_roll_deg),
            ("scale_pitch_deg", m.scale_pitch_deg),
        ] {
            if !(0.0..=45.0).contains(&a) {
                return Err(format!("[mesh] {name} = {a}: expected 0 to 45 degrees"));
            }
        }
        Ok(())
    }

    /// `[output]`: the image size, exposure, background, supersampling and white point.
    fn validate_output(&self) -> std::result::Result<(), String> {
        let o = &self.output;
        for (what, v) in [("width", o.width), ("height", o.height)] {
            if !(1..=8192).contains(&v) {
                return Err(format!("[output] {what} = {v}: must be 1..=8192 pixels"));
            }
        }
        if !(MIN_EXPOSURE..=MAX_EXPOSURE).contains(&o.exposure) {
            return Err(format!(
                "[output] exposure = {}: expected {MIN_EXPOSURE:e} to {MAX_EXPOSURE:e}",
                o.exposure
            ));
        }
        finite3("[output] background", o.background)?;
        if o.background.iter().any(|&c| c < 0.0) {
            return Err(format!(
                "[output] background = {:?}: must not be negative",
                o.background
            ));
        }
        if !(1..=MAX_SUPERSAMPLE).contains(&o.supersample) {
            return Err(format!(
                "[output] supersample = {}: expected 1 to {MAX_SUPERSAMPLE} (samples per pixel \
                 = its square)",
                o.supersample
            ));
        }
        positive("[output] white", o.white)?;
        Ok(())
    }
}

/// `[texture]`: a path, and weights within bounds.
fn validate_texture(t: &TextureSpec) -> std::result::Result<(), String> {
    if t.path.as_os_str().is_empty() {
        return Err("[texture] path is empty".into());
    }
    if !(t.w_diffuse.is_finite() && (0.0..=1.0).contains(&t.w_diffuse)) {
        return Err(format!(
            "[texture] w_diffuse = {}: must be in [0, 1]",
            t.w_diffuse
        ));
    }
    positive("[texture] gain", t.gain)?;
    if !(0.0..=1.0).contains(&t.ambient) {
        return Err(format!(
            "[texture] ambient = {}: must be in [0, 1]",
            t.ambient
        ));
    }
    Ok(())
}

/// `Err` naming `what` unless every component of `v` is finite.
fn finite3(what: &str, v: [f32; 3]) -> std::result::Result<(), String> {
    if v.iter().all(|c| c.is_finite()) {
        Ok(())
    } else {
        Err(format!("{what} = {v:?}: all components must be finite"))
    }
}

/// `Err` naming `what` unless `x` is positive and finite.
fn positive(what: &str, x: f32) -> std::result::Result<(), String> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(format!("{what} = {x}: must be positive and finite"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_default_parses_and_keeps_general_section_defaults() {
        let parsed = Scene::from_toml_str(DEFAULT_SCENE_TOML, Path::new("x/default.toml"))
            .expect("embedded default scene");
        assert_eq!(Scene::default(), parsed);
        // The default scene sets up its own close-up (see the file); a scene that leaves a
        // section out gets general-purpose defaults instead.
        let empty = Scene::from_toml_str("", Path::new("e.toml")).unwrap();
        assert_eq!(empty.camera, Camera::default());
        assert_eq!(empty.light, Light::default());
        assert_eq!(empty.mesh, MeshSpec::default());
        assert_eq!(empty.output, Output::default());
        assert_eq!(empty.texture, None);
        assert_eq!(parsed.mesh.builtin.as_deref(), Some("scaly-snake"));
        assert_eq!(parsed.material.heightfield, "builtin:elaphe-grown");
        assert_eq!(
            parsed.material,
            Material {
                heightfield: "builtin:elaphe-grown".into(),
                ..Material::default()
            }
        );
        let t = parsed.texture.as_ref().expect("[texture]");
        assert_eq!(
            t.path,
            Path::new(ELAPHE_SKIN_BUILTIN),
            "builtins are not paths"
        );
        assert_eq!(
            parsed.output,
            Output {
                exposure: 400.0,
                supersample: 3,
                tone: Tone::Filmic,
                ..Output::default()
            }
        );
        assert_eq!(
            (parsed.light.angular_diameter_deg, parsed.light.disk_samples),
            (SUN_ANGULAR_DIAMETER_DEG, DEFAULT_DISK_SAMPLES)
        );
        // Light and camera in one plane across the body (x = const): ωi + ωr has no
        // component along the trunk, so u ≈ 0 on it and the colours come from v.
        let wi = parsed.light.towards_light();
        let wr = (parsed.camera.eye() - Vec3::from(parsed.camera.target)).normalize();
        assert!((wi + wr).x.abs() < 1e-6);
    }

    #[test]
    fn new_keys_are_validated() {
        for (text, key) in [
            ("[output]\nsupersample = 0", "supersample"),
            ("[output]\nsupersample = 5", "supersample"),
            ("[output]\nwhite = 0.0", "white"),
            ("[output]\ntone = \"aces\"", "aces"),
            (
                "[light]\nangular_diameter_deg = -1.0",
                "angular_diameter_deg",
            ),
            (
                "[light]\nangular_diameter_deg = 30.0",
                "angular_diameter_deg",
            ),
            ("[light]\ndisk_samples = 0", "disk_samples"),
            ("[texture]\npath = \"a.png\"\ngain = 0.0", "gain"),
            ("[texture]\npath = \"a.png\"\nambient = 2.0", "ambient"),
        ] {
            let e = Scene::from_toml_str(text, Path::new("s.toml"))
                .unwrap_err()
                .to_string();
            assert!(e.contains(key) && e.contains("s.toml"), "{text}: {e}");
        }
        let s = Scene::from_toml_str(
            "[output]\nsupersample = 3\ntone = \"filmic\"\nwhite = 4.0\n[light]\nangular_diameter_deg = 0\ndisk_samples = 16",
            Path::new("s.toml"),
        )
        .unwrap();
        assert_eq!(s.output.render_size(), (1536, 1536));
        assert_eq!(
            s.light.disk_samples().len(),
            1,
            "diameter 0 is a point light"
        );
    }

    #[test]
    fn resolve_downsamples_then_exposes_then_tones() {
        let out = Output {
            width: 2,
            height: 1,
            exposure: 2.0,
            supersample: 2,
            tone: Tone::Filmic,
            white: 4.0,
            ..Output::default()
        };
        assert_eq!(out.render_size(), (4, 2));
        let frame = vec![
            [1.0, 0.0, 0.0],
            [3.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0],
        ];
        let px = out.resolve(&frame).unwrap();
        let f = |x: f32| crate::image_io::tone_map(x, Tone::Filmic, 4.0);
        assert_eq!(px, vec![[f(2.0), 0.0, 0.0], [0.0, 0.0, f(2.0)]]);
        assert!(out.resolve(&frame[..4]).is_err());
    }

    #[test]
    fn texture_shading_is_algorithm_4_lit_by_the_sun_plus_the_sky() {
        let t = TextureSpec {
            path: "x.png".into(),
            w_diffuse: 0.25,
            ambient: 0.1,
            gain: 0.5,
        };
        let c = t.shade([0.8, 0.4, 0.0], [0.2, 0.4, 1.0], 0.04, 0.5, 2.0);
        // lit = 2·0.5 = 1; tex = 0.5·c_texture; (1 − α) = 0.96.
        let want = [0, 1, 2].map(|i| {
            let tex = 0.5 * [0.2f32, 0.4, 1.0][i];
            0.75 * [0.8f32, 0.4, 0.0][i] + 0.96 * tex + 0.25 * tex
        });
        for i in 0..3 {
            assert!((c[i] - want[i]).abs() < 1e-6, "{c:?} vs {want:?}");
        }
        // Facing away from the sun: nothing of it is left.
        let dark = t.shade([5.0; 3], [0.2, 0.4, 1.0], 0.04, -0.3, 2.0);
        assert_eq!(dark, [0.0; 3]);
        // The sky, seen head-on without Fresnel on the scale 1: radiance 0.1·2/π times
        // (1 − w_d) of the mirror's 1 plus t·(π(1 + w_d) − A_α).
        let sky = t.sky([0.2, 0.4, 1.0], 1.0, 2.0, (0.04, false), 1.0);
        let a_alpha = std::f64::consts::PI * 0.04 + 0.96 * crate::light::sky::fresnel_tail(1.0);
        let want = [0.2f64, 0.4, 1.0].map(|c| {
            let tex = 0.5 * c * (std::f64::consts::PI * 1.25 - a_alpha);
            (0.2 / std::f64::consts::PI * (0.75 + tex)) as f32
        });
        for i in 0..3 {
            assert!((sky[i] - want[i]).abs() < 1e-5, "{sky:?} vs {want:?}");
        }
    }

    #[test]
    fn a_scene_serialises_to_toml_that_parses_back() {
        let mut s = Scene::default_scene();
        s.texture = Some(TextureSpec {
            path: "/t/skin.png".into(),
            w_diffuse: 0.25,
            ambient: 0.125,
            gain: 0.5,
        });
        s.output.tone = Tone::Filmic;
        s.output.supersample = 3;
        s.light.angular_diameter_deg = 2.0;
        s.material.dh_um = Some(0.05);
        let text = toml::to_string(&s).expect("serialise");
        assert_eq!(
            Scene::from_toml_str(&text, Path::new("/x/s.toml")).unwrap(),
            s
        );
    }

    #[test]
    fn semantic_errors_name_line_and_column() {
        let text = "[camera]\neye = [0, 1, 2]\nfov_y_deg = 200\n\n[material]\nterms = 99\n";
        let e = Scene::from_toml_str(text, Path::new("s.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 3, column 1: [camera] fov_y_deg"), "{e}");
        let text = "[material]\nexpansion = \"taylor\"\n  terms = 99\n";
        let e = Scene::from_toml_str(text, Path::new("s.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 3, column 3: [material]"), "{e}");
        let text = "[camera]\neye = [0, 1, 2]\ntarget = [0, 1, 2]\n";
        let e = Scene::from_toml_str(text, Path::new("s.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2, column 1"), "{e}");
    }

    #[test]
    fn line_col_counts_from_one() {
        assert_eq!(line_col("ab\ncd", 0), (1, 1));
        assert_eq!(line_col("ab\ncd", 4), (2, 2));
        assert_eq!(line_col("ab", 99), (1, 3));
    }

    #[test]
    fn vulkan_clip_space_has_y_down_and_depth_0_to_1() {
        let cam = Camera {
            eye: [0.0, 0.0, 5.0],
            target: [0.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
            near: 1.0,
            far: 10.0,
        };
        let m = cam.view_proj(1.0);
        let ndc = |p: Vec3| {
            let c = m * p.extend(1.0);
            c.truncate() / c.w
        };
        // A point above the target appears in the upper half: negative y in Vulkan NDC.
        assert!(ndc(Vec3::new(0.0, 1.0, 0.0)).y < 0.0);
        assert!(ndc(Vec3::new(1.0, 0.0, 0.0)).x > 0.0);
        assert!(
            ndc(Vec3::new(0.0, 0.0, 4.0)).z.abs() < 1e-5,
            "near plane → 0"
        );
        assert!(
            (ndc(Vec3::new(0.0, 0.0, -5.0)).z - 1.0).abs() < 1e-5,
            "far plane → 1"
        );
    }
}
