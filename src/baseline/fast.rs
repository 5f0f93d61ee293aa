//! The baseline in one pass: bilinear demosaic of every channel, the colour matrix and, for
//! 8-bit output, the sRGB encoding, fused over strips of rows run in parallel.
//!
//! [`render_baseline`](super::render_baseline) runs the steps one after another over whole
//! frames: [`bilinear_demosaic`](super::bilinear_demosaic) looks up every neighbour's CFA
//! channel for every pixel and channel, then [`ColourMatrix::apply`] makes a second pass, a
//! few Mpix/s. Here which neighbours each channel is averaged over is worked out once per
//! CFA position ([`Plan`]). On a CFA whose tile is at most 2×2 (Bayer, RGBW) every channel
//! has a neighbour in each pixel's 3×3 window; each row is split into its even and odd
//! columns, so that every average is a sum of whole shifted slices and the matrix a few
//! multiply-adds over slices, loops the compiler vectorises (with AVX2 where the CPU has
//! it). Larger tiles take a per-pixel path over a padded frame with the same arithmetic.
//!
//! Each value is the same sum of the same neighbours in the same order divided by the same
//! count, and the matrix adds the channels in the same order, so the output is the
//! straightforward path's bit for bit (the tests compare the two; the 8-bit path encodes with
//! [`linear_srgb_matrix`] and [`SrgbLut`] as [`xyz_to_srgb8`](crate::l3::render::xyz_to_srgb8)
//! does). It is written here because no crate demosaics an arbitrary CFA (RGBW) in f32 with
//! the baseline's average.

use rayon::prelude::*;

use super::{BaselineError, ColourMatrix, check_frame, check_matrix};
use crate::camera::Cfa;
use crate::colour::SrgbLut;
use crate::l3::classify::mirror;
use crate::l3::render::linear_srgb_matrix;

/// Output rows per parallel task.
const STRIP_ROWS: usize = 8;

/// [`render_baseline`](super::render_baseline) in one pass: bilinear demosaic then
/// XYZ = M · channels, interleaved XYZ out, bit for bit the same. Errors as it does: a
/// matrix that does not fit the CFA, a frame whose size does not match its values, a
/// non-finite output value.
pub fn render_baseline_fused(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
    m: &ColourMatrix,
) -> Result<Vec<f32>, BaselineError> {
    render(volts, width, height, cfa, m, &XyzOut, simd_available())
}

/// [`render_baseline_fused`] encoded as 8-bit sRGB with Y = `white_y` as white: the bytes
/// [`xyz_to_srgb8`](crate::l3::render::xyz_to_srgb8) makes of its XYZ, without the XYZ frame.
pub fn render_baseline_fused_srgb8(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
    m: &ColourMatrix,
    white_y: f64,
) -> Result<Vec<u8>, BaselineError> {
    let sink = Srgb8Out {
        m: linear_srgb_matrix(white_y),
        lut: SrgbLut::new(),
    };
    render(volts, width, height, cfa, m, &sink, simd_available())
}

fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// How one channel is had at one CFA position: the pixel's own value, or the mean of the
/// neighbours at these offsets `(dy, dx)`, summed in this order (none: 0).
#[derive(Clone, Debug, PartialEq)]
enum Source {
    Own,
    Mean(Vec<(isize, isize)>),
}

/// Per CFA tile position, per channel, its [`Source`], as [`super::bilinear_demosaic`]
/// chooses it: the channel's pixels in the 3×3 neighbourhood, else in the 5×5, row by row.
struct Plan {
    rows: usize,
    cols: usize,
    /// Row-major over the tile.
    sources: Vec<Vec<Source>>,
}

impl Plan {
    fn new(cfa: &Cfa) -> Self {
        let mut sources = Vec::with_capacity(cfa.n_positions());
        for r in 0..cfa.rows {
            for c in 0..cfa.cols {
                let own = cfa.channel_at(r, c);
                let per_channel = (0..cfa.n_channels())
                    .map(|ch| {
                        if ch == own {
                            Source::Own
                        } else {
                            Source::Mean(neighbours(cfa, r, c, ch))
                        }
                    })
                    .collect();
                sources.push(per_channel);
            }
        }
        Self {
            rows: cfa.rows,
            cols: cfa.cols,
            sources,
        }
    }

