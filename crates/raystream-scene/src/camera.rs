//! Pinhole camera. Its framing rule is the one `../shared/tools/rays.py` uses for the standard
//! ray sets (60° vertical field of view, looking at the bounding-box centre from direction
//! (0.35, 0.25, 1), backed off until the projected points fit with a 5 % margin), so that
//! `raystream bench` and `rays.py gen` trace the same primary rays.

use raystream_math::{Aabb, Mat3, Quat, Ray, Vec3};

pub const FRAME_FOV_DEG: f32 = 60.0;
pub const FRAME_VIEW_DIR: Vec3 = Vec3::new(0.35, 0.25, 1.0);
/// The view of meshes and scenes: from `FRAME_VIEW_DIR`, (0.35, 0.25, 1), y up.
pub const FRAME_VIEW: View = View::from(FRAME_VIEW_DIR);
const FRAME_MARGIN: f32 = 1.05;
const FRAME_SAMPLES: usize = 200_000;

/// Where a framing camera looks from: `back` points from what it frames towards the eye, and
/// `up` is the image's up (any vector not along `back`; the camera keeps its part across the
/// view).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub back: Vec3,
    pub up: Vec3,
}

impl View {
    /// From `back`, with y up.
    pub const fn from(back: Vec3) -> View {
        View { back, up: Vec3::Y }
    }

    /// This view turned `azimuth` degrees about its up axis (right-handed: from the front, +90
    /// looks from the image's right side), then raised `elevation` degrees towards its up
    /// (90: looking straight down the up axis, the old view's far side now at the image's
    /// top). Zero angles leave it exactly as it was.
    #[must_use]
    pub fn orbit(self, azimuth: f32, elevation: f32) -> View {
        let mut v = self;
        if azimuth != 0.0 {
            v.back = Quat::from_axis_angle(v.up.normalize(), azimuth.to_radians()) * v.back;
        }
        if elevation != 0.0 {
            let b = v.back.normalize();
            let u = v.up.reject_from_normalized(b).normalize();
            let (s, c) = elevation.to_radians().sin_cos();
            v = View {
                back: b * c + u * s,
                up: u * c - b * s,
            };
        }
        v
    }

    /// The view's frame as the columns of a rotation: the image's right, its up and `back`,
    /// each of unit length.
    pub fn basis(self) -> Mat3 {
        let back = self.back.normalize();
        let right = self.up.cross(back).normalize();
        Mat3::from_cols(right, back.cross(right), back)
    }

