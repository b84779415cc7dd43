//! What the mouse and keys change: an orbit camera (left drag orbits, right drag moves the
//! light, middle drag or shift+left pans, wheel zooms), the light direction, exposure,
//! variant, feature switches, the BRDF map beside the mesh and the material (the
//! structure's height, the coherence length, the height field). Pure state, no Vulkan and no
//! window: [`Controls`] takes winit's events (or a test's synthetic ones) and says what
//! changed ([`Effect`]); the app applies it.

use glam::Vec3;
use winit::event::{MouseButton, MouseScrollDelta};
use winit::keyboard::{Key, ModifiersState, NamedKey};

use crate::mesh::{Mesh, Vertex};
use crate::render::VariantKind;
use crate::scene::{Camera, Scene};

/// The key table, printed at start and on `H`.
pub const HELP: &str = "\
diffract view — keys and mouse
  left drag        orbit the camera          wheel         zoom
  middle drag      pan (or shift + left)     right drag    move the light
  arrow keys       move the light            + / -         exposure ×1.25 / ÷1.25
  V                next shader variant       F / S / T     toggle Fresnel / shadowing / texture
  B                BRDF map beside the mesh  [ / ]         map exposure ÷1.25 / ×1.25
  Z / X            height ÷1.25 / ×1.25      K / L         coherence length ÷1.25 / ×1.25
  N                next height field         P             screenshot (PNG)
  E                next environment (none, sky, studio, white, --env's)
  R + left drag    turn the environment      , / .         turn it by −5° / +5°
  H                this help                 Esc / Q       quit
  (a material edit rebuilds the table in the background; the title shows its progress;
   under an environment the picture accumulates, the title shows the samples so far)";

/// The height fields `N` cycles through after the scene's own: the synthetic gratings and
/// the measured Elaphe crop grown to the default patch.
pub const SHIPPED_FIELDS: [&str; 5] = [
    "builtin:blazed",
    "builtin:sinusoidal",
    "builtin:elaphe",
    "builtin:xenopeltis",
    "builtin:elaphe-grown",
];

/// Factor of the height and coherence steps (`Z`/`X`, `K`/`L`).
pub const MATERIAL_STEP: f64 = 1.25;

/// The material edits of the viewer, relative to the scene's material: the heights are
/// multiplied by `1.25^height_steps`, the coherence length by `1.25^coherence_steps`, and
/// `field` picks the height field (0: the scene's own, then [`SHIPPED_FIELDS`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MaterialEdit {
    pub height_steps: i32,
    pub coherence_steps: i32,
    pub field: usize,
}

impl MaterialEdit {
    /// The factor on every height.
    pub fn height_scale(&self) -> f64 {
        MATERIAL_STEP.powi(self.height_steps)
    }

    /// The factor on the coherence length.
    pub fn coherence_scale(&self) -> f64 {
        MATERIAL_STEP.powi(self.coherence_steps)
    }

    /// The height field: `own` (the scene's) or a shipped one.
    pub fn heightfield<'a>(&self, own: &'a str) -> &'a str {
        match self.field {
            0 => own,
            i => SHIPPED_FIELDS[(i - 1) % SHIPPED_FIELDS.len()],
        }
    }
}

/// Exposure of the BRDF map without `--map-exposure`: a BRDF is much smaller than the
/// radiance a scene's exposure is chosen for (the README's map figures use 30 to 300).
pub const DEFAULT_MAP_EXPOSURE: f32 = 30.0;

/// Radians per pixel of an orbit or light drag.
const DRAG_RADIANS: f32 = 0.01;
/// Fraction of the eye's distance per pixel of a pan.
const PAN_PER_PIXEL: f32 = 0.002;
/// Zoom factor per wheel line (0.9: a line towards the target brings the eye 10 % closer).
const ZOOM_PER_LINE: f32 = 0.9;
/// Pixels of a touchpad's pixel scroll that count as one wheel line.
const PIXELS_PER_LINE: f32 = 40.0;
/// Light turn per arrow key press (degrees).
const ARROW_DEGREES: f32 = 3.0;
/// Exposure factor of `+` / `-`.
const EXPOSURE_STEP: f32 = 1.25;
/// Degrees the environment turns per `,` / `.` press.
pub const ENV_ROTATE_STEP_DEG: f64 = 5.0;
/// Degrees the environment turns per pixel of an `R` + left drag.
const ENV_DRAG_DEG: f64 = 0.5;

