//! [`PatchGeometry::stats`] for [`LANES`] neighbouring interior pixels at once, for the
//! training's pass over every pixel of its frames.
//!
//! Each lane runs `stats`' own sums, element by element in the patch's order, so every lane's
//! [`PatchStats`] is the same, bit for bit, as `stats` of that pixel's gathered patch: the
//! classes of a training sample do not depend on which path classified it. What changes is
//! that the sixteen sums run side by side in vector registers, where `stats` chains one
//! pixel's sums through memory. The per-lane channel of each element is a mask; a lane whose
//! element is of another channel adds +0.0, which leaves a sum that starts at +0.0 unchanged
//! (such a sum is never −0.0).
//!
//! Plain Rust that the compiler vectorises, not intrinsics: these loops need nothing beyond
//! compares, selects and adds. The release build targets baseline x86-64 (SSE2), so the same
//! loops are also compiled for AVX2 and AVX-512 and chosen at run time. Rust never fuses a
//! multiply and an add on its own, so every version rounds as `stats` does.

use super::{MAX_CHANNELS, PatchGeometry, PatchStats};

/// Pixels classified side by side.
pub const LANES: usize = 16;

/// Per CFA phase of a run's first pixel: each patch element's channel in each lane, and each
/// lane's `1 / count` per channel. Built once per geometry and frame shift.
#[derive(Clone, Debug)]
pub struct LaneChannels {
    /// `[row phase][column phase]` → per patch element, the channel in each lane.
    chans: Vec<Vec<[u8; LANES]>>,
    /// The same phases → per channel, each lane's `1 / count`.
    inv: Vec<[[f32; LANES]; MAX_CHANNELS]>,
    cols: usize,
    /// The widest vectors this CPU has.
    isa: Isa,
}

/// The instruction sets [`PatchGeometry::stats_run`] is compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Isa {
    Baseline,
    #[cfg(target_arch = "x86_64")]
    Avx2,
    #[cfg(target_arch = "x86_64")]
    Avx512,
}

impl Isa {
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx512f")
                && std::is_x86_feature_detected!("avx512bw")
                && std::is_x86_feature_detected!("avx512vl")
                && std::is_x86_feature_detected!("avx512dq")
            {
                return Isa::Avx512;
            }
            if std::is_x86_feature_detected!("avx2") {
                return Isa::Avx2;
            }
        }
        Isa::Baseline
    }
}

impl LaneChannels {
    /// The tables of runs whose first pixel is at CFA row phase `row` and column phase `col`.
    fn at(&self, row: usize, col: usize) -> (&[[u8; LANES]], &[[f32; LANES]; MAX_CHANNELS]) {
        let i = row * self.cols + col;
        (&self.chans[i], &self.inv[i])
    }
}

impl PatchGeometry {
    /// The lane tables of this geometry ([`Self::stats_run`]).
    pub fn lane_channels(&self) -> LaneChannels {
        let (rows, cols) = (self.cfa.rows, self.cfa.cols);
        let n = self.size * self.size;
        let mut chans = Vec::with_capacity(rows * cols);
        let mut inv = Vec::with_capacity(rows * cols);
        for row in 0..rows {
            for col in 0..cols {
                let pos_of = |j: usize| row * cols + (col + j) % cols;
                let mut c = vec![[0u8; LANES]; n];
                let mut v = [[0f32; LANES]; MAX_CHANNELS];
                for j in 0..LANES {
                    let pos = pos_of(j);
                    for (k, lanes) in c.iter_mut().enumerate() {
                        lanes[j] = self.chan_of[pos][k];
                    }
                    for (ch, lanes) in v.iter_mut().enumerate() {
                        lanes[j] = self.inv_count[pos][ch];
                    }
                }
                chans.push(c);
                inv.push(v);
            }
        }
        LaneChannels {
            chans,
            inv,
            cols,
            isa: Isa::detect(),
        }
    }

    /// Whether [`Self::stats_run`] takes the run of pixels `(r, c0..c0 + LANES)` of a
    /// `width` × `height` image: every patch inside the image.
    pub fn run_is_interior(&self, width: usize, height: usize, r: usize, c0: usize) -> bool {
        let rad = self.radius;
        r >= rad && r + rad < height && c0 >= rad && c0 + LANES - 1 + rad < width
    }