    /// The sources at sensor pixel `(r, c)`.
    fn at(&self, r: usize, c: usize) -> &[Source] {
        &self.sources[(r % self.rows) * self.cols + c % self.cols]
    }
}

/// The offsets of channel `ch`'s pixels around tile position `(r, c)`: within radius 1,
/// else within radius 2, row-major; the channel is decided by the neighbour's true CFA
/// position (the value is read mirrored at the frame's edges).
fn neighbours(cfa: &Cfa, r: usize, c: usize, ch: usize) -> Vec<(isize, isize)> {
    let wrap = |i: usize, d: isize, n: usize| (i as isize + d).rem_euclid(n as isize) as usize;
    for rad in [1isize, 2] {
        let taps: Vec<(isize, isize)> = (-rad..=rad)
            .flat_map(|dy| (-rad..=rad).map(move |dx| (dy, dx)))
            .filter(|&(dy, dx)| cfa.channel_at(wrap(r, dy, cfa.rows), wrap(c, dx, cfa.cols)) == ch)
            .collect();
        if !taps.is_empty() {
            return taps;
        }
    }
    Vec::new()
}

/// What a render writes per pixel: three values of `T` from the pixel's XYZ.
trait Sink: Sync {
    type T: Copy + Default + Send + Sync;

    /// Write pixels `first`, `first + step`, … of an output row from the first `n` values of
    /// the X, Y and Z planes (`idx`: scratch of at least `n` per plane).
    fn emit(
        &self,
        xyz: &[Vec<f32>; 3],
        n: usize,
        first_step: (usize, usize),
        row: &mut [Self::T],
        idx: &mut [Vec<u32>; 3],
    );
}

/// Interleaved XYZ, f32.
struct XyzOut;

impl Sink for XyzOut {
    type T = f32;

    #[inline(always)]
    fn emit(
        &self,
        xyz: &[Vec<f32>; 3],
        n: usize,
        (first, step): (usize, usize),
        row: &mut [f32],
        _: &mut [Vec<u32>; 3],
    ) {
        let (x, y, z) = (&xyz[0][..n], &xyz[1][..n], &xyz[2][..n]);
        let pixels = row.chunks_exact_mut(3).skip(first).step_by(step);
        for (px, ((&x, &y), &z)) in pixels.zip(x.iter().zip(y).zip(z)) {
            px.copy_from_slice(&[x, y, z]);
        }
    }
}

/// 8-bit sRGB: the white-scaled linear sRGB matrix, then the encoding table.
struct Srgb8Out {
    m: [[f32; 3]; 3],
    lut: SrgbLut,
}

impl Sink for Srgb8Out {
    type T = u8;

    #[inline(always)]
    fn emit(
        &self,
        xyz: &[Vec<f32>; 3],
        n: usize,
        (first, step): (usize, usize),
        row: &mut [u8],
        idx: &mut [Vec<u32>; 3],
    ) {
        let (x, y, z) = (&xyz[0][..n], &xyz[1][..n], &xyz[2][..n]);
        let m = &self.m;
        let [ir, ig, ib] = idx;
        let (ir, ig, ib) = (&mut ir[..n], &mut ig[..n], &mut ib[..n]);
        // the table indices: a loop that vectorises (the sum in xyz_to_srgb8's order)
        for k in 0..n {
            let p = [x[k], y[k], z[k]];
            ir[k] = self
                .lut
                .index(m[0][0] * p[0] + m[0][1] * p[1] + m[0][2] * p[2]);
            ig[k] = self
                .lut
                .index(m[1][0] * p[0] + m[1][1] * p[1] + m[1][2] * p[2]);
            ib[k] = self
                .lut
                .index(m[2][0] * p[0] + m[2][1] * p[1] + m[2][2] * p[2]);
        }
        let pixels = row.chunks_exact_mut(3).skip(first).step_by(step);
        for (px, ((&r, &g), &b)) in pixels.zip(ir.iter().zip(ig.iter()).zip(ib.iter())) {
            px.copy_from_slice(&[self.lut.at(r), self.lut.at(g), self.lut.at(b)]);
        }
    }
}

