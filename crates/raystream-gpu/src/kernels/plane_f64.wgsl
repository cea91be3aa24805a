// PLANE_T_WIDE: `plane_t` in f64, as the CPU's `plane_t_f64` computes it: the edges, the
// corner's offset from the origin and the normal's products are exact, only the sums round.
// A t beyond f32's range (a ray all but parallel to the plane) or NaN comes back as +inf, which
// the test rejects as the CPU does its infinity or NaN. (`t32`, the f32 t, is not needed here.)
fn plane_t_wide(x: vec3<f32>, y: vec3<f32>, z: vec3<f32>, w: Watertight, t32: f32) -> f32 {
    let xd = vec3<f64>(x);
    let yd = vec3<f64>(y);
    let zd = vec3<f64>(z);
    let e1 = vec3<f64>(xd.y - xd.x, yd.y - yd.x, zd.y - zd.x);
    let e2 = vec3<f64>(xd.z - xd.x, yd.z - yd.x, zd.z - zd.x);
    let n = vec3<f64>(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
    let o = vec3<f64>(w.o);
    let along = n.x * (xd.x - o.x) + n.y * (yd.x - o.y) + n.z * (zd.x - o.z);
    let facing = n.x * f64(w.shear.x) + n.y * f64(w.shear.y) + n.z;
    let t = f64(w.shear.z) * (along / facing);
    if !(abs(t) <= f64(3.4028234663852886e38)) {
        return bitcast<f32>(0x7f800000u);
    }
    return f32(t);
}
// END PLANE_T_WIDE
