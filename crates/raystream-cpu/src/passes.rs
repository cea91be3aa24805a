//! The renderer's order-keeping passes over its queues, run in parallel: joining runs of items
//! into one queue, splitting a queue in two, and adding contributions to the film. Each gives
//! what the plain serial loop gives, bit for bit: items keep their order, and a pixel's
//! contributions are added in queue order.
//!
//! These passes were serial: about 66 ms of a 1.2 s frame on 2 threads (the default scene at
//! 960×540, BENCHMARKS.md), which no number of cores shortens, and a third of the frame at
//! 16. Written here rather than through rayon's `par_extend` or `partition`: those collect
//! into a list of vectors and then copy them into the target one after another, the serial
//! copy these passes are meant to remove.

use std::mem::MaybeUninit;

use rayon::prelude::*;
use raystream_math::Vec3;

/// Items a run of a pass takes, at most (film passes end a run at a pixel's last item).
pub(crate) const RUN: usize = 1 << 13;

/// `out` cleared and made room for `lens`' sum of items, and its spare memory cut into parts
/// of those lengths, in order.
fn parts_of<'a, T>(out: &'a mut Vec<T>, lens: &[usize]) -> Vec<&'a mut [MaybeUninit<T>]> {
    let total: usize = lens.iter().sum();
    out.clear();
    out.reserve(total);
    let mut parts = Vec::with_capacity(lens.len());
    let mut rest = &mut out.spare_capacity_mut()[..total];
    for &len in lens {
        let (part, tail) = std::mem::take(&mut rest).split_at_mut(len);
        parts.push(part);
        rest = tail;
    }
    parts
}

/// Sets `out`'s length to `total` once [`parts_of`]'s parts are written.
///
/// # Safety
/// Every part of `parts_of(out, lens)`, `lens` summing to `total`, was written in full.
unsafe fn written<T>(out: &mut Vec<T>, total: usize) {
    debug_assert!(total <= out.capacity());
    // SAFETY: the parts cover the first `total` slots (the caller's promise).
    unsafe { out.set_len(total) };
}

/// Fills `out` (cleared first, its memory kept) with runs of items, in order: run `r` yields
/// `lens[r]` items through `items(r)`, and the runs are written in parallel, each into its own
/// part of `out`. Panics if a run yields another number of items than `lens` says.
pub(crate) fn fill_runs<T, I>(out: &mut Vec<T>, lens: &[usize], items: impl Fn(usize) -> I + Sync)
where
    T: Send,
    I: Iterator<Item = T>,
{
    parts_of(out, lens)
        .into_par_iter()
        .enumerate()
        .for_each(|(r, part)| {
            let mut it = items(r);
            for slot in part.iter_mut() {
                let item = it.next().expect("a run yields the items it counted");
                slot.write(item);
            }
            assert!(it.next().is_none(), "a run yields the items it counted");
        });
    // SAFETY: every part was written in full (a run that fell short panicked above).
    unsafe { written(out, lens.iter().sum()) };
}

/// Joins the items `part(r)` of `count` parts into `out` (cleared first), in order.
pub(crate) fn concat_into<'a, T: Copy + Send + Sync + 'a>(
    out: &mut Vec<T>,
    count: usize,
    part: impl Fn(usize) -> &'a [T] + Sync,
) {
    let lens: Vec<usize> = (0..count).map(|r| part(r).len()).collect();
    fill_runs(out, &lens, |r| part(r).iter().copied());
}

