//! Output buffers of the fast renderer.
//!
//! A 12 MP sRGB frame is 36 MB. Memory fresh from the kernel costs far more
//! than rendering into it would suggest: every page is faulted in and zeroed on
//! first write, and on virtual machines that hand freed memory back to the host
//! (free page reporting) the host faults it in again as well. Two measures:
//!
//! - new buffers come from [`buffers::zeroed`](super::zeroed), which asks for
//!   transparent huge pages on large buffers (measured on one thread: 14 ms to allocate and fill
//!   36 MB in 4 KiB pages, 2 ms in 2 MiB pages);
//! - 8-bit frames come as a [`Frame`], which gives its buffer back to a small
//!   process-wide pool when dropped, so the next render writes into memory
//!   that is already mapped. The pool keeps at most [`KEEP_FRAMES`] buffers and
//!   [`KEEP_BYTES`] bytes; [`Frame::into_vec`] takes a buffer out for good.

use std::ops::{Deref, DerefMut};
use std::sync::{Mutex, PoisonError};

/// The most buffers the pool keeps.
pub const KEEP_FRAMES: usize = 4;
/// The most bytes the pool keeps, in all.
pub const KEEP_BYTES: usize = 256 << 20;
/// Smaller buffers are not pooled: the allocator serves them from memory it keeps anyway.
const POOL_MIN_BYTES: usize = 1 << 20;

/// Buffers given back by dropped frames, up to a count and a byte budget.
#[derive(Debug)]
pub struct FramePool {
    free: Mutex<Vec<Vec<u8>>>,
    keep_frames: usize,
    keep_bytes: usize,
}

/// The pool of the renderer's 8-bit frames.
static POOL: FramePool = FramePool::new(KEEP_FRAMES, KEEP_BYTES);

impl FramePool {
    const fn new(keep_frames: usize, keep_bytes: usize) -> FramePool {
        FramePool {
            free: Mutex::new(Vec::new()),
            keep_frames,
            keep_bytes,
        }
    }

    fn free(&self) -> std::sync::MutexGuard<'_, Vec<Vec<u8>>> {
        // a buffer list stays valid whatever a panicking holder did
        self.free.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// A buffer of `len` bytes: the smallest pooled one that holds them, else a new one.
    fn take(&'static self, len: usize) -> Frame {
        let pooled = if len >= POOL_MIN_BYTES {
            let mut free = self.free();
            free.iter()
                .enumerate()
                .filter(|(_, b)| b.capacity() >= len)
                .min_by_key(|(_, b)| b.capacity())
                .map(|(i, _)| i)
                .map(|i| free.swap_remove(i))
        } else {
            None
        };
        let buf = match pooled {
            Some(mut b) => {
                b.resize(len, 0);
                b
            }
            None => super::zeroed::<u8>(len),
        };
        Frame { buf, pool: self }
    }

    fn give_back(&self, buf: &mut Vec<u8>) {
        let cap = buf.capacity();
        if cap < POOL_MIN_BYTES {
            return;
        }
        let mut free = self.free();
        let held: usize = free.iter().map(Vec::capacity).sum();
        if free.len() < self.keep_frames && held + cap <= self.keep_bytes {
            free.push(std::mem::take(buf));
        }
    }

    /// Buffers the pool holds now, and their bytes in all.
    fn held(&self) -> (usize, usize) {
        let free = self.free();
        (free.len(), free.iter().map(Vec::capacity).sum())
    }
}

/// An 8-bit image buffer (interleaved, row-major) that returns to the pool
/// when dropped. Reads and writes as a `[u8]`.
///
/// A frame taken from the pool holds the bytes of an earlier image until the
/// renderer overwrites them; the renderer writes every byte.
#[derive(Debug)]
pub struct Frame {
    buf: Vec<u8>,
    pool: &'static FramePool,
}

impl Frame {
    /// A buffer of `len` bytes from the renderer's pool.
    pub(super) fn take(len: usize) -> Frame {
        POOL.take(len)
    }

    /// The bytes as a plain vector, leaving the pool for good.
    pub fn into_vec(mut self) -> Vec<u8> {
        std::mem::take(&mut self.buf)
    }

    /// Buffers the renderer's pool holds now, and their bytes in all.
    pub fn pooled() -> (usize, usize) {
        POOL.held()
    }
}

impl Drop for Frame {
    fn drop(&mut self) {
        self.pool.give_back(&mut self.buf);
    }
}

impl Deref for Frame {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        &self.buf
    }
}

impl DerefMut for Frame {
    fn deref_mut(&mut self) -> &mut [u8] {
        &mut self.buf
    }
}

impl AsRef<[u8]> for Frame {
    fn as_ref(&self) -> &[u8] {
        &self.buf
    }
}

impl From<Frame> for Vec<u8> {
    fn from(f: Frame) -> Vec<u8> {
        f.into_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pool(frames: usize, bytes: usize) -> &'static FramePool {
        Box::leak(Box::new(FramePool::new(frames, bytes)))
    }

    #[test]
    fn a_dropped_frame_is_reused_by_the_next_request_it_can_hold() {
        let p = pool(2, 64 << 20);
        let len = 3 * POOL_MIN_BYTES + 12_345;
        let mut a = p.take(len);
        assert_eq!(a.len(), len);
        assert!(a.iter().all(|&b| b == 0), "a new frame starts zeroed");
        a[len - 1] = 7;
        let ptr = a.as_ptr();
        drop(a);
        let (n, bytes) = p.held();
        assert_eq!(n, 1);
        assert!(bytes >= len);
        // a smaller request takes the pooled buffer, shortened
        let b = p.take(len - 100);
        assert_eq!(b.as_ptr(), ptr);
        assert_eq!(b.len(), len - 100);
        assert_eq!(p.held().0, 0);
        // a larger one than any pooled buffer gets a new one
        drop(b);
        let c = p.take(2 * len);
        assert_ne!(c.as_ptr(), ptr);
        assert_eq!(c.len(), 2 * len);
        assert_eq!(p.held().0, 1);
        // into_vec leaves the pool for good
        let v = c.into_vec();
        assert_eq!(v.len(), 2 * len);
        drop(v);
        assert_eq!(p.held().0, 1);
    }

    #[test]
    fn the_pool_keeps_at_most_its_limits_and_no_small_buffers() {
        let p = pool(3, 4 * POOL_MIN_BYTES);
        let frames: Vec<Frame> = (0..6).map(|_| p.take(POOL_MIN_BYTES + 4096)).collect();
        drop(frames);
        let (n, bytes) = p.held();
        assert_eq!(n, 3, "three buffers fit both limits");
        assert!(bytes <= 4 * POOL_MIN_BYTES);
        let p = pool(8, 2 * POOL_MIN_BYTES + 10);
        drop((0..4).map(|_| p.take(POOL_MIN_BYTES)).collect::<Vec<_>>());
        assert_eq!(p.held().0, 2, "the byte budget holds two");
        let p = pool(8, 64 << 20);
        drop(p.take(POOL_MIN_BYTES - 1));
        assert_eq!(p.held(), (0, 0), "a small buffer is not pooled");
    }
}