/// One render's inputs.
struct Job<'a, S> {
    volts: &'a [f32],
    width: usize,
    height: usize,
    /// The colour matrix in f32, `m[channel][k]`.
    m: &'a [[f32; 3]],
    sink: &'a S,
    /// Run the strips with AVX2.
    simd: bool,
}

/// Per-thread buffers.
struct Scratch {
    /// Three frame rows, mirrored one pixel past each end, split into even and odd columns
    /// of the padded row ([`split_row`]); a row split for one output row serves the next.
    split: [[Vec<f32>; 2]; 3],
    /// The frame row each of `split` holds (`usize::MAX`: none yet).
    held: [usize; 3],
    /// Demosaicked channel planes (one parity of a row).
    chan: Vec<Vec<f32>>,
    /// One pixel's channels (the per-pixel path).
    px: Vec<f32>,
    xyz: [Vec<f32>; 3],
    idx: [Vec<u32>; 3],
}

impl Scratch {
    fn new(width: usize, nc: usize) -> Self {
        let half = width.div_ceil(2) + 1;
        let plane = || vec![0f32; half];
        Self {
            split: [0, 1, 2].map(|_| [plane(), plane()]),
            held: [usize::MAX; 3],
            chan: vec![vec![0f32; half]; nc],
            px: vec![0f32; nc],
            xyz: [0, 1, 2].map(|_| vec![0f32; width]),
            idx: [0, 1, 2].map(|_| vec![0u32; width]),
        }
    }
}

/// The fused render with `sink`, on AVX2 when `simd` (which the caller has checked).
fn render<S: Sink>(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
    m: &ColourMatrix,
    sink: &S,
    simd: bool,
) -> Result<Vec<S::T>, BaselineError> {
    check_matrix(m, cfa)?;
    check_frame(volts, width, height)?;
    let nc = cfa.n_channels();
    if m.m.len() != nc {
        return Err(BaselineError::InvalidInput(format!(
            "colour matrix has {} columns for {nc} channels",
            m.m.len()
        )));
    }
    let mf: Vec<[f32; 3]> = m.m.iter().map(|c| c.map(|v| v as f32)).collect();
    let job = Job {
        volts,
        width,
        height,
        m: &mf,
        sink,
        simd,
    };
    let plan = Plan::new(cfa);
    let mut out = vec![S::T::default(); width * height * 3];
    let strips = out.par_chunks_mut(STRIP_ROWS * width * 3).enumerate();
    match PairPlan::new(&plan) {
        Some(pairs) => strips.try_for_each_init(
            || Scratch::new(width, nc),
            |sc, (s, strip)| pairs.strip(&job, s * STRIP_ROWS, strip, sc),
        )?,
        None => {
            let padded = pad_mirrored(volts, width, height, 2);
            strips.try_for_each_init(
                || Scratch::new(width, nc),
                |sc, (s, strip)| {
                    for (i, row) in strip.chunks_exact_mut(width * 3).enumerate() {
                        per_pixel_row(&plan, &job, &padded, s * STRIP_ROWS + i, row, sc)?;
                    }
                    Ok::<(), BaselineError>(())
                },
            )?
        }
    }
    Ok(out)
}

/// The frame mirrored `pad` pixels past every edge (as [`mirror`] does), for the per-pixel
/// path's fixed 5 × 5 neighbourhood.
fn pad_mirrored(volts: &[f32], width: usize, height: usize, pad: usize) -> Vec<f32> {
    let pw = width + 2 * pad;
    let mut out = vec![0f32; pw * (height + 2 * pad)];
    for (pr, row) in out.chunks_exact_mut(pw).enumerate() {
        let r = mirror(pr as isize - pad as isize, height);
        let src = &volts[r * width..(r + 1) * width];
        row[pad..pad + width].copy_from_slice(src);
        for p in 0..pad {
            row[p] = src[mirror(p as isize - pad as isize, width)];
            row[pad + width + p] = src[mirror((width + p) as isize, width)];
        }
    }
    out
}