/// Camera and light state of the viewer.
#[derive(Debug, Clone)]
pub struct ViewState {
    pub camera: Camera,
    /// Direction the light travels (world), unit length.
    pub light_dir: Vec3,
    pub exposure: f32,
    /// Exposure of the BRDF map (its XYZ → linear sRGB values are multiplied by it).
    pub map_exposure: f32,
    pub fresnel: bool,
    pub shadowing: bool,
    pub texture: bool,
    /// The environment's turn about +Y on top of its own (degrees; `,` `.` and `R` + drag).
    pub env_rotate_deg: f64,
}

/// What an input changed, for the app to act on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Effect {
    /// Not a control (or a mouse move with no button held).
    None,
    /// Camera, light or exposure moved: the same pipeline draws the next frame.
    View,
    /// The variant or a feature switch changed: the pass is rebuilt. The line says what.
    Rebuild(String),
    /// The material changed ([`Controls::material`]): it is loaded and its table built in
    /// the background. The line says what.
    Material(String),
    /// `B`: the BRDF map beside the mesh was switched on or off ([`Controls::map`]).
    Map,
    /// `E`: the next environment.
    Env,
    /// `H`: print [`HELP`].
    Help,
    /// `P`: save the next frame.
    Screenshot,
    /// `Esc` / `Q`.
    Quit,
}

/// The interactive controls: the [`ViewState`], the variant, the BRDF-map switch and the
/// mouse buttons held. The app feeds it winit's window events; tests feed it synthetic ones.
#[derive(Debug, Clone)]
pub struct Controls {
    pub state: ViewState,
    pub variant: VariantKind,
    /// The BRDF map is drawn beside the mesh.
    pub map: bool,
    /// Mesh frames are evaluated per vertex: `V` cycles only the variants that have a
    /// vertex stage.
    pub per_vertex: bool,
    /// The material edits so far.
    pub material: MaterialEdit,
    /// Left, right, middle.
    buttons: [bool; 3],
    shift: bool,
    /// `R` is held: a left drag turns the environment.
    rotate_env: bool,
    cursor: Option<(f64, f64)>,
}

impl Controls {
    pub fn new(state: ViewState, variant: VariantKind) -> Self {
        Self {
            state,
            variant: variant.resolve(),
            map: false,
            per_vertex: false,
            material: MaterialEdit::default(),
            buttons: [false; 3],
            shift: false,
            rotate_env: false,
            cursor: None,
        }
    }

