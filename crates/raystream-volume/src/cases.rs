//! The marching-cubes case table, generated rather than typed in.
//!
//! For each of the 256 inside/outside patterns of a cell's corners, the surface inside the cell
//! is built from its boundary: on every face, the isoline segments join the face's edge
//! crossings; segments chain into closed loops across faces; each loop is fanned into
//! triangles. A face with alternating corners (the ambiguous case) always separates its inside
//! corners — a rule that looks at that face only, so the two cells sharing a face build the same
//! segments there, and the surface has no cracks. Segments run from the crossing that enters
//! the inside region to the one that leaves it, walking each face counter-clockwise seen from
//! outside the cell; a crossing edge is walked in opposite directions by its two faces, so every
//! crossing ends one segment and starts the next and the loops close, all oriented alike.
//!
//! Corner `c` of a cell is at offset `(c & 1, c >> 1 & 1, c >> 2 & 1)`; edge `e` (0..12) runs
//! along axis `e / 4` from corner [`EDGE_START`]`[e]`.

use std::sync::LazyLock;

/// Corner each edge starts at (the other end is that corner plus the edge's axis).
pub const EDGE_START: [u8; 12] = {
    let mut out = [0u8; 12];
    let mut e = 0;
    while e < 12 {
        let axis = e / 4;
        let k = e % 4;
        // The two bits of the other axes, in axis order, take k's bits.
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let (lo, hi) = if u < v { (u, v) } else { (v, u) };
        out[e] = (((k & 1) << lo) | ((k >> 1) << hi)) as u8;
        e += 1;
    }
    out
};

/// The edge between two corners that differ in one bit.
fn edge_between(a: u8, b: u8) -> u8 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    let axis = (hi ^ lo).trailing_zeros() as usize;
    (0..4)
        .map(|k| (axis * 4 + k) as u8)
        .find(|&e| EDGE_START[e as usize] == lo)
        .expect("corners differ in one bit")
}

/// Triangles (edge-index triples) of every case, wound so that the geometric normal points from
/// the inside (values ≥ iso) to the outside.
pub static CASES: LazyLock<Vec<Vec<[u8; 3]>>> = LazyLock::new(|| (0..256).map(case).collect());

fn case(mask: usize) -> Vec<[u8; 3]> {
    let inside = |c: u8| mask >> c & 1 == 1;
    // next[e] = the crossing edge that follows crossing edge e along its loop.
    let mut next = [u8::MAX; 12];
    for axis in 0..3usize {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in 0..2u8 {
            // Counter-clockwise around +axis is (0,0),(1,0),(1,1),(0,1) in (u, v); seen from
            // outside the −axis face, that order is reversed.
            let mut ring: Vec<u8> = [(0, 0), (1, 0), (1, 1), (0, 1)]
                .iter()
                .map(|&(a, b)| (side << axis) | (a << u) | (b << v))
                .collect();
            if side == 0 {
                ring.reverse();
            }
            // Crossings in ring order: (edge, enters the inside?).
            let crossings: Vec<(u8, bool)> = (0..4)
                .filter_map(|i| {
                    let (a, b) = (ring[i], ring[(i + 1) % 4]);
                    (inside(a) != inside(b)).then(|| (edge_between(a, b), inside(b)))
                })
                .collect();
            let n = crossings.len();
            for i in 0..n {
                let (e, enters) = crossings[i];
                if enters {
                    // The leaving crossing after it closes off the inside corner(s) between.
                    let (f, _) = crossings[(i + 1) % n];
                    next[e as usize] = f;
                }
            }
        }
    }
    let mut tris = Vec::new();
    let mut seen = [false; 12];
    for start in 0..12u8 {
        if next[start as usize] == u8::MAX || seen[start as usize] {
            continue;
        }
        let mut lp = vec![start];
        seen[start as usize] = true;
        let mut e = next[start as usize];
        while e != start {
            seen[e as usize] = true;
            lp.push(e);
            e = next[e as usize];
        }
        tris.extend(fan(&lp));
    }
    tris
}

/// The two faces (axis, side) an edge lies on.
fn faces_of(e: u8) -> [(usize, u8); 2] {
    let axis = e as usize / 4;
    let c = EDGE_START[e as usize];
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    [(u, c >> u & 1), (v, c >> v & 1)]
}

fn share_face(a: u8, b: u8) -> bool {
    faces_of(a).iter().any(|f| faces_of(b).contains(f))
}

/// Fans a loop from an apex whose diagonals all cross the cell's interior: a diagonal between
/// two crossings on one face would also be a diagonal of the neighbour cell across that face,
/// and four triangles would meet at that edge.
fn fan(lp: &[u8]) -> Vec<[u8; 3]> {
    let n = lp.len();
    let apex = (0..n)
        .find(|&a| (2..n - 1).all(|d| !share_face(lp[a], lp[(a + d) % n])))
        .unwrap_or_else(|| panic!("no interior fan for loop {lp:?}"));
    (1..n - 1)
        .map(|i| [lp[apex], lp[(apex + i) % n], lp[(apex + i + 1) % n]])
        .collect()
}
