//! The per-thread buffers a tile works in.

thread_local! {
    /// Each thread's tile buffers (a band that finds them in use makes its own).
    pub(super) static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// Reusable per-thread buffers.
#[derive(Default)]
pub(super) struct Scratch {
    /// The tile and its halo, clamped volts.
    pub(super) buf: Vec<f32>,
    /// Per buffer row, the horizontal sums over the patch's even and odd
    /// column offsets, and the horizontal maxima.
    pub(super) he: Vec<f32>,
    pub(super) ho: Vec<f32>,
    pub(super) hmax: Vec<f32>,
    /// One output row's work.
    pub(super) row: RowScratch,
}

/// The buffers of one output row of a tile.
#[derive(Default)]
pub(super) struct RowScratch {
    pub(super) sums: [Vec<f32>; 4],
    pub(super) means: [Vec<f32>; 4],
    pub(super) lum: Vec<f32>,
    pub(super) contrast: Vec<f32>,
    pub(super) sat: Vec<bool>,
    pub(super) class: Vec<u32>,
    /// Per pixel, where its kernels start in the AVX-512 layout.
    pub(super) offsets: Vec<u32>,
    pub(super) lin: [Vec<f32>; 3],
    pub(super) patch: Vec<f32>,
    pub(super) feat: Vec<f32>,
    pub(super) chroma: ChromaScratch,
}

/// A tile row's chroma classes ([`FastRenderer::chroma_row`](super::FastRenderer::chroma_row)).
#[derive(Default)]
pub(super) struct ChromaScratch {
    /// Channel means per channel (clamped at 0), from the phase means.
    pub(super) means: Vec<Vec<f32>>,
    pub(super) score: Vec<f32>,
    /// Each pixel's score scale (see [`CHROMA_MARGIN`](super::CHROMA_MARGIN)).
    pub(super) scale: Vec<f32>,
    /// The lowest and second-lowest class score, and the lowest's class.
    pub(super) s1: Vec<f32>,
    pub(super) s2: Vec<f32>,
    pub(super) best: Vec<u32>,
}

/// Grow `v` to at least `n` values (never shrinks: tiles of different widths reuse it;
/// callers use the first `n`).
pub(super) fn resize(v: &mut Vec<f32>, n: usize) {
    if v.len() < n {
        v.resize(n, 0.0);
    }
}