    /// [`Self::stats`] of the [`LANES`] pixels `(r, c0 + j)` of `img` (`width` wide), whose
    /// first pixel is at CFA phase `phase` (row, column). Bit for bit what `stats` gives each
    /// pixel's patch. Returns `false`, and writes nothing, unless every patch is inside the
    /// image ([`Self::run_is_interior`]) and `lanes` and `phase` are this geometry's.
    pub fn stats_run(
        &self,
        lanes: &LaneChannels,
        phase: (usize, usize),
        img: &[f32],
        width: usize,
        at: (usize, usize),
        out: &mut [PatchStats; LANES],
    ) -> bool {
        let fits = width > 0
            && self.run_is_interior(width, img.len() / width, at.0, at.1)
            && phase.0 < self.cfa.rows
            && phase.1 < self.cfa.cols
            && lanes.cols == self.cfa.cols
            && lanes.chans.len() == self.cfa.rows * self.cfa.cols
            && lanes.chans.iter().all(|c| c.len() == self.size * self.size);
        if !fits {
            return false;
        }
        let run = Run {
            geo: self,
            lanes,
            phase,
            img,
            width,
            at,
        };
        match lanes.isa {
            // SAFETY: the CPU has the features (`Isa::detect`).
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { run.avx512(out) },
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => unsafe { run.avx2(out) },
            Isa::Baseline => run.stats(out),
        }
        true
    }
}

/// One call of [`PatchGeometry::stats_run`].
struct Run<'a> {
    geo: &'a PatchGeometry,
    lanes: &'a LaneChannels,
    phase: (usize, usize),
    img: &'a [f32],
    width: usize,
    at: (usize, usize),
}

impl Run<'_> {
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512dq")]
    unsafe fn avx512(&self, out: &mut [PatchStats; LANES]) {
        self.stats(out);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn avx2(&self, out: &mut [PatchStats; LANES]) {
        self.stats(out);
    }

    #[inline(always)]
    fn stats(&self, out: &mut [PatchStats; LANES]) {
        let Run {
            geo,
            lanes,
            phase,
            img,
            width,
            at: (r, c0),
        } = *self;
        let (chans, inv) = lanes.at(phase.0, phase.1);
        let (s, rad, nch) = (geo.size, geo.radius, geo.n_channels);
        let thr = geo.sat_threshold;
        let value = |k: usize| -> &[f32; LANES] {
            let at = (r + k / s - rad) * width + c0 + k % s - rad;
            img[at..at + LANES].try_into().unwrap_or(&[0.0; LANES])
        };
        // two channels at a time, so that each sum stays in a register over the patch and
        // two chains of additions overlap
        let mut means = [[0f32; LANES]; MAX_CHANNELS];
        let mut sat = [0u32; LANES];
        let mut lum = [0f32; LANES];
        let mut nl = [0u32; LANES];
        let mut ch = 0;
        while ch < nch {
            let sums: &[Sums] = if nch - ch >= 2 {
                &channel_sums::<2>(chans, &value, ch, thr)
            } else {
                &channel_sums::<1>(chans, &value, ch, thr)
            };
            for t in sums {
                for j in 0..LANES {
                    means[ch][j] = t.sum[j] * inv[ch][j];
                    sat[j] |= t.saturated[j] << ch;
                    let seen = t.ucount[j] > 0;
                    let share = t.usum[j] / t.ucount[j].max(1) as f32;
                    lum[j] += if seen { share } else { 0.0 };
                    nl[j] += u32::from(seen);
                }
                ch += 1;
            }
        }
        let mut dev = [0f32; LANES];
        for (k, ck) in chans.iter().enumerate() {
            let v = value(k);
            // each lane's channel mean, picked by bit masks (a select here became a gather)
            let mut m = means[0].map(f32::to_bits);
            for (ch, mc) in means.iter().enumerate().take(nch).skip(1) {
                for j in 0..LANES {
                    let pick = if ck[j] == ch as u8 { u32::MAX } else { 0 };
                    m[j] = (mc[j].to_bits() & pick) | (m[j] & !pick);
                }
            }
            for j in 0..LANES {
                dev[j] += (v[j] - f32::from_bits(m[j])).abs();
            }
        }
        let n = chans.len() as f32;
        for (j, o) in out.iter_mut().enumerate() {
            let mut channel_means = [0f32; MAX_CHANNELS];
            for (ch, m) in channel_means.iter_mut().enumerate().take(nch) {
                *m = means[ch][j];
            }
            *o = PatchStats {
                luminance: if nl[j] > 0 {
                    lum[j] / nl[j] as f32
                } else {
                    thr
                },
                sat_mask: sat[j],
                contrast: dev[j] / n,
                channel_means,
            };
        }
    }
}

/// One channel's sums over a run's patches, per lane: all its values, its unsaturated ones
/// and their count, and whether one is saturated (1 or 0).
struct Sums {
    sum: [f32; LANES],
    usum: [f32; LANES],
    ucount: [u32; LANES],
    saturated: [u32; LANES],
}

