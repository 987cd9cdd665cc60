//! Bounded joins of the threads a daemon starts (issue 35): at shutdown
//! every thread is waited for at most a stated time, then left behind (it
//! ends with the process) and named, never waited for without bound.

use std::sync::Mutex;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The threads [`join_within`] left behind, by name, in the order they were
/// given up on.
static LEFT_BEHIND: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// How often [`join_within`] looks whether the thread has ended.
const POLL: Duration = Duration::from_millis(1);

/// Joins `handle` if its thread ends within `timeout`: `Some` with what
/// the thread returned (`Err`: it panicked). `None` when it did not end in
/// time: the thread is left behind (detached; it ends with the process) and
/// its name is kept for [`left_behind`].
pub fn join_within<T>(handle: JoinHandle<T>, timeout: Duration) -> Option<std::thread::Result<T>> {
    let start = Instant::now();
    while !handle.is_finished() {
        if start.elapsed() >= timeout {
            let name = handle
                .thread()
                .name()
                .map_or_else(|| format!("{:?}", handle.thread().id()), str::to_owned);
            if let Ok(mut list) = LEFT_BEHIND.lock() {
                list.push(format!(
                    "{name} (not ended within {} ms)",
                    timeout.as_millis()
                ));
            }
            return None;
        }
        std::thread::sleep(POLL);
    }
    Some(handle.join())
}

/// The threads left behind so far by [`join_within`] (what `sard` says at
/// its end).
pub fn left_behind() -> Vec<String> {
    LEFT_BEHIND.lock().map(|l| l.clone()).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A thread that ends is joined with its value; one that does not end
    /// in time is given up on after the timeout, and named.
    #[test]
    fn a_join_is_bounded_and_names_what_it_left_behind() {
        let done = std::thread::spawn(|| 7);
        assert_eq!(
            join_within(done, Duration::from_secs(5)).unwrap().unwrap(),
            7
        );
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let stuck = std::thread::Builder::new()
            .name("stuck-for-the-test".into())
            .spawn(move || {
                let _ = rx.recv();
            })
            .unwrap();
        let t = Instant::now();
        assert!(join_within(stuck, Duration::from_millis(50)).is_none());
        assert!(t.elapsed() >= Duration::from_millis(50));
        assert!(
            left_behind()
                .iter()
                .any(|n| n == "stuck-for-the-test (not ended within 50 ms)"),
            "{:?}",
            left_behind()
        );
        drop(tx);
    }
}
