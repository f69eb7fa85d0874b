//! Keeping one of rayon's worker threads awake while a training loop runs.
//!
//! A training step on the CPU is hundreds of short parallel passes separated by short
//! serial ones (burn's bookkeeping, small operations). Between two passes rayon's idle
//! worker goes to sleep, and waking it for the next pass takes longer than many of these
//! passes last, so the calling thread ran most of the short ones alone. [`KeepAwake`] keeps
//! one worker looking for work ([`rayon::yield_now`]) instead of sleeping, until it is
//! dropped; that worker burns its core meanwhile, which a training loop uses anyway.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use burn::tensor::Device;

/// While alive, one worker of the current rayon pool spins looking for work instead of
/// sleeping. Dropping it lets the worker go back to sleeping.
///
/// The spinning worker runs a job of the pool, so the pool's other threads, the caller's
/// included, still find their own work done by it: nothing waits on the spinner.
#[derive(Debug)]
pub struct KeepAwake {
    stop: Arc<AtomicBool>,
}

impl KeepAwake {
    /// Starts the spinning worker when `device` is flex, whose operations run on rayon's
    /// threads (on other devices, or a pool of one thread, the guard does nothing).
    pub fn on(device: &Device) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        if *device == Device::flex() && rayon::current_num_threads() > 1 {
            let origin = rayon::current_thread_index();
            let flag = stop.clone();
            rayon::spawn(move || {
                // Run by the thread that spawned it (it took its own job back while waiting):
                // spinning there would keep it from ever reaching the code that stops it.
                if origin.is_some() && rayon::current_thread_index() == origin {
                    return;
                }
                while !flag.load(Ordering::Relaxed) {
                    if rayon::yield_now() != Some(rayon::Yield::Executed) {
                        std::hint::spin_loop();
                    }
                }
            });
        }
        KeepAwake { stop }
    }
}

impl Drop for KeepAwake {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use rayon::prelude::*;

    use super::*;

    /// Waits until only `stop`'s holder is left (the spinner has returned), for at most 10 s.
    fn spinner_ended(stop: &Arc<AtomicBool>) -> bool {
        let start = Instant::now();
        while Arc::strong_count(stop) > 1 {
            if start.elapsed() > Duration::from_secs(10) {
                return false;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        true
    }

    /// With a worker kept awake, parallel work (joins, nested guards, work from outside the
    /// pool) completes with the right values, and the spinner returns once the guard is
    /// dropped; on another device nothing spins.
    #[test]
    fn work_completes_and_the_spinner_stops() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("a pool");
        let flex = Device::flex();
        let stop = pool.install(|| {
            let awake = KeepAwake::on(&flex);
            let inner = KeepAwake::on(&flex);
            for n in [10u64, 1_000, 100_000] {
                let sum: u64 = (0..n).into_par_iter().sum();
                assert_eq!(sum, n * (n - 1) / 2);
                let (a, b) = rayon::join(|| n + 1, || n + 2);
                assert_eq!((a, b), (n + 1, n + 2));
            }
            let inner_stop = inner.stop.clone();
            drop(inner);
            assert!(spinner_ended(&inner_stop), "the inner spinner returned");
            awake.stop.clone()
        });
        assert!(spinner_ended(&stop), "the spinner returned after the drop");
        // Started from outside the pool (the test thread): the same.
        let outside = pool.install(|| (0..100u64).into_par_iter().sum::<u64>());
        assert_eq!(outside, 4950);
        #[allow(deprecated)] // burn's other CPU backend: any device but flex will do.
        let ndarray = KeepAwake::on(&Device::ndarray());
        assert_eq!(Arc::strong_count(&ndarray.stop), 1, "no spinner off flex");
    }
}