/// The [`Sums`] of channels `first..first + C`, element by element in the patch's order
/// (`chans`: each element's channel per lane; `value(k)`: element `k` in each lane).
#[inline(always)]
fn channel_sums<'a, const C: usize>(
    chans: &[[u8; LANES]],
    value: &impl Fn(usize) -> &'a [f32; LANES],
    first: usize,
    thr: f32,
) -> [Sums; C] {
    let mut out: [Sums; C] = std::array::from_fn(|_| Sums {
        sum: [0.0; LANES],
        usum: [0.0; LANES],
        ucount: [0; LANES],
        saturated: [0; LANES],
    });
    for (k, ck) in chans.iter().enumerate() {
        let v = value(k);
        for (i, t) in out.iter_mut().enumerate() {
            let ch = (first + i) as u8;
            for j in 0..LANES {
                // all-ones or zero masks: `bits & mask` is the value or +0.0
                let mine = if ck[j] == ch { u32::MAX } else { 0 };
                let over = if v[j] >= thr { u32::MAX } else { 0 };
                let bits = v[j].to_bits();
                t.sum[j] += f32::from_bits(bits & mine);
                let unsat = mine & !over;
                t.usum[j] += f32::from_bits(bits & unsat);
                t.ucount[j] += unsat & 1;
                t.saturated[j] |= mine & over & 1;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Cfa;
    use proptest::prelude::*;

    /// Every lane of every interior run equals `stats` of the gathered patch, bit for bit,
    /// for `cfa` and patch `size`, on `img` (values from the dark end to past saturation,
    /// negatives, exact ties at the threshold).
    fn runs_match(cfa: &str, size: usize, img: &[f32], width: usize, shift: (usize, usize)) {
        let cfa = Cfa::parse(cfa).unwrap();
        let g = PatchGeometry::new(size, &cfa, &[0.01, 0.1, 1.0], 1.5).unwrap();
        for isa in available() {
            let mut lanes = g.lane_channels();
            lanes.isa = isa;
            runs_match_on(&g, &lanes, img, width, shift);
        }
    }

    /// The versions of `stats_run` this CPU runs.
    fn available() -> Vec<Isa> {
        let mut v = vec![Isa::Baseline];
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                v.push(Isa::Avx2);
            }
            if Isa::detect() == Isa::Avx512 {
                v.push(Isa::Avx512);
            }
        }
        v
    }

    fn runs_match_on(
        g: &PatchGeometry,
        lanes: &LaneChannels,
        img: &[f32],
        width: usize,
        shift: (usize, usize),
    ) {
        let (cfa, size) = (&g.cfa, g.size);
        let height = img.len() / width;
        let mut patch = vec![0f32; size * size];
        let mut out = [g.stats(&patch, 0); LANES];
        let mut runs = 0;
        for r in 0..height {
            for c0 in 0..width {
                if !g.run_is_interior(width, height, r, c0) {
                    continue;
                }
                let (pr, pc) = ((r + shift.0) % cfa.rows, (c0 + shift.1) % cfa.cols);
                assert!(g.stats_run(lanes, (pr, pc), img, width, (r, c0), &mut out));
                for (j, got) in out.iter().enumerate() {
                    g.gather(img, width, height, r, c0 + j, &mut patch);
                    let want = g.stats(&patch, g.position(r + shift.0, c0 + j + shift.1));
                    assert_eq!(
                        (
                            got.luminance.to_bits(),
                            got.contrast.to_bits(),
                            got.sat_mask
                        ),
                        (
                            want.luminance.to_bits(),
                            want.contrast.to_bits(),
                            want.sat_mask
                        ),
                        "({r}, {})",
                        c0 + j
                    );
                    let bits = |m: &[f32; MAX_CHANNELS]| m.map(f32::to_bits);
                    assert_eq!(bits(&got.channel_means), bits(&want.channel_means));
                }
                runs += 1;
            }
        }
        assert!(runs > 0);
        // a run touching the border, or a phase outside the CFA, is refused
        let first = out;
        assert!(!g.stats_run(lanes, (0, 0), img, width, (0, g.radius), &mut out));
        assert!(!g.stats_run(
            lanes,
            (cfa.rows, 0),
            img,
            width,
            (g.radius, g.radius),
            &mut out
        ));
        assert!(out == first, "a refused run wrote its stats");
    }

    fn image(seed: u64, width: usize, height: usize) -> Vec<f32> {
        let mut state = seed | 1;
        (0..width * height)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                match state % 16 {
                    0 => 1.5,
                    1 => 1.8,
                    2 => -0.003,
                    3 => 0.0,
                    _ => (state >> 40) as f32 / (1u64 << 24) as f32 * 1.2,
                }
            })
            .collect()
    }

    #[test]
    fn runs_give_stats_bit_for_bit_on_each_cfa_and_patch_size() {
        let (w, h) = (45, 13);
        for (cfa, size) in [
            ("RG/WB", 5),
            ("RG/GB", 5),
            ("RG/GB", 3),
            ("RG/WB", 7),
            ("RGB", 5),
            ("RGBW/GBWR/BWRG/WRGB", 5),
            ("GRBGBR/BGGRGG/RGGBGG/GBRGRB/RGGBGG/BGGRGG", 9),
        ] {
            for shift in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                runs_match(cfa, size, &image(7, w, h), w, shift);
            }
        }
    }

    proptest! {
        #[test]
        fn runs_give_stats_bit_for_bit(seed in any::<u64>(), width in 21usize..40) {
            runs_match("RG/WB", 5, &image(seed, width, 9), width, (0, 0));
        }
    }
}