fn non_finite() -> BaselineError {
    BaselineError::InvalidInput("the colour matrix gives a non-finite value".into())
}

/// Whether the first `n` values of every plane are finite.
#[inline(always)]
fn all_finite(planes: &[Vec<f32>; 3], n: usize) -> bool {
    planes
        .iter()
        .all(|p| p[..n].iter().fold(true, |ok, v| ok & v.is_finite()))
}

/// One row by the per-pixel path (any CFA): `padded` is the frame mirrored 2 pixels past
/// every edge.
fn per_pixel_row<S: Sink>(
    plan: &Plan,
    job: &Job<'_, S>,
    padded: &[f32],
    r: usize,
    row: &mut [S::T],
    sc: &mut Scratch,
) -> Result<(), BaselineError> {
    let (w, pw) = (job.width, job.width + 4);
    let at = |dy: isize, c: usize, dx: isize| {
        padded[(r as isize + 2 + dy) as usize * pw + (c as isize + 2 + dx) as usize]
    };
    for c in 0..w {
        for (v, src) in sc.px.iter_mut().zip(plan.at(r, c)) {
            *v = match src {
                Source::Own => at(0, c, 0),
                Source::Mean(taps) if taps.is_empty() => 0.0,
                Source::Mean(taps) => {
                    let mut s = 0f32;
                    for &(dy, dx) in taps {
                        s += at(dy, c, dx);
                    }
                    s / taps.len() as f32
                }
            };
        }
        for (k, plane) in sc.xyz.iter_mut().enumerate() {
            let mut acc = 0f32;
            for (mc, &v) in job.m.iter().zip(&sc.px) {
                acc += mc[k] * v;
            }
            plane[c] = acc;
        }
    }
    if !all_finite(&sc.xyz, w) {
        return Err(non_finite());
    }
    job.sink.emit(&sc.xyz, w, (0, 1), row, &mut sc.idx);
    Ok(())
}

/// A tap of the row-pair path: the split row (0: above, 1: the row, 2: below), its plane
/// (0: even, 1: odd columns of the padded row) and the offset into it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Tap {
    row: usize,
    plane: usize,
    offset: usize,
}

/// A channel's taps at one parity: copied (its own pixel) or averaged.
#[derive(Clone, Debug, PartialEq)]
struct ChannelTaps {
    taps: Vec<Tap>,
    /// The count to divide by (`None`: the pixel's own value).
    count: Option<f32>,
}

impl ChannelTaps {
    /// The channel for the `n` pixels of one parity of the row; `slot[t.row]` is the split
    /// row holding tap row `t.row`.
    #[inline(always)]
    fn fill(&self, split: &[[Vec<f32>; 2]; 3], slot: [usize; 3], dst: &mut [f32]) {
        let n = dst.len();
        let src = |t: &Tap| &split[slot[t.row]][t.plane][t.offset..t.offset + n];
        let Some((first, rest)) = self.taps.split_first() else {
            dst.fill(0.0);
            return;
        };
        // bilinear_demosaic sums from 0: 0 + first is first (up to the sign of a zero, which
        // the matrix's sum from 0 removes)
        dst.copy_from_slice(src(first));
        for t in rest {
            for (d, &v) in dst.iter_mut().zip(src(t)) {
                *d += v;
            }
        }
        if let Some(count) = self.count {
            for d in dst.iter_mut() {
                *d /= count;
            }
        }
    }
}

/// The row-pair path of a CFA whose tile is at most 2×2: per row parity and column parity,
/// each channel's [`ChannelTaps`].
struct PairPlan {
    taps: [[Vec<ChannelTaps>; 2]; 2],
}