    /// A key press (releases are not controls).
    pub fn key(&mut self, key: &Key) -> Effect {
        let step = ARROW_DEGREES.to_radians();
        let s = &mut self.state;
        match key {
            Key::Named(NamedKey::Escape) => return Effect::Quit,
            Key::Named(NamedKey::ArrowLeft) => s.turn_light(-step, 0.0),
            Key::Named(NamedKey::ArrowRight) => s.turn_light(step, 0.0),
            Key::Named(NamedKey::ArrowUp) => s.turn_light(0.0, -step),
            Key::Named(NamedKey::ArrowDown) => s.turn_light(0.0, step),
            Key::Character(c) => match c.to_lowercase().as_str() {
                "q" => return Effect::Quit,
                "+" | "=" => s.exposure *= EXPOSURE_STEP,
                "-" => s.exposure /= EXPOSURE_STEP,
                "]" => s.map_exposure *= EXPOSURE_STEP,
                "[" => s.map_exposure /= EXPOSURE_STEP,
                "h" => return Effect::Help,
                "e" => return Effect::Env,
                "," => s.env_rotate_deg -= ENV_ROTATE_STEP_DEG,
                "." => s.env_rotate_deg += ENV_ROTATE_STEP_DEG,
                "r" => {
                    self.rotate_env = true;
                    return Effect::None;
                }
                "z" | "x" | "k" | "l" | "n" => return self.edit_material(c),
                "p" => return Effect::Screenshot,
                "b" => {
                    self.map = !self.map;
                    return Effect::Map;
                }
                "v" => {
                    let per_vertex = self.per_vertex;
                    let all: Vec<VariantKind> = VariantKind::ALL
                        .into_iter()
                        .filter(|k| !per_vertex || k.per_vertex_file().is_some())
                        .collect();
                    let i = all.iter().position(|k| *k == self.variant).unwrap_or(0);
                    self.variant = all[(i + 1) % all.len()];
                    return Effect::Rebuild(format!("variant → {}", self.variant.name()));
                }
                "f" => {
                    s.fresnel = !s.fresnel;
                    return Effect::Rebuild(format!("Fresnel {}", on_off(s.fresnel)));
                }
                "s" => {
                    s.shadowing = !s.shadowing;
                    return Effect::Rebuild(format!("shadowing {}", on_off(s.shadowing)));
                }
                "t" => {
                    s.texture = !s.texture;
                    return Effect::Rebuild(format!("texture blending {}", on_off(s.texture)));
                }
                _ => return Effect::None,
            },
            _ => return Effect::None,
        }
        Effect::View
    }

    /// A key released: `R` ends the environment's drag.
    pub fn key_released(&mut self, key: &Key) {
        if matches!(key, Key::Character(c) if c.eq_ignore_ascii_case("r")) {
            self.rotate_env = false;
        }
    }

    /// `Z`/`X` (height), `K`/`L` (coherence length), `N` (height field).
    fn edit_material(&mut self, key: &str) -> Effect {
        let m = &mut self.material;
        let line = match key.to_lowercase().as_str() {
            "z" | "x" => {
                m.height_steps += if key.eq_ignore_ascii_case("x") { 1 } else { -1 };
                format!("height ×{:.4} of the field's own", m.height_scale())
            }
            "k" | "l" => {
                m.coherence_steps += if key.eq_ignore_ascii_case("l") { 1 } else { -1 };
                format!("coherence length ×{:.4}", m.coherence_scale())
            }
            _ => {
                m.field = (m.field + 1) % (SHIPPED_FIELDS.len() + 1);
                match m.field {
                    0 => "height field → the scene's own".to_string(),
                    _ => format!("height field → {}", m.heightfield("")),
                }
            }
        };
        Effect::Material(line)
    }

    /// The modifier keys held (shift + left drag pans).
    pub fn modifiers(&mut self, m: ModifiersState) {
        self.shift = m.shift_key();
    }

    /// A mouse button pressed or released.
    pub fn button(&mut self, button: MouseButton, pressed: bool) {
        match button {
            MouseButton::Left => self.buttons[0] = pressed,
            MouseButton::Right => self.buttons[1] = pressed,
            MouseButton::Middle => self.buttons[2] = pressed,
            _ => {}
        }
    }

    /// The cursor moved to `(x, y)` (window pixels): a drag with the buttons held.
    pub fn cursor_moved(&mut self, x: f64, y: f64) -> Effect {
        let last = self.cursor.replace((x, y));
        let Some((lx, ly)) = last else {
            return Effect::None;
        };
        let (dx, dy) = ((x - lx) as f32, (y - ly) as f32);
        let [left, right, middle] = self.buttons;
        if left && self.rotate_env {
            self.state.env_rotate_deg += f64::from(dx) * ENV_DRAG_DEG;
        } else if middle || (left && self.shift) {
            self.state.pan(dx * PAN_PER_PIXEL, dy * PAN_PER_PIXEL);
        } else if left {
            self.state.orbit(dx * DRAG_RADIANS, dy * DRAG_RADIANS);
        } else if right {
            self.state.turn_light(dx * DRAG_RADIANS, dy * DRAG_RADIANS);
        } else {
            return Effect::None;
        }
        Effect::View
    }

