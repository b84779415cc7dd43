//! What the mouse and keys change: an orbit camera (left drag orbits, right drag moves the
//! light, middle drag or shift+left pans, wheel zooms), the light direction, exposure and
//! feature switches. Pure state, no Vulkan and no window: the app applies it.

use glam::Vec3;

use crate::scene::{Camera, Scene};

/// The key table, printed at start and on `H`.
pub const HELP: &str = "\
diffract view — keys and mouse
  left drag        orbit the camera          wheel         zoom
  middle drag      pan (or shift + left)     right drag    move the light
  arrow keys       move the light            + / -         exposure ×1.25 / ÷1.25
  V                next shader variant       F / S / T     toggle Fresnel / shadowing / texture
  P                screenshot (PNG)          H             this help
  Esc / Q          quit";

/// Camera and light state of the viewer.
#[derive(Debug, Clone)]
pub struct ViewState {
    pub camera: Camera,
    /// Direction the light travels (world), unit length.
    pub light_dir: Vec3,
    pub exposure: f32,
    pub fresnel: bool,
    pub shadowing: bool,
    pub texture: bool,
}

impl ViewState {
    pub fn from_scene(scene: &Scene) -> Self {
        Self {
            camera: scene.camera.clone(),
            light_dir: Vec3::from(scene.light.direction).normalize_or(Vec3::NEG_Y),
            exposure: scene.output.exposure,
            fresnel: scene.material.fresnel,
            shadowing: scene.material.shadowing,
            texture: true,
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