/// Splits items `0..len` into `yes` and `no` (each cleared first) by `pick`: item `i` goes
/// into `yes` where `pick(i)` is `Ok`, into `no` where it is `Err`, each in the order of `i`.
/// Two parallel passes: one counts each run's `Ok`s, one writes both queues.
pub(crate) fn split_into<Y: Send, N: Send>(
    len: usize,
    pick: impl Fn(usize) -> Result<Y, N> + Sync,
    yes: &mut Vec<Y>,
    no: &mut Vec<N>,
) {
    let run = |r: usize| r * RUN..((r + 1) * RUN).min(len);
    let runs = len.div_ceil(RUN);
    let ok: Vec<usize> = (0..runs)
        .into_par_iter()
        .map(|r| run(r).filter(|&i| pick(i).is_ok()).count())
        .collect();
    let err: Vec<usize> = (0..runs).map(|r| run(r).len() - ok[r]).collect();
    let short = "a run picks as it counted";
    parts_of(yes, &ok)
        .into_par_iter()
        .zip(parts_of(no, &err))
        .enumerate()
        .for_each(|(r, (y, n))| {
            let (mut ky, mut kn) = (0, 0);
            for i in run(r) {
                match pick(i) {
                    Ok(v) => {
                        y.get_mut(ky).expect(short).write(v);
                        ky += 1;
                    }
                    Err(v) => {
                        n.get_mut(kn).expect(short).write(v);
                        kn += 1;
                    }
                }
            }
            assert!(ky == y.len() && kn == n.len(), "{short}");
        });
    // SAFETY: every part was written in full (a run that picked otherwise panicked above).
    unsafe {
        written(yes, ok.iter().sum());
        written(no, len - ok.iter().sum::<usize>());
    }
}

/// Adds `len` contributions to `film`: item `i` adds `colour(i)` (where `Some`) to pixel
/// `pixel(i)`, each pixel's in the order of `i`, so the sums are a serial loop's, bit for bit.
/// Items in non-decreasing pixel order (checked in a first pass) go to [`add_sorted`], others
/// are added serially.
pub(crate) fn add_to_film(
    film: &mut [Vec3],
    len: usize,
    pixel: impl Fn(usize) -> u32 + Sync,
    colour: impl Fn(usize) -> Option<Vec3> + Sync,
) {
    if (1..len).into_par_iter().all(|i| pixel(i - 1) <= pixel(i)) {
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
pub(crate) fn add_sorted(
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

    /// A deterministic stream of numbers for the tests.
    fn numbers(seed: u64) -> impl FnMut() -> u64 {
        let mut x = seed;
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        }
    }

    #[test]
    fn joining_and_splitting_keep_order() {
        let mut next = numbers(7);
        for n in [0, 1, RUN - 1, RUN, RUN + 1, 5 * RUN + 17] {
            let items: Vec<u64> = (0..n).map(|_| next() % 1000).collect();
            let (mut yes, mut no) = (vec![5u64; 3], vec![9u32; 2]);
            let pick = |i: usize| match items[i] {
                x if x % 3 == 0 => Ok(x),
                x => Err(x as u32),
            };
            split_into(items.len(), pick, &mut yes, &mut no);
            let want_yes: Vec<u64> = items.iter().copied().filter(|x| x % 3 == 0).collect();
            let want_no: Vec<u32> = items
                .iter()
                .filter(|x| *x % 3 != 0)
                .map(|x| *x as u32)
                .collect();
            assert_eq!((yes, no), (want_yes, want_no), "{n} items");

            let parts: Vec<&[u64]> = items.chunks(RUN / 3 + 1).collect();
            let mut joined = vec![1, 2, 3];
            concat_into(&mut joined, parts.len(), |r| parts[r]);
            assert_eq!(joined, items, "{n} items joined");
        }
    }

    #[test]
    #[should_panic(expected = "a run yields the items it counted")]
    fn a_run_that_yields_too_few_items_panics() {
        let mut out: Vec<u32> = Vec::new();
        fill_runs(&mut out, &[3, 4], |r| 0..(3 + r as u32 - 1));
    }

    #[test]
    fn film_sums_are_the_serial_loops_bit_for_bit() {
        // Sorted runs of a pixel longer than RUN, pixels skipped, items without colour, and
        // an unsorted queue (added serially): the sums must be the serial loop's exactly, in
        // its order (float addition is not associative, so another order shows).
        let mut next = numbers(11);
        let mut unit = move || (next() >> 40) as f32 / (1u64 << 24) as f32;
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
            add_to_film(&mut got, pixels.len(), |i| pixels[i], |i| colours[i]);
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
        add_sorted(&mut film, pixels.len(), |i| pixels[i], |_| Some(Vec3::ONE));
    }
}