    /// The rotation that takes `from`'s frame onto this view's: what turns with the camera
    /// (lights that keep their place beside it) turns by it.
    pub fn turn_from(self, from: View) -> Mat3 {
        self.basis() * from.basis().transpose()
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub fwd: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    /// tan of half the vertical field of view.
    pub tan_y: f32,
    /// Half the view's height in world units for a parallel (orthographic) projection: each
    /// ray runs along `fwd` from its own point of the image plane through `eye`, so that sizes
    /// do not change with depth. 0: a perspective projection from `eye` (`tan_y`).
    pub parallel: f32,
}

/// How a framing camera projects.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Projection {
    /// From the eye, 60° high: near things larger.
    #[default]
    Perspective,
    /// Rays parallel to the view: every depth at one scale, as radiology shows projections.
    Parallel,
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
            parallel: 0.0,
        }
    }

    /// A camera looking at the points' bounding-box centre from `FRAME_VIEW_DIR`, backed off
    /// until every point projects inside the frame with a 5 % margin.
    pub fn frame(points: &[Vec3], aspect: f32) -> Camera {
        Self::frame_from(points, aspect, FRAME_VIEW)
    }

    /// As [`Camera::frame`], with `view`.
    pub fn frame_from(points: &[Vec3], aspect: f32, view: View) -> Camera {
        Self::framing(points, aspect, view, Projection::Perspective)
    }

    /// A parallel projection along `view` of the points' bounding-box centre, the view's
    /// height the smallest that shows every point with a 5 % margin, the eye plane in front of
    /// them all.
    pub fn frame_parallel(points: &[Vec3], aspect: f32, view: View) -> Camera {
        Self::framing(points, aspect, view, Projection::Parallel)
    }

    /// A camera looking at the points' bounding-box centre along `view`: in perspective
    /// ([`Camera::frame_from`]) or in parallel ([`Camera::frame_parallel`]).
    pub fn framing(points: &[Vec3], aspect: f32, view: View, projection: Projection) -> Camera {
        let b = Aabb::from_points(points);
        let center = b.center();
        let back = view.back.normalize();
        // The view direction straight from `back`, as rays.py takes it (not from an eye one
        // unit from the centre, which rounds onto the centre far from the origin).
        let mut cam = Camera::looking_along(center, -back, view.up, FRAME_FOV_DEG);
        let step = (points.len() / FRAME_SAMPLES).max(1);
        let sampled = points.iter().step_by(step).map(|&p| p - center);
        let r = b.radius();
        match projection {
            Projection::Perspective => {
                let tan_x = cam.tan_y * aspect;
                let need = sampled
                    .map(|q| {
                        (q.dot(cam.right).abs() / tan_x).max(q.dot(cam.up).abs() / cam.tan_y)
                            * FRAME_MARGIN
                            + q.dot(back)
                    })
                    .fold(f32::NEG_INFINITY, f32::max);
                cam.eye = center + back * need.max(1e-6 * r);
            }
            Projection::Parallel => {
                let (half, front) =
                    sampled.fold((0.0f32, f32::NEG_INFINITY), |(half, front), q| {
                        let h = (q.dot(cam.right).abs() / aspect).max(q.dot(cam.up).abs());
                        (half.max(h), front.max(q.dot(back)))
                    });
                cam.parallel = (half * FRAME_MARGIN).max(1e-6 * r).max(f32::MIN_POSITIVE);
                cam.eye = center + back * (front + 0.05 * r).max(1e-6 * r);
            }
        }
        cam
    }

    /// The ray through the image point (`x`, `y`) in pixels from the top-left corner of a
    /// `width`×`height` image (pixel centres at +0.5), unit direction, t from 0 to infinity.
    pub fn ray(&self, x: f32, y: f32, width: u32, height: u32) -> Ray {
        let (w, h) = (width as f32, height as f32);
        if self.parallel > 0.0 {
            let px = (x / w * 2.0 - 1.0) * (w / h);
            let py = 1.0 - y / h * 2.0;
            let origin = self.eye + (px * self.right + py * self.up) * self.parallel;
            return Ray::new(origin, self.fwd, 0.0, f32::INFINITY);
        }
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

    /// `View::orbit`: no turn is exactly no turn; a turn keeps the distance to the up axis and
    /// the camera level; raising a level view by ±90° looks straight down (up) the up axis
    /// with a finite camera; raising adds to the view's angle above the horizontal; a full
    /// circle comes back.
    #[test]
    fn orbits_turn_about_the_up_axis_and_raise_towards_it() {
        let v = View::from(FRAME_VIEW_DIR);
        assert_eq!(v.orbit(0.0, 0.0), v);
        let pts = [Vec3::new(-1.0, -2.0, -3.0), Vec3::new(2.0, 1.0, 0.5)];
        for az in [-170.0f32, -90.0, 33.0, 90.0, 180.0] {
            let t = v.orbit(az, 0.0);
            assert!((t.back.y - v.back.y).abs() < 1e-6, "{az}: {t:?}");
            assert!((t.back.length() - v.back.length()).abs() < 1e-5);
            let (s, c) = az.to_radians().sin_cos();
            let want = Vec3::new(
                v.back.x * c + v.back.z * s,
                v.back.y,
                v.back.z * c - v.back.x * s,
            );
            assert!((t.back - want).length() < 1e-5, "{az}: {t:?} vs {want}");
            let cam = Camera::frame_from(&pts, 1.0, t);
            assert!(cam.right.y.abs() < 1e-6, "{az}: the horizon tilts: {cam:?}");
        }
        let back = v.orbit(200.0, 0.0).orbit(160.0, 0.0);
        assert!((back.back - v.back).length() < 1e-5);
        // From a level view, ±90° looks straight down (up) the axis.
        let level = View::from(Vec3::Z);
        for el in [-90.0f32, 90.0] {
            let t = level.orbit(30.0, el);
            assert!(
                (t.back.normalize() - Vec3::Y * el.signum()).length() < 1e-6,
                "{t:?}"
            );
            let cam = Camera::frame_from(&pts, 1.0, t);
            assert!(cam.fwd.is_finite() && cam.right.is_finite() && cam.up.is_finite());
            assert!((cam.fwd + Vec3::Y * el.signum()).length() < 1e-6, "{cam:?}");
        }
        // Raised 30°: the view's angle above the horizontal grows by 30°.
        let rise = |b: Vec3| (b.y / b.length()).asin().to_degrees();
        assert!((rise(v.orbit(0.0, 30.0).back) - rise(v.back) - 30.0).abs() < 1e-3);
    }

    /// A parallel framing: every ray runs along `fwd`, every point lies in front of the eye
    /// plane and inside the view (5 % margin), and the view is no larger than that needs.
    #[test]
    fn parallel_framing_shows_every_point_at_one_scale() {
        let pts: Vec<Vec3> = (0..100)
            .map(|i| Vec3::new(i as f32, (i * 7 % 13) as f32, -(i as f32) * 0.5))
            .collect();
        for view in [
            FRAME_VIEW,
            View::from(Vec3::X),
            FRAME_VIEW.orbit(40.0, -30.0),
        ] {
            let aspect = 1.5;
            let cam = Camera::frame_parallel(&pts, aspect, view);
            assert!(cam.parallel > 0.0);
            let mut widest = 0.0f32;
            for p in &pts {
                let q = *p - cam.eye;
                assert!(q.dot(cam.fwd) > 0.0, "{p} behind the eye plane");
                let (x, y) = (q.dot(cam.right) / aspect, q.dot(cam.up));
                widest = widest.max(x.abs()).max(y.abs());
            }
            let b = Aabb::from_points(&pts);
            let c = b.center() - cam.eye;
            let (cx, cy) = (c.dot(cam.right) / aspect, c.dot(cam.up));
            assert!(cx.abs() < 1e-3 && cy.abs() < 1e-3, "off centre: {cx} {cy}");
            assert!(
                widest <= cam.parallel && widest * 1.06 > cam.parallel,
                "{widest} vs {}",
                cam.parallel
            );
            let (w, h) = (30, 20);
            for (x, y) in [(0.5, 0.5), (29.5, 0.5), (15.0, 10.0), (0.5, 19.5)] {
                let r = cam.ray(x, y, w, h);
                assert_eq!(r.dir, cam.fwd);
                let o = r.origin - cam.eye;
                assert!(
                    o.dot(cam.fwd).abs() < 1e-3,
                    "the ray starts off the eye plane"
                );
            }
            let corner = cam.ray(0.0, 0.0, w, h).origin - cam.eye;
            assert!((corner.dot(cam.up) - cam.parallel).abs() < 1e-3);
            assert!((corner.dot(cam.right) + cam.parallel * aspect).abs() < 1e-3);
        }
    }

    /// `View::turn_from` takes one view's frame onto another's: a point keeps its place in the
    /// camera's frame (right, up, back) when both turn, and the basis is orthonormal.
    #[test]
    fn what_turns_with_the_camera_keeps_its_place_beside_it() {
        let a = View::from(FRAME_VIEW_DIR);
        let p = Vec3::new(2.0, 3.0, 2.5);
        for b in [
            a.orbit(90.0, 0.0),
            a.orbit(-140.0, 35.0),
            a.orbit(10.0, -80.0),
            View {
                back: Vec3::NEG_Y,
                up: Vec3::Z,
            },
        ] {
            let m = b.basis();
            assert!(
                (m.transpose() * m - Mat3::IDENTITY)
                    .abs()
                    .to_cols_array()
                    .iter()
                    .all(|&e| e < 1e-6)
            );
            assert!((m.determinant() - 1.0).abs() < 1e-6);
            let turned = b.turn_from(a) * p;
            let (here, there) = (a.basis().transpose() * p, m.transpose() * turned);
            assert!((here - there).length() < 1e-5, "{b:?}: {here} vs {there}");
            assert!((turned.length() - p.length()).abs() < 1e-5);
        }
        assert!(
            (a.turn_from(a) - Mat3::IDENTITY)
                .abs()
                .to_cols_array()
                .iter()
                .all(|&e| e < 1e-6)
        );
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
