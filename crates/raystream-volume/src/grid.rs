//! Reading a grid of values between its points.

use raystream_math::Vec3;

/// Trilinear interpolation at continuous index `p` of a grid of `dims` values read by `at`,
/// clamped to the grid (the GPU's `sample_at` and `light_at` compute the same).
pub fn trilinear<T>(dims: [usize; 3], p: Vec3, at: impl Fn(usize, usize, usize) -> T) -> T
where
    T: Copy
        + std::ops::Add<Output = T>
        + std::ops::Sub<Output = T>
        + std::ops::Mul<f32, Output = T>,
{
    let [nx, ny, nz] = dims;
    let c = |x: f32, n: usize| x.clamp(0.0, (n - 1) as f32);
    let (x, y, z) = (c(p.x, nx), c(p.y, ny), c(p.z, nz));
    // Through u32 (each coordinate is below its axis's size): x86-64's baseline converts
    // between f32 and u32 in one instruction, between f32 and usize in several.
    let cell = |x: f32, n: usize| (x as u32).min(n.saturating_sub(2) as u32);
    let (i, j, k) = (cell(x, nx), cell(y, ny), cell(z, nz));
    let (fx, fy, fz) = (x - i as f32, y - j as f32, z - k as f32);
    let (i, j, k) = (i as usize, j as usize, k as usize);
    let v = |di: usize, dj: usize, dk: usize| {
        at(
            (i + di).min(nx - 1),
            (j + dj).min(ny - 1),
            (k + dk).min(nz - 1),
        )
    };
    let l = |a: T, b: T, w: f32| a + (b - a) * w;
    l(
        l(
            l(v(0, 0, 0), v(1, 0, 0), fx),
            l(v(0, 1, 0), v(1, 1, 0), fx),
            fy,
        ),
        l(
            l(v(0, 0, 1), v(1, 0, 1), fx),
            l(v(0, 1, 1), v(1, 1, 1), fx),
            fy,
        ),
        fz,
    )
}
