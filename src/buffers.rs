//! Large buffers on transparent huge pages.
//!
//! Memory fresh from the kernel is faulted in and zeroed page by page on first
//! write. For the tens of megabytes of a 12 MP frame that is expensive in
//! 4 KiB pages, and more so on virtual machines that hand freed memory back to
//! the host. Measured on the 2-core machine, one thread: allocating and filling
//! 36 MB took 14 ms in 4 KiB pages and 2 ms in 2 MiB pages. These helpers
//! advise a large allocation onto huge pages (Linux, `MADV_HUGEPAGE`) before
//! anything touches it; elsewhere, or for small buffers, they are plain vectors.

/// Transparent huge page size on x86-64 and most aarch64 kernels.
const HUGE_PAGE: usize = 2 << 20;

/// Advise the whole huge pages inside `v`'s allocation (capacity, not only
/// length) onto transparent huge pages. Call it before the memory is touched:
/// pages already faulted in stay as they are.
fn advise_huge<T>(v: &mut Vec<T>) {
    let bytes = v.capacity().saturating_mul(std::mem::size_of::<T>());
    if bytes < 2 * HUGE_PAGE {
        return;
    }
    #[cfg(target_os = "linux")]
    {
        let start = v.as_mut_ptr() as usize;
        let first = start.next_multiple_of(HUGE_PAGE);
        let end = (start + bytes) / HUGE_PAGE * HUGE_PAGE;
        if end > first {
            // SAFETY: the range lies inside the vector's allocation; the advice only
            // changes how the kernel backs those pages (an error is harmless and ignored).
            unsafe {
                libc::madvise(first as *mut libc::c_void, end - first, libc::MADV_HUGEPAGE);
            }
        }
    }
}

/// `n` zero (default) values. A large zeroed allocation comes untouched from
/// the kernel, so the advice takes effect before the first write.
pub fn zeroed<T: Copy + Default>(n: usize) -> Vec<T> {
    let mut v = vec![T::default(); n];
    advise_huge(&mut v);
    v
}

/// An empty vector with room for `cap` values, for writers that append (encoders).
pub fn with_capacity<T>(cap: usize) -> Vec<T> {
    let mut v = Vec::with_capacity(cap);
    advise_huge(&mut v);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_have_the_asked_size_and_contents() {
        for n in [0, 1, 1000, 5 << 20] {
            let z: Vec<u16> = zeroed(n);
            assert_eq!(z.len(), n);
            assert!(z.iter().all(|&v| v == 0));
            let mut c: Vec<u8> = with_capacity(n);
            assert!(c.is_empty() && c.capacity() >= n);
            c.extend(std::iter::repeat_n(7u8, n));
            assert_eq!(c.len(), n);
            assert!(c.iter().all(|&v| v == 7));
        }
    }
}