    /// The cursor left the window: the next move starts a new drag.
    pub fn cursor_left(&mut self) {
        self.cursor = None;
    }

    /// A wheel or touchpad scroll: up (positive) zooms in.
    pub fn wheel(&mut self, delta: MouseScrollDelta) -> Effect {
        let lines = match delta {
            MouseScrollDelta::LineDelta(_, y) => y,
            MouseScrollDelta::PixelDelta(p) => p.y as f32 / PIXELS_PER_LINE,
        };
        if lines == 0.0 || !lines.is_finite() {
            return Effect::None;
        }
        self.state.zoom(ZOOM_PER_LINE.powf(lines));
        Effect::View
    }
}

fn on_off(b: bool) -> &'static str {
    if b {
        "on"
    } else {
        "off"
    }
}

/// The vertex nearest the line through `eye` along the unit `axis`.
fn nearest_to_axis<'a>(
    vertices: impl Iterator<Item = &'a Vertex>,
    eye: Vec3,
    axis: Vec3,
) -> Option<&'a Vertex> {
    let off_axis = |v: &Vertex| {
        let d = Vec3::from(v.position) - eye;
        (d - axis * d.dot(axis)).length_squared()
    };
    vertices.min_by(|a, b| off_axis(a).total_cmp(&off_axis(b)))
}

/// The tangent frame `(t, b, n)` of the surface at the centre of `camera`'s view: of the
/// vertices that face the eye, the one nearest the line of sight (eye → target); all
/// vertices when none faces it. Built as diffraction.vert builds it (Gram–Schmidt tangent,
/// bitangent with the handedness sign). `None` for a mesh without vertices.
pub fn tangent_frame_at_view(mesh: &Mesh, camera: &Camera) -> Option<[Vec3; 3]> {
    let eye = Vec3::from(camera.eye);
    let axis = (Vec3::from(camera.target) - eye).normalize_or(Vec3::NEG_Z);
    let facing = |v: &&Vertex| {
        let p = Vec3::from(v.position);
        Vec3::from(v.normal).dot(eye - p) > 0.0 && (p - eye).dot(axis) > 0.0
    };
    let v = nearest_to_axis(mesh.vertices.iter().filter(facing), eye, axis)
        .or_else(|| nearest_to_axis(mesh.vertices.iter(), eye, axis))?;
    let n = Vec3::from(v.normal).normalize_or(Vec3::Z);
    let t0 = Vec3::new(v.tangent[0], v.tangent[1], v.tangent[2]);
    let t = (t0 - n * n.dot(t0)).normalize_or(n.any_orthonormal_vector());
    let b = if v.tangent[3] < 0.0 { -1.0 } else { 1.0 } * n.cross(t);
    Some([t, b, n])
}

impl ViewState {
    pub fn from_scene(scene: &Scene) -> Self {
        Self {
            camera: scene.camera.clone(),
            light_dir: Vec3::from(scene.light.direction).normalize_or(Vec3::NEG_Y),
            exposure: scene.output.exposure,
            map_exposure: DEFAULT_MAP_EXPOSURE,
            fresnel: scene.material.fresnel,
            shadowing: scene.material.shadowing,
            texture: true,
            env_rotate_deg: 0.0,
        }
    }

    fn up(&self) -> Vec3 {
        Vec3::from(self.camera.up).normalize_or(Vec3::Y)
    }

    /// Rotates the eye about the target: `dx` about the up axis, `dy` towards/away from it
    /// (radians); stops short of the poles so the view never flips.
    pub fn orbit(&mut self, dx: f32, dy: f32) {
        let target = Vec3::from(self.camera.target);
        let up = self.up();
        let offset = Vec3::from(self.camera.eye) - target;
        let r = offset.length();
        if r <= 0.0 {
            return;
        }
        let mut d = glam::Quat::from_axis_angle(up, -dx) * offset;
        let right = d.cross(up).normalize_or_zero();
        if right != Vec3::ZERO {
            let tilted = glam::Quat::from_axis_angle(right, -dy) * d;
            // Keep 5° away from the up axis.
            if tilted.normalize().dot(up).abs() < 0.996 {
                d = tilted;
            }
        }
        self.camera.eye = (target + d.normalize() * r).to_array();
    }

