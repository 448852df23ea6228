//! The viewer's camera: a position and a viewing direction that the mouse turns and the keys
//! move, kept as the scene's `Camera` (position, look_at, up, fov_y) so that what the
//! viewer renders is exactly what `firstshot SCENE` renders from the printed `[camera]`.

use firstshot::scene::Camera;
use glam::DVec3;

/// Closest the viewing direction may come to straight up or down (degrees): at the pole
/// "right" (direction x up) is undefined.
const POLE_MARGIN_DEGREES: f64 = 1.0;

/// A camera that flies: `camera.look_at` is always `distance` ahead of the position, along
/// the viewing direction; `camera.up` never changes (it is the scene's vertical).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlyCamera {
    pub camera: Camera,
    /// Distance from the position to `look_at` (the scene file's, kept so that the printed
    /// `look_at` stays a sensible point).
    distance: f64,
}

/// A move along the camera's own axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    Forward,
    Back,
    Left,
    Right,
    Up,
    Down,
}

impl Direction {
    /// Script and key names.
    pub fn parse(word: &str) -> Option<Direction> {
        Some(match word {
            "forward" => Direction::Forward,
            "back" => Direction::Back,
            "left" => Direction::Left,
            "right" => Direction::Right,
            "up" => Direction::Up,
            "down" => Direction::Down,
            _ => return None,
        })
    }
}

impl FlyCamera {
    pub fn new(camera: Camera) -> FlyCamera {
        let distance = (camera.look_at - camera.position).length();
        let distance = if distance.is_finite() && distance > 0.0 { distance } else { 1.0 };
        FlyCamera { camera, distance }
    }

    fn forward(&self) -> DVec3 {
        (self.camera.look_at - self.camera.position).normalize()
    }

    fn up(&self) -> DVec3 {
        self.camera.up.normalize()
    }

    fn right(&self) -> DVec3 {
        self.forward().cross(self.up()).normalize()
    }

    /// Moves the camera (and its look_at) by `distance` scene units along `direction`:
    /// forward and back along the viewing direction, up and down along the scene's vertical.
    pub fn translate(&mut self, direction: Direction, distance: f64) {
        let axis = match direction {
            Direction::Forward => self.forward(),
            Direction::Back => -self.forward(),
            Direction::Right => self.right(),
            Direction::Left => -self.right(),
            Direction::Up => self.up(),
            Direction::Down => -self.up(),
        };
        let by = axis * distance;
        self.camera.position += by;
        self.camera.look_at += by;
    }

    /// Turns the viewing direction `yaw` degrees to the right (about the vertical) and
    /// `pitch` degrees up, stopping short of straight up or down.
    pub fn turn(&mut self, yaw: f64, pitch: f64) {
        let up = self.up();
        let forward = self.forward();
        // Elevation of the direction above the horizontal plane, in degrees.
        let elevation = forward.dot(up).clamp(-1.0, 1.0).asin().to_degrees();
        let limit = 90.0 - POLE_MARGIN_DEGREES;
        let pitch = (elevation + pitch).clamp(-limit, limit) - elevation;
        let turned = glam::DQuat::from_axis_angle(up, -yaw.to_radians()) * forward;
        let right = turned.cross(up).normalize();
        let turned = glam::DQuat::from_axis_angle(right, pitch.to_radians()) * turned;
        self.camera.look_at = self.camera.position + turned.normalize() * self.distance;
    }

