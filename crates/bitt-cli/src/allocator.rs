//! The binary's memory allocator: mimalloc, told to keep the memory it frees.
//!
//! A training step allocates and frees many multi-megabyte tensor buffers. glibc's `malloc`
//! serves each from fresh `mmap` pages (a page fault per 4 KiB touched) and unmaps it on
//! free; mimalloc keeps freed segments for reuse. By default mimalloc still *purges* freed
//! memory one second after it is freed (its `purge_delay` option): the pages go back to
//! the kernel, which zeroes each one again when it is next touched. BTR at `paper` runs
//! operations of several seconds over 50-100 MB activations, so nearly every buffer was
//! purged and faulted in again: `bitt bench-nets btr --preset paper --runs 2` spent 26.5 s
//! in the kernel (44,459 page faults) by default and 8.2 s (4,227) without purging
//! (README, Networks). [`keep_freed_memory`] turns purging off; the process then keeps its
//! peak memory until it exits, which a training run reaches in its first step anyway.

/// mimalloc with the `purge_delay` set by [`keep_freed_memory`].
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// mimalloc's `mi_option_purge_delay` (the 16th entry of `mi_option_t` in mimalloc v3's
/// `include/mimalloc.h`; `libmimalloc-sys` has no constant for it). The test
/// `purge_delay_is_the_option_it_names` checks the index against the documented default.
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// The environment variable through which a user sets the purge delay themselves (read by
/// mimalloc when the process starts); when it is set, it is kept.
const PURGE_DELAY_VARIABLE: &str = "MIMALLOC_PURGE_DELAY";

/// Turns mimalloc's purging of freed memory off (`purge_delay = -1`), unless the user set
/// [`PURGE_DELAY_VARIABLE`].
#[allow(unsafe_code)]
pub(crate) fn keep_freed_memory() {
    if std::env::var_os(PURGE_DELAY_VARIABLE).is_none() {
        // SAFETY: `mi_option_set` stores a value in mimalloc's option table (an atomic
        // store); the option index is checked by the test below.
        unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
    }
}

/// The current purge delay in milliseconds (-1: never).
#[cfg(test)]
#[allow(unsafe_code)]
#[allow(clippy::useless_conversion)] // `c_long` is `i64` here but `i32` on other targets.
fn purge_delay() -> i64 {
    // SAFETY: `mi_option_get` reads mimalloc's option table.
    i64::from(unsafe { libmimalloc_sys::mi_option_get(MI_OPTION_PURGE_DELAY) })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Index 15 is the purge delay: mimalloc v3 documents its default as 1,000 ms and
    /// reads it from `MIMALLOC_PURGE_DELAY`; after [`keep_freed_memory`] it is -1.
    #[test]
    fn purge_delay_is_the_option_it_names() {
        match std::env::var(PURGE_DELAY_VARIABLE) {
            Ok(value) => assert_eq!(purge_delay().to_string(), value.trim()),
            Err(_) => {
                assert_eq!(purge_delay(), 1000, "mimalloc v3's default purge delay");
                keep_freed_memory();
                assert_eq!(purge_delay(), -1);
            }
        }
    }
}
