//! Reading a grid of values between its points.

use raystream_math::Vec3;

/// Trilinear interpolation at continuous index `p` of a grid of `dims` values read by `at`,
/// clamped to the grid (the GPU's `sample_at` and `light_at` compute the same).
#[inline(always)]
pub fn trilinear<T>(dims: [usize; 3], p: Vec3, at: impl Fn(usize, usize, usize) -> T) -> T
where
    T: Copy
        + std::ops::Add<Output = T>
        + std::ops::Sub<Output = T>
        + std::ops::Mul<f32, Output = T>,
{
    let ([i, j, k], [i1, j1, k1], f) = trilinear_cell(dims, p);
    blend(
        [
            at(i, j, k),
            at(i1, j, k),
            at(i, j1, k),
            at(i1, j1, k),
            at(i, j, k1),
            at(i1, j, k1),
            at(i, j1, k1),
            at(i1, j1, k1),
        ],
        f,
    )
}

/// [`trilinear`] of the values `data` (`dims`, x fastest), bit for bit, without a closure to
/// read them: inlined into a CPU renderer's x86-64-v3 copy, the compiler left the reading
/// closure out of line, in the baseline's code (13 % of a linear DVR frame, by perf).
#[inline(always)]
pub fn trilinear_in(dims: [usize; 3], data: &[f32], p: Vec3) -> f32 {
    let ([i, j, k], [i1, j1, k1], f) = trilinear_cell(dims, p);
    let [nx, ny, _] = dims;
    let (r00, r10) = (nx * (j + ny * k), nx * (j1 + ny * k));
    let (r01, r11) = (nx * (j + ny * k1), nx * (j1 + ny * k1));
    blend(
        [
            data[r00 + i],
            data[r00 + i1],
            data[r10 + i],
            data[r10 + i1],
            data[r01 + i],
            data[r01 + i1],
            data[r11 + i],
            data[r11 + i1],
        ],
        f,
    )
}

/// The trilinear blend of a cell's corners (x fastest, then y, then z) at fractions `f`:
/// along x, then y, then z, in that order (the bits every caller and the GPU rely on).
#[inline(always)]
fn blend<T>(c: [T; 8], [fx, fy, fz]: [f32; 3]) -> T
where
    T: Copy
        + std::ops::Add<Output = T>
        + std::ops::Sub<Output = T>
        + std::ops::Mul<f32, Output = T>,
{
    lerp(
        lerp(lerp(c[0], c[1], fx), lerp(c[2], c[3], fx), fy),
        lerp(lerp(c[4], c[5], fx), lerp(c[6], c[7], fx), fy),
        fz,
    )
}

/// The cell [`trilinear`] interpolates in at `p`: its lower and upper indices along each axis
/// (the same where the axis has one point) and `p`'s fractions across it. No closures: inlined
/// into a CPU renderer's x86-64-v3 copy, the compiler left them out of line, in the baseline's
/// code (28 % of a linear DVR frame, by perf).
#[inline(always)]
fn trilinear_cell(dims: [usize; 3], p: Vec3) -> ([usize; 3], [usize; 3], [f32; 3]) {
    let [nx, ny, nz] = dims;
    let (x, y, z) = (
        clamp_to_grid(p.x, nx),
        clamp_to_grid(p.y, ny),
        clamp_to_grid(p.z, nz),
    );
    // Through u32 (each coordinate is below its axis's size): x86-64's baseline converts
    // between f32 and u32 in one instruction, between f32 and usize in several.
    let (i, j, k) = (
        (x as u32).min(nx.saturating_sub(2) as u32),
        (y as u32).min(ny.saturating_sub(2) as u32),
        (z as u32).min(nz.saturating_sub(2) as u32),
    );
    let f = [x - i as f32, y - j as f32, z - k as f32];
    let (i, j, k) = (i as usize, j as usize, k as usize);
    (
        [i, j, k],
        [
            (i + 1).min(nx - 1),
            (j + 1).min(ny - 1),
            (k + 1).min(nz - 1),
        ],
        f,
    )
}

/// `a + (b − a)·w`.
#[inline(always)]
fn lerp<T>(a: T, b: T, w: f32) -> T
where
    T: Copy
        + std::ops::Add<Output = T>
        + std::ops::Sub<Output = T>
        + std::ops::Mul<f32, Output = T>,
{
    a + (b - a) * w
}

/// `x.clamp(0.0, (n − 1) as f32)`, bit for bit (NaN stays NaN, −0 stays −0), for a grid of
/// `n` ≥ 1 points along an axis: written out, since `f32::clamp` is a function of the
/// standard library's that the compiler may leave out of line in an x86-64-v3 copy.
#[inline(always)]
pub fn clamp_to_grid(x: f32, n: usize) -> f32 {
    let hi = (n - 1) as f32;
    let x = if x < 0.0 { 0.0 } else { x };
    if x > hi { hi } else { x }
}
