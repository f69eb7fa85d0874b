//! Per-thread scratch buffers for the convolutions' patch matrices (im2col blocks).
//!
//! A patch matrix is rebuilt for every block of texels or pixels and every element of it is
//! written before it is read, so it need not start cleared. Allocating it anew each call
//! cleared it anyway (`vec![0.0; n]`) and touched cold memory: in a profile of the `quick`
//! training step, clearing BTR's patch blocks was as much as a third of the time spent
//! copying into them. [`Scratch`] hands out the thread's last buffer instead, already in its
//! cache, and takes it back when dropped.

use std::cell::Cell;
use std::ops::{Deref, DerefMut};

thread_local! {
    /// The largest buffer returned on this thread and not yet handed out again.
    static POOL: Cell<Vec<f32>> = const { Cell::new(Vec::new()) };
}

/// `len` floats whose values are left over from earlier use (zeros when fresh): the user
/// must write every element before reading it. Returned to its thread's pool when dropped.
///
/// A second `Scratch` taken on a thread while one is held there (rayon may run another task
/// on a thread that waits inside a parallel GEMM) gets a buffer of its own; the pool keeps
/// the larger of the two.
#[derive(Debug)]
pub(crate) struct Scratch {
    buf: Vec<f32>,
    len: usize,
}

impl Scratch {
    /// A buffer of `len` floats (see the type's docs for its contents).
    pub(crate) fn new(len: usize) -> Self {
        if len == 0 {
            return Scratch {
                buf: Vec::new(),
                len,
            };
        }
        let mut buf = POOL.with(Cell::take);
        if buf.len() < len {
            buf.resize(len, 0.0);
        }
        Scratch { buf, len }
    }
}

impl Deref for Scratch {
    type Target = [f32];

    fn deref(&self) -> &[f32] {
        &self.buf[..self.len]
    }
}

impl DerefMut for Scratch {
    fn deref_mut(&mut self) -> &mut [f32] {
        &mut self.buf[..self.len]
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let buf = std::mem::take(&mut self.buf);
        // `try_with`: a thread that is exiting has no pool left; the buffer is then freed.
        let _ = POOL.try_with(|pool| {
            let held = pool.take();
            pool.set(if held.len() >= buf.len() { held } else { buf });
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_buffer_is_reused_and_nested_ones_are_separate() {
        let first_ptr = {
            let mut a = Scratch::new(100);
            a.fill(7.0);
            // Held while another is taken: the second is its own buffer.
            let mut b = Scratch::new(50);
            b.fill(1.0);
            assert!(a.iter().all(|&v| v == 7.0));
            assert_eq!((a.len(), b.len()), (100, 50));
            a.as_ptr()
        };
        // Both were returned; the pool kept the larger, and hands it out again.
        let c = Scratch::new(80);
        assert_eq!(c.len(), 80);
        assert_eq!(c.as_ptr(), first_ptr);
        assert!(
            c.iter().all(|&v| v == 7.0),
            "contents are left over, not cleared"
        );
        drop(c);
        // A larger request grows the buffer; its new part starts at zero.
        let d = Scratch::new(200);
        assert_eq!(d.len(), 200);
        assert!(d[..100].iter().all(|&v| v == 7.0));
        assert!(d[100..].iter().all(|&v| v == 0.0));
    }
}