    /// The camera as a `[camera]` table of the scene format (docs/SCENE_FORMAT.md). Numbers
    /// are written in Rust's shortest form that reads back as the same f64, so the scene
    /// renders the very camera the viewer showed. `file_origin`: the scene's
    /// (`Scene::file_origin`), so that the table is in the scene file's coordinates.
    pub fn toml(&self, file_origin: DVec3) -> String {
        let c = Camera {
            position: self.camera.position + file_origin,
            look_at: self.camera.look_at + file_origin,
            ..self.camera
        };
        let v = |v: DVec3| format!("[{:?}, {:?}, {:?}]", v.x, v.y, v.z);
        format!(
            "[camera]\nposition = {}\nlook_at = {}\nup = {}\nfov_y = {:?}\nwidth = {}\nheight = {}\n",
            v(c.position),
            v(c.look_at),
            v(c.up),
            c.fov_y,
            c.width,
            c.height
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cornell() -> Camera {
        Camera {
            position: DVec3::new(278.0, 273.0, -800.0),
            look_at: DVec3::new(278.0, 273.0, 0.0),
            up: DVec3::Y,
            fov_y: 39.3,
            width: 64,
            height: 48,
        }
    }

    #[test]
    fn moves_follow_the_view_and_keep_the_look_at_distance() {
        let mut c = FlyCamera::new(cornell());
        c.translate(Direction::Forward, 100.0);
        assert_eq!(c.camera.position, DVec3::new(278.0, 273.0, -700.0));
        assert_eq!(c.camera.look_at, DVec3::new(278.0, 273.0, 100.0));
        c.translate(Direction::Up, 10.0);
        assert_eq!(c.camera.position.y, 283.0);
        // Looking along +z with y up, right is -x (a right-handed frame, as the renderer's).
        c.translate(Direction::Right, 5.0);
        assert!((c.camera.position.x - 273.0).abs() < 1e-9, "{:?}", c.camera.position);
        c.turn(90.0, 0.0);
        let forward = (c.camera.look_at - c.camera.position).normalize();
        assert!((forward - DVec3::new(-1.0, 0.0, 0.0)).length() < 1e-9, "{forward:?}");
        assert!(((c.camera.look_at - c.camera.position).length() - 800.0).abs() < 1e-9);
    }

    #[test]
    fn pitch_stops_short_of_the_poles() {
        let mut c = FlyCamera::new(cornell());
        c.turn(0.0, 500.0);
        let forward = (c.camera.look_at - c.camera.position).normalize();
        let elevation = forward.y.asin().to_degrees();
        assert!((elevation - (90.0 - POLE_MARGIN_DEGREES)).abs() < 1e-6, "{elevation}");
        c.turn(0.0, -1000.0);
        let forward = (c.camera.look_at - c.camera.position).normalize();
        assert!((forward.y.asin().to_degrees() + 89.0).abs() < 1e-6);
    }

    #[test]
    fn the_printed_table_reads_back_as_the_same_camera() {
        let mut c = FlyCamera::new(cornell());
        c.turn(12.345, -3.21);
        c.translate(Direction::Left, 1.0 / 3.0);
        let table: toml::Table = c.toml(DVec3::ZERO).parse().unwrap();
        let cam = table["camera"].as_table().unwrap();
        let v = |k: &str| {
            let a = cam[k].as_array().unwrap();
            DVec3::new(a[0].as_float().unwrap(), a[1].as_float().unwrap(), a[2].as_float().unwrap())
        };
        assert_eq!(v("position"), c.camera.position);
        assert_eq!(v("look_at"), c.camera.look_at);
        assert_eq!(v("up"), c.camera.up);
        assert_eq!(cam["fov_y"].as_float().unwrap(), c.camera.fov_y);
        assert_eq!(cam["width"].as_integer().unwrap(), 64);
    }

    #[test]
    fn the_printed_table_is_in_the_scene_files_coordinates() {
        // A scene the loader moved to its own origin (`Scene::recentre`) by this much.
        let file_origin = DVec3::new(1048576.0, -2.0, 262144.0);
        let c = FlyCamera::new(cornell());
        let table: toml::Table = c.toml(file_origin).parse().unwrap();
        let cam = table["camera"].as_table().unwrap();
        let v = |k: &str| {
            let a = cam[k].as_array().unwrap();
            DVec3::new(a[0].as_float().unwrap(), a[1].as_float().unwrap(), a[2].as_float().unwrap())
        };
        assert_eq!(v("position"), c.camera.position + file_origin);
        assert_eq!(v("look_at"), c.camera.look_at + file_origin);
        assert_eq!(v("up"), c.camera.up);
    }
}
