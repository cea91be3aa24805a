//! Order-keeping passes over large queues, run in parallel: joining parts into one vector, and
//! splitting items into two. Each gives what the plain serial loop gives, items in their
//! order, with every part copied by a task of its own. The kd-tree build joins its large
//! nodes' partitioned runs with them, and the CPU renderer its queues (`raystream-cpu`).
//!
//! Written here rather than through rayon's `par_extend` or `partition`: those collect
//! unindexed iterators into a list of vectors and then copy them into the target one after
//! another, a serial copy that no number of cores shortens (on the CPU renderer's frame, 5 %
//! of it on 2 threads and about a third by arithmetic on 16: BENCHMARKS.md, 2026-12-05).

use std::mem::MaybeUninit;

use rayon::prelude::*;

/// Items a run of [`split_into`] takes.
pub const RUN: usize = 1 << 13;

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
fn fill_runs<T, I>(out: &mut Vec<T>, lens: &[usize], items: impl Fn(usize) -> I + Sync)
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
pub fn concat_into<'a, T: Copy + Send + Sync + 'a>(
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
pub fn split_into<Y: Send, N: Send>(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joining_and_splitting_keep_order() {
        let mut rng = crate::tests::Rng(7);
        for n in [0, 1, RUN - 1, RUN, RUN + 1, 5 * RUN + 17] {
            let items: Vec<u64> = (0..n).map(|_| (rng.next() * 1000.0) as u64).collect();
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
}
