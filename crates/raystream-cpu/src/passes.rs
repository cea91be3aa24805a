//! The renderer's film adds, run in parallel: each pixel's contributions added in queue order,
//! so the sums are a serial loop's, bit for bit. (Its queues are joined and split by
//! `raystream_accel::par`.) Serial, the film adds were about 13 ms of a 1.2 s frame on 2
//! threads (the default scene at 960×540, BENCHMARKS.md), which no number of cores shortens.

use rayon::prelude::*;
use raystream_accel::par::RUN;
use raystream_math::Vec3;

/// Adds `len` contributions to `film`: item `i` adds `colour(i)` (where `Some`) to pixel
/// `pixel(i)`, each pixel's in the order of `i`, so the sums are a serial loop's, bit for bit.
/// Items in non-decreasing pixel order go to [`add_sorted`], others are added serially; the
/// order is checked in a first pass unless the caller vouches for it (`in_order`: the
/// renderer's queues, built in pixel order).
pub(crate) fn add_to_film(
    film: &mut [Vec3],
    len: usize,
    in_order: bool,
    pixel: impl Fn(usize) -> u32 + Sync,
    colour: impl Fn(usize) -> Option<Vec3> + Sync,
) {
    if in_order || (1..len).into_par_iter().all(|i| pixel(i - 1) <= pixel(i)) {
        add_sorted(film, len, pixel, colour);
    } else {
        add_run(film, 0..len, 0, &pixel, &colour);
    }
}

/// [`add_to_film`] of items in non-decreasing pixel order, as the renderer's queues are
/// (camera rays are pixel-major, and every stage keeps its queues' order), in one parallel
/// pass: runs of about [`RUN`] items that end at a pixel's last item, each into its own
/// pixels. Items out of order either panic or, where no other run has their pixel, still add
/// as the serial loop does (a run adds its items in their order): never another sum.
fn add_sorted(
    film: &mut [Vec3],
    len: usize,
    pixel: impl Fn(usize) -> u32 + Sync,
    colour: impl Fn(usize) -> Option<Vec3> + Sync,
) {
    if len <= RUN {
        add_run(film, 0..len, 0, &pixel, &colour);
        return;
    }
    // Each run's items and its pixels, a part of the film of their own. Runs end every RUN
    // items, moved on past the rest of that pixel's items.
    let mut parts = Vec::with_capacity(len / RUN + 1);
    let (mut rest, mut rest_first, mut start) = (film, 0usize, 0usize);
    while start < len {
        let mut end = (start + RUN).min(len);
        while end < len && pixel(end) == pixel(end - 1) {
            end += 1;
        }
        let (lo, hi) = (pixel(start) as usize, pixel(end - 1) as usize + 1);
        let skip = lo.checked_sub(rest_first).expect(ORDER);
        let (_, from_lo) = std::mem::take(&mut rest).split_at_mut(skip);
        let (part, tail) = from_lo.split_at_mut(hi.checked_sub(lo).expect(ORDER));
        parts.push((start..end, part, lo));
        (rest, rest_first, start) = (tail, hi, end);
    }
    parts
        .into_par_iter()
        .for_each(|(items, part, first)| add_run(part, items, first, &pixel, &colour));
}

const ORDER: &str = "contributions in pixel order";

/// Adds items `items` to `film`, whose first entry is pixel `first`, in order.
#[inline]
fn add_run(
    film: &mut [Vec3],
    items: std::ops::Range<usize>,
    first: usize,
    pixel: &impl Fn(usize) -> u32,
    colour: &impl Fn(usize) -> Option<Vec3>,
) {
    for i in items {
        if let Some(c) = colour(i) {
            let at = (pixel(i) as usize).checked_sub(first).expect(ORDER);
            *film.get_mut(at).expect(ORDER) += c;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn film_sums_are_the_serial_loops_bit_for_bit() {
        // Sorted runs of a pixel longer than RUN, pixels skipped, items without colour, and
        // an unsorted queue (added serially): the sums must be the serial loop's exactly, in
        // its order (float addition is not associative, so another order shows).
        let mut rng = crate::tests::XorShift(11);
        let mut unit = move || rng.f32();
        for sorted in [true, false] {
            let mut pixels: Vec<u32> = Vec::new();
            let mut p = 0;
            while pixels.len() < 12 * RUN {
                let repeat = if unit() < 0.01 {
                    3 * RUN
                } else {
                    1 + (unit() * 9.0) as usize
                };
                pixels.extend(std::iter::repeat_n(p, repeat));
                p += 1 + (unit() * 3.0) as u32;
            }
            if !sorted {
                pixels.swap(10, 9 * RUN);
            }
            let colours: Vec<Option<Vec3>> = pixels
                .iter()
                .map(|_| (unit() > 0.2).then(|| Vec3::new(unit(), 1e7 * unit(), 1e-7 * unit())))
                .collect();
            let mut want = vec![Vec3::splat(0.25); p as usize + 5];
            for (&px, c) in pixels.iter().zip(&colours) {
                if let Some(c) = c {
                    want[px as usize] += *c;
                }
            }
            let mut got = vec![Vec3::splat(0.25); p as usize + 5];
            add_to_film(&mut got, pixels.len(), false, |i| pixels[i], |i| colours[i]);
            let bits = |f: &[Vec3]| -> Vec<[u32; 3]> {
                f.iter().map(|c| c.to_array().map(f32::to_bits)).collect()
            };
            assert_eq!(bits(&got), bits(&want), "sorted: {sorted}");
        }
    }

    #[test]
    #[should_panic(expected = "contributions in pixel order")]
    fn sorted_adds_of_items_out_of_order_panic() {
        // Pixel 0 in the first run and again in the last: the runs' pixels overlap.
        let pixels: Vec<u32> = (0..3 * RUN as u32).map(|i| i / 2).chain([0]).collect();
        let mut film = vec![Vec3::ZERO; 2 * RUN];
        add_to_film(
            &mut film,
            pixels.len(),
            true,
            |i| pixels[i],
            |_| Some(Vec3::ONE),
        );
    }
}