    /// Multiplies the eye's distance to the target by `factor`.
    pub fn zoom(&mut self, factor: f32) {
        let target = Vec3::from(self.camera.target);
        let offset = Vec3::from(self.camera.eye) - target;
        let r = (offset.length() * factor).clamp(1e-3, 1e6);
        self.camera.eye = (target + offset.normalize_or(Vec3::Z) * r).to_array();
    }

    /// Moves eye and target in the view plane by `dx`, `dy` (fractions of the distance).
    pub fn pan(&mut self, dx: f32, dy: f32) {
        let target = Vec3::from(self.camera.target);
        let eye = Vec3::from(self.camera.eye);
        let forward = (target - eye).normalize_or(Vec3::NEG_Z);
        let right = forward.cross(self.up()).normalize_or(Vec3::X);
        let up = right.cross(forward);
        let shift = (right * -dx + up * dy) * (target - eye).length();
        self.camera.eye = (eye + shift).to_array();
        self.camera.target = (target + shift).to_array();
    }

    /// Turns the light: `dx` about the up axis, `dy` towards/away from it (radians).
    pub fn turn_light(&mut self, dx: f32, dy: f32) {
        let up = self.up();
        let mut d = glam::Quat::from_axis_angle(up, dx) * self.light_dir;
        let right = d.cross(up).normalize_or_zero();
        if right != Vec3::ZERO {
            let tilted = glam::Quat::from_axis_angle(right, dy) * d;
            if tilted.dot(up).abs() < 0.996 {
                d = tilted;
            }
        }
        self.light_dir = d.normalize();
    }

    /// The BRDF map's light as `(θi, φi)` in degrees — the arguments of
    /// `Renderer::render_brdf_map` — in `frame` (from [`tangent_frame_at_view`]): the direction
    /// to the light, dropped onto the horizon when the light is below it (the map then shows
    /// grazing light; the mesh there is unlit).
    pub fn map_light_angles(&self, frame: [Vec3; 3]) -> (f64, f64) {
        let to_light = -self.light_dir;
        let [t, b, n] = frame;
        let local = Vec3::new(to_light.dot(t), to_light.dot(b), to_light.dot(n).max(0.0));
        let l = local.normalize_or(Vec3::Z);
        let theta = (l.z as f64).clamp(-1.0, 1.0).acos().to_degrees().min(90.0);
        let phi = (l.y as f64).atan2(l.x as f64).to_degrees();
        (theta, phi)
    }

    /// `scene` with this state's camera, light and exposure (the switches are pass options,
    /// so the prepared material stays the same).
    pub fn apply(&self, scene: &Scene) -> Scene {
        let mut s = scene.clone();
        s.camera = self.camera.clone();
        s.light.direction = self.light_dir.to_array();
        s.output.exposure = self.exposure;
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orbit_keeps_the_distance_and_zoom_scales_it() {
        let scene = Scene::default_scene();
        let mut v = ViewState::from_scene(&scene);
        let dist =
            |v: &ViewState| (Vec3::from(v.camera.eye) - Vec3::from(v.camera.target)).length();
        let r0 = dist(&v);
        v.orbit(0.3, 0.2);
        assert!((dist(&v) - r0).abs() < 1e-3 * r0);
        assert_ne!(v.camera.eye, scene.camera.eye);
        v.zoom(0.5);
        assert!((dist(&v) - 0.5 * r0).abs() < 1e-3 * r0);
        // A light perpendicular to the up axis moves by 2·sin(0.1) ≈ 0.2 when turned by 0.2
        // about it, whatever the scene's own light.
        v.light_dir = v.up().any_orthonormal_vector();
        let before = v.light_dir;
        v.turn_light(0.2, 0.0);
        assert!((v.light_dir.length() - 1.0).abs() < 1e-5);
        assert!(v.light_dir.distance(before) > 0.1);
    }
}