impl PairPlan {
    /// None when the tile is larger than 2×2 (or a channel reaches past the 3×3 window,
    /// which a 2×2 tile never does: its four phases are all in every 3×3 window).
    fn new(plan: &Plan) -> Option<Self> {
        if plan.rows > 2 || plan.cols > 2 {
            return None;
        }
        // padded column c + 1 + dx of pixel c = 2k + q is split plane (q + 1 + dx) % 2 at
        // k + (q + 1 + dx) / 2
        let tap = |q: usize, dy: isize, dx: isize| {
            let j = (q as isize + 1 + dx) as usize;
            Tap {
                row: (dy + 1) as usize,
                plane: j % 2,
                offset: j / 2,
            }
        };
        let mut taps: [[Vec<ChannelTaps>; 2]; 2] = Default::default();
        for (pr, per_row) in taps.iter_mut().enumerate() {
            for (q, per_col) in per_row.iter_mut().enumerate() {
                for src in plan.at(pr, q) {
                    per_col.push(match src {
                        Source::Own => ChannelTaps {
                            taps: vec![tap(q, 0, 0)],
                            count: None,
                        },
                        Source::Mean(t) if t.iter().any(|d| d.0.abs() > 1 || d.1.abs() > 1) => {
                            return None;
                        }
                        Source::Mean(t) => ChannelTaps {
                            taps: t.iter().map(|&(dy, dx)| tap(q, dy, dx)).collect(),
                            count: Some(t.len() as f32),
                        },
                    });
                }
            }
        }
        Some(Self { taps })
    }

