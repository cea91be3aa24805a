//! A stage of work on a thread of its own: items handed to it in order are processed there
//! while the caller goes on (a frame's file encoded while the next frame renders), with at most
//! one item waiting, so that a long series is never held whole. Written by hand: a bounded
//! channel and one thread from the standard library are all it takes.

use std::sync::mpsc::{SyncSender, sync_channel};
use std::thread::JoinHandle;

/// What an item handed to a stage that has stopped on an error is told.
pub const STOPPED: &str = "stopped on an earlier item's error";

/// A stage's thread, holding its state `S` (an encoder, or nothing) and processing items `T`
/// one by one; [`Pipeline::finish`] gives the state back, or the first error.
pub struct Pipeline<T: Send + 'static, S: Send + 'static> {
    items: Option<SyncSender<T>>,
    thread: Option<JoinHandle<Result<S, String>>>,
}

impl<T: Send + 'static, S: Send + 'static> Pipeline<T, S> {
    /// Items waiting beyond the one being processed: one, so that the caller never waits for a
    /// stage that keeps up with it.
    const QUEUED: usize = 1;

    /// Starts the thread: `process(&mut state, item, i)` for the i-th item (from 0). The first
    /// error stops it; [`Pipeline::send`] or [`Pipeline::finish`] returns it.
    pub fn spawn(
        mut state: S,
        mut process: impl FnMut(&mut S, T, usize) -> Result<(), String> + Send + 'static,
    ) -> Self {
        let (tx, rx) = sync_channel::<T>(Self::QUEUED);
        let thread = std::thread::spawn(move || {
            for (i, item) in rx.into_iter().enumerate() {
                process(&mut state, item, i)?;
            }
            Ok(state)
        });
        Pipeline {
            items: Some(tx),
            thread: Some(thread),
        }
    }

    /// Hands the next item over, waiting while one is already waiting; the stage's error if it
    /// has stopped.
    pub fn send(&mut self, item: T) -> Result<(), String> {
        let Some(items) = self.items.as_ref() else {
            return Err(STOPPED.into());
        };
        match items.send(item) {
            Ok(()) => Ok(()),
            // The thread ended on an error: that error.
            Err(_) => self.finish().and(Err(STOPPED.into())),
        }
    }

    /// Waits for every item handed over to be processed; the state, or the first error.
    pub fn finish(&mut self) -> Result<S, String> {
        self.items = None;
        let Some(thread) = self.thread.take() else {
            return Err(STOPPED.into());
        };
        match thread.join() {
            Ok(r) => r,
            Err(_) => Err("the stage's thread panicked".into()),
        }
    }
}

impl<T: Send + 'static, S: Send + 'static> Drop for Pipeline<T, S> {
    /// Waits for the thread, so that nothing it writes outlives the owner.
    fn drop(&mut self) {
        let _ = self.finish();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn items_are_processed_in_order_and_the_state_comes_back() {
        let mut p = Pipeline::spawn(Vec::new(), |seen: &mut Vec<(usize, u32)>, x: u32, i| {
            seen.push((i, x));
            Ok(())
        });
        for x in [7, 3, 9, 1] {
            p.send(x).unwrap();
        }
        assert_eq!(p.finish().unwrap(), vec![(0, 7), (1, 3), (2, 9), (3, 1)]);
        assert_eq!(p.finish().unwrap_err(), STOPPED);
    }

    #[test]
    fn the_first_error_reaches_the_caller_and_stops_the_stage() {
        let mut p = Pipeline::spawn(0u32, |n: &mut u32, x: u32, i| {
            if x == 3 {
                return Err(format!("item {i}: three"));
            }
            *n += x;
            Ok(())
        });
        // The error comes back from a later send (once the thread has stopped) or finish.
        let e = (0..50)
            .map(|k| if k == 2 { 3 } else { 1 })
            .find_map(|x| p.send(x).err())
            .or_else(|| p.finish().err())
            .expect("the error is returned");
        assert_eq!(e, "item 2: three");
        assert_eq!(p.send(1).unwrap_err(), STOPPED);
        assert_eq!(p.finish().unwrap_err(), STOPPED);
    }
}
