//! Pinhole camera. Its framing rule is the one `../shared/tools/rays.py` uses for the standard
//! ray sets (60° vertical field of view, looking at the bounding-box centre from direction
//! (0.35, 0.25, 1), backed off until the projected points fit with a 5 % margin), so that
//! `raystream bench` and `rays.py gen` trace the same primary rays.

use raystream_math::{Aabb, Ray, Vec3};

pub const FRAME_FOV_DEG: f32 = 60.0;
pub const FRAME_VIEW_DIR: Vec3 = Vec3::new(0.35, 0.25, 1.0);
const FRAME_MARGIN: f32 = 1.05;
const FRAME_SAMPLES: usize = 200_000;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub fwd: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    /// tan of half the vertical field of view.
    pub tan_y: f32,
}

impl Camera {
    pub fn look_at(eye: Vec3, target: Vec3, up: Vec3, fov_y_deg: f32) -> Camera {
        Self::looking_along(eye, (target - eye).normalize(), up, fov_y_deg)
    }

    /// A camera at `eye` looking along the unit vector `fwd`.
    fn looking_along(eye: Vec3, fwd: Vec3, up: Vec3, fov_y_deg: f32) -> Camera {
        let right = fwd.cross(up).normalize();
        Camera {
            eye,
            fwd,
            right,
            up: right.cross(fwd),
            tan_y: (fov_y_deg.to_radians() * 0.5).tan(),
        }
    }

    /// A camera looking at the points' bounding-box centre from `FRAME_VIEW_DIR`, backed off
    /// until every point projects inside the frame with a 5 % margin.
    pub fn frame(points: &[Vec3], aspect: f32) -> Camera {
        Self::frame_from(points, aspect, FRAME_VIEW_DIR)
    }

    /// As [`Camera::frame`], looking from direction `view_dir` (towards the eye, y up).
    pub fn frame_from(points: &[Vec3], aspect: f32, view_dir: Vec3) -> Camera {
        let b = Aabb::from_points(points);
        let center = b.center();
        let back = view_dir.normalize();
        // The view direction straight from `back`, as rays.py takes it (not from an eye one
        // unit from the centre, which rounds onto the centre far from the origin).
        let mut cam = Camera::looking_along(center, -back, Vec3::Y, FRAME_FOV_DEG);
        let tan_x = cam.tan_y * aspect;
        let step = (points.len() / FRAME_SAMPLES).max(1);
        let need = points
            .iter()
            .step_by(step)
            .map(|&p| {
                let q = p - center;
                (q.dot(cam.right).abs() / tan_x).max(q.dot(cam.up).abs() / cam.tan_y) * FRAME_MARGIN
                    + q.dot(back)
            })
            .fold(f32::NEG_INFINITY, f32::max);
        cam.eye = center + back * need.max(1e-6 * b.radius());
        cam
    }

    /// The ray through the image point (`x`, `y`) in pixels from the top-left corner of a
    /// `width`×`height` image (pixel centres at +0.5), unit direction, t from 0 to infinity.
    pub fn ray(&self, x: f32, y: f32, width: u32, height: u32) -> Ray {
        let (w, h) = (width as f32, height as f32);
        let px = (x / w * 2.0 - 1.0) * self.tan_y * (w / h);
        let py = (1.0 - y / h * 2.0) * self.tan_y;
        let d = (self.fwd + px * self.right + py * self.up).normalize();
        Ray::new(self.eye, d, 0.0, f32::INFINITY)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framed_points_project_inside_the_image() {
        let pts: Vec<Vec3> = (0..100)
            .map(|i| Vec3::new(i as f32, (i * 7 % 13) as f32, -(i as f32) * 0.5))
            .collect();
        let cam = Camera::frame(&pts, 16.0 / 9.0);
        for p in &pts {
            let q = *p - cam.eye;
            let z = q.dot(cam.fwd);
            assert!(z > 0.0);
            assert!((q.dot(cam.right) / z).abs() <= cam.tan_y * 16.0 / 9.0 * 1.0001);
            assert!((q.dot(cam.up) / z).abs() <= cam.tan_y * 1.0001);
        }
        // The centre pixel looks at the box centre.
        let r = cam.ray(8.0, 4.5, 16, 9);
        assert!((r.dir - cam.fwd).length() < 1e-6);
    }

    /// Framing does not depend on where the points are or how large: the same view from 1e-3
    /// to 1e12 units (an eye one unit from the centre used to round onto it far from the
    /// origin, leaving a NaN view and an empty image).
    #[test]
    fn framing_holds_at_any_scale_and_place() {
        let pts: Vec<Vec3> = (0..100)
            .map(|i| Vec3::new(i as f32, (i * 7 % 13) as f32, -(i as f32) * 0.5))
            .collect();
        let unit = Camera::frame(&pts, 1.5);
        for scale in [1e-3f32, 1.0, 1e6, 1e9, 1e12] {
            for offset in [Vec3::ZERO, Vec3::new(3.0, -2.0, 1.0) * scale] {
                let moved: Vec<Vec3> = pts.iter().map(|&p| p * scale + offset).collect();
                let cam = Camera::frame(&moved, 1.5);
                assert_eq!(
                    (cam.fwd, cam.right, cam.up),
                    (unit.fwd, unit.right, unit.up),
                    "scale {scale}"
                );
                let want = unit.eye * scale + offset;
                assert!(
                    (cam.eye - want).length() <= 1e-5 * want.length().max(scale),
                    "scale {scale}: eye {} vs {want}",
                    cam.eye
                );
            }
        }
    }
}