    /// The rows from `r0` into `strip` (whole output rows).
    fn strip<S: Sink>(
        &self,
        job: &Job<'_, S>,
        r0: usize,
        strip: &mut [S::T],
        sc: &mut Scratch,
    ) -> Result<(), BaselineError> {
        #[cfg(target_arch = "x86_64")]
        if job.simd {
            // SAFETY: `simd` is set only where the CPU reports AVX2
            return unsafe { self.strip_avx2(job, r0, strip, sc) };
        }
        self.strip_body(job, r0, strip, sc)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn strip_avx2<S: Sink>(
        &self,
        job: &Job<'_, S>,
        r0: usize,
        strip: &mut [S::T],
        sc: &mut Scratch,
    ) -> Result<(), BaselineError> {
        self.strip_body(job, r0, strip, sc)
    }

    #[inline(always)]
    fn strip_body<S: Sink>(
        &self,
        job: &Job<'_, S>,
        r0: usize,
        strip: &mut [S::T],
        sc: &mut Scratch,
    ) -> Result<(), BaselineError> {
        let w = job.width;
        for (i, row) in strip.chunks_exact_mut(w * 3).enumerate() {
            let r = r0 + i;
            let slot = split_rows(job, r, sc);
            for q in 0..2 {
                // pixels 2k + q of the row
                let n = (w + 1 - q) / 2;
                if n == 0 {
                    continue;
                }
                for (ct, chan) in self.taps[r % 2][q].iter().zip(sc.chan.iter_mut()) {
                    ct.fill(&sc.split, slot, &mut chan[..n]);
                }
                matrix(&sc.chan, job.m, n, &mut sc.xyz);
                if !all_finite(&sc.xyz, n) {
                    return Err(non_finite());
                }
                job.sink.emit(&sc.xyz, n, (q, 2), row, &mut sc.idx);
            }
        }
        Ok(())
    }
}

/// Have `sc.split` hold rows r − 1, r and r + 1 (mirrored at the frame's edges), splitting
/// only those it does not hold yet; the slot of each.
#[inline(always)]
fn split_rows<S>(job: &Job<'_, S>, r: usize, sc: &mut Scratch) -> [usize; 3] {
    let need = [-1isize, 0, 1].map(|dy| mirror(r as isize + dy, job.height));
    let mut slot = [usize::MAX; 3];
    for (i, &rr) in need.iter().enumerate() {
        if let Some(s) = sc.held.iter().position(|&h| h == rr) {
            slot[i] = s;
        }
    }
    for i in 0..3 {
        if slot[i] != usize::MAX {
            continue;
        }
        let rr = need[i];
        // a row split for an earlier role of this one, else a slot no role uses (there is
        // one: at most two slots are taken while a role is unassigned)
        let s = match (0..3).find(|&s| sc.held[s] == rr && slot.contains(&s)) {
            Some(s) => s,
            None => {
                let free = (0..3).find(|s| !slot.contains(s)).unwrap_or(i);
                split_row(
                    &job.volts[rr * job.width..(rr + 1) * job.width],
                    &mut sc.split[free],
                );
                sc.held[free] = rr;
                free
            }
        };
        slot[i] = s;
    }
    slot
}

/// Split `src` mirrored one pixel past each end (padded column j is `src[mirror(j − 1)]`)
/// into its even (`out[0][i]` = padded `2i`) and odd (`out[1][i]` = padded `2i + 1`) columns.
#[inline(always)]
fn split_row(src: &[f32], out: &mut [Vec<f32>; 2]) {
    let w = src.len();
    let [even, odd] = out;
    even[0] = src[mirror(-1, w)];
    for ((pair, o), e) in src
        .chunks_exact(2)
        .zip(odd.iter_mut())
        .zip(even[1..].iter_mut())
    {
        *o = pair[0];
        *e = pair[1];
    }
    if w % 2 == 1 {
        odd[w / 2] = src[w - 1];
    }
    let right = src[mirror(w as isize, w)];
    if w.is_multiple_of(2) {
        odd[w / 2] = right;
    } else {
        even[w.div_ceil(2)] = right;
    }
}

/// XYZ = M · channels over the first `n` pixels of the planes, each sum from 0 in channel
/// order (as [`ColourMatrix::apply`]).
#[inline(always)]
fn matrix(chan: &[Vec<f32>], m: &[[f32; 3]], n: usize, xyz: &mut [Vec<f32>; 3]) {
    for (k, out) in xyz.iter_mut().enumerate() {
        let out = &mut out[..n];
        out.fill(0.0);
        for (mc, c) in m.iter().zip(chan) {
            let w = mc[k];
            for (o, &v) in out.iter_mut().zip(&c[..n]) {
                *o += w * v;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::baseline::{bilinear_demosaic, render_baseline};
    use crate::l3::render::xyz_to_srgb8;

    /// Every kind of tile: the four Bayer phases, RGBW and a rotation of it, 1×2 and 2×1
    /// tiles, a 3×3 and a 4×4 tile, and a 6×6 one where a channel is missing from some 5×5
    /// windows (its value there is 0).
    const CFAS: [&str; 11] = [
        "RG/GB",
        "GR/BG",
        "GB/RG",
        "BG/GR",
        "RG/WB",
        "WB/RG",
        "RG",
        "R/G",
        "RGB/GBR/BRG",
        "RGBW/WRGB/BWRG/GBWR",
        "RGGGGG/GGGGGG/GGGGGG/GGGGGG/GGGGGG/GGGGGB",
    ];

    const SIZES: [(usize, usize); 12] = [
        (1, 1),
        (2, 1),
        (1, 2),
        (2, 2),
        (3, 3),
        (7, 1),
        (1, 7),
        (5, 4),
        (4, 5),
        (17, 9),
        (64, 33),
        (101, 3),
    ];

    fn random_case(cfa: &Cfa, w: usize, h: usize, seed: u64) -> (Vec<f32>, ColourMatrix) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let volts = (0..w * h)
            .map(|_| rng.random::<f32>() * 1.8 * (rng.random::<f32>() < 0.95) as u8 as f32)
            .collect();
        let m = ColourMatrix {
            m: (0..cfa.n_channels())
                .map(|_| [0, 1, 2].map(|_| rng.random::<f64>() * 2.0 - 0.5))
                .collect(),
            n_channels: cfa.n_channels(),
        };
        (volts, m)
    }

    #[test]
    fn fused_baseline_is_the_straightforward_one_bit_for_bit() {
        let mut compared = 0;
        for (i, p) in CFAS.iter().enumerate() {
            let cfa = Cfa::parse(p).unwrap();
            for (j, &(w, h)) in SIZES.iter().enumerate() {
                let (volts, m) = random_case(&cfa, w, h, (i * 100 + j) as u64);
                let want = render_baseline(&volts, w, h, &cfa, &m).unwrap();
                assert_eq!(
                    want,
                    m.apply(&bilinear_demosaic(&volts, w, h, &cfa).unwrap())
                        .unwrap()
                );
                for simd in [false, simd_available()] {
                    let got = render(&volts, w, h, &cfa, &m, &XyzOut, simd).unwrap();
                    let diff = got
                        .iter()
                        .zip(&want)
                        .map(|(a, b)| (a - b).abs())
                        .fold(0f32, f32::max);
                    assert_eq!(got.len(), want.len());
                    assert_eq!(diff, 0.0, "{p} {w}×{h}, simd {simd}");
                    for white in [0.5, 1.0, 2.0] {
                        let sink = Srgb8Out {
                            m: linear_srgb_matrix(white),
                            lut: SrgbLut::new(),
                        };
                        let bytes = render(&volts, w, h, &cfa, &m, &sink, simd).unwrap();
                        assert!(
                            bytes == xyz_to_srgb8(&want, white),
                            "{p} {w}×{h} white {white}"
                        );
                    }
                    compared += 1;
                }
            }
        }
        assert_eq!(compared, CFAS.len() * SIZES.len() * 2);
        // the public entry points are these
        let cfa = Cfa::parse("RG/WB").unwrap();
        let (volts, m) = random_case(&cfa, 40, 30, 9);
        let want = render_baseline(&volts, 40, 30, &cfa, &m).unwrap();
        assert_eq!(
            render_baseline_fused(&volts, 40, 30, &cfa, &m).unwrap(),
            want
        );
        assert_eq!(
            render_baseline_fused_srgb8(&volts, 40, 30, &cfa, &m, 1.0).unwrap(),
            xyz_to_srgb8(&want, 1.0)
        );
    }

    #[test]
    fn tiles_up_to_2x2_take_the_row_pair_path_and_others_the_per_pixel_one() {
        for p in CFAS {
            let cfa = Cfa::parse(p).unwrap();
            let pairs = PairPlan::new(&Plan::new(&cfa));
            assert_eq!(pairs.is_some(), cfa.rows <= 2 && cfa.cols <= 2, "{p}");
        }
        // Bayer G at R: the four-neighbour cross, in row order, divided by 4
        let plan = Plan::new(&Cfa::parse("RG/GB").unwrap());
        assert_eq!(
            plan.at(0, 0)[1],
            Source::Mean(vec![(-1, 0), (0, -1), (0, 1), (1, 0)])
        );
        // the 6×6 tile's B is 3 pixels away from (2, 2) both ways (R is 2)
        let far = Plan::new(&Cfa::parse(CFAS[10]).unwrap());
        assert_eq!(far.at(2, 2)[2], Source::Mean(Vec::new()));
        assert_eq!(far.at(2, 2)[0], Source::Mean(vec![(-2, -2)]));
    }

    #[test]
    fn fused_baseline_refuses_what_the_straightforward_one_refuses() {
        let cfa = Cfa::parse("RG/WB").unwrap();
        let (mut volts, m) = random_case(&cfa, 8, 6, 3);
        let three = ColourMatrix {
            m: m.m[..3].to_vec(),
            n_channels: 3,
        };
        assert!(render_baseline_fused(&volts, 8, 6, &cfa, &three).is_err());
        assert!(render_baseline_fused(&volts, 8, 5, &cfa, &m).is_err());
        assert!(render_baseline_fused(&volts, 0, 0, &cfa, &m).is_err());
        volts[13] = f32::NAN;
        assert!(render_baseline(&volts, 8, 6, &cfa, &m).is_err());
        assert!(render_baseline_fused(&volts, 8, 6, &cfa, &m).is_err());
        assert!(render_baseline_fused_srgb8(&volts, 8, 6, &cfa, &m, 1.0).is_err());
        let big = Cfa::parse("RGB/GBR/BRG").unwrap();
        let (mut volts, m) = random_case(&big, 8, 6, 4);
        volts[20] = f32::INFINITY;
        assert!(render_baseline_fused(&volts, 8, 6, &big, &m).is_err());
    }
}
