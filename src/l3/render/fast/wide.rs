//! The AVX-512 path's view of the table, and its kernel step over classes found by the
//! portable code.

use super::avx512;
use super::kernels::KernelSet;
use super::phases::PhaseMap;
use super::scratch::RowScratch;
use super::stages::TileRow;
use super::{CHROMA_MARGIN, CHROMA_MARGIN_FLOOR, FastRenderer, NO_CLASS, RenderStats};

impl FastRenderer {
    /// The AVX-512 kernel step over a tile row whose classes (`rs.class`, [`NO_CLASS`]
    /// for the reference path) the portable code found: each pixel's kernels by its
    /// class's offset in the paired layout, then the reference path's pixels, into
    /// `rs.lin`. Only from `WIDE` tiles. Returns `false`, having written nothing to the
    /// output, when the kernel step refuses its arguments. Out of line (one call per
    /// row), so the tiles the AVX-512 classification takes do not carry it.
    ///
    /// # Safety
    /// The CPU must have AVX-512 F, VL and DQ, AVX2 and FMA.
    #[inline(never)]
    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx2,fma")]
    pub(super) unsafe fn apply_classes_wide<const P: usize>(
        &self,
        set: &KernelSet,
        row: &TileRow<'_>,
        rs: &mut RowScratch,
        st: &mut RenderStats,
    ) -> bool {
        let tw = row.tw;
        let RowScratch {
            class,
            offsets,
            lin,
            ..
        } = rs;
        let mut texture = 0u64;
        let padded = offsets.len().min(tw.div_ceil(16) * 16);
        for (i, o) in offsets[..padded].iter_mut().enumerate() {
            let c = class.get(i).copied().filter(|_| i < tw).unwrap_or(NO_CLASS);
            *o = if c == NO_CLASS {
                0
            } else {
                texture += u64::from(c & 1);
                // an offset past the kernels is refused by the kernel step
                u32::try_from(c as usize * set.pstride).unwrap_or(u32::MAX)
            };
        }
        let [l0, l1, l2] = lin;
        let kernels = avx512::KernelRow {
            buf: row.rows,
            stride: row.stride,
            offsets,
            tw,
            kernels: set.paired(),
            kstride: set.pstride,
        };
        // SAFETY: the caller has the features; the kernel step checks the lengths and
        // offsets of what it touches
        let applied = unsafe {
            avx512::apply_kernels::<P>(&kernels, [&mut l0[..], &mut l1[..], &mut l2[..]])
        };
        if !applied {
            return false;
        }
        st.texture += texture;
        self.exact_pixels(set, row, rs, st);
        true
    }

    /// The AVX-512 classification's view of the table for one tile: phase
    /// weights, level edges and the contrast thresholds per position and level.
    pub(super) fn class_params(
        &self,
        thresholds: &[f32],
        use_contrast: bool,
        set: &KernelSet,
    ) -> Option<avx512::ClassParams> {
        let maps = self.phases.as_deref()?;
        let src = self.geo.level_edges();
        let kc = self.n_chroma.max(1);
        let n_levels = self.n_bands / kc;
        if n_levels > avx512::MAX_LEVELS || src.len() >= avx512::MAX_LEVELS {
            return None;
        }
        let mut edges = [f32::INFINITY; avx512::MAX_LEVELS];
        edges[..src.len()].copy_from_slice(src);
        let mut below = [f32::NEG_INFINITY; avx512::MAX_LEVELS];
        below[1..=src.len()].copy_from_slice(src);
        let n_sat = self.sat_cases.len();
        // NaN (never expected) sends the pixels to the reference path
        let threshold = |pos: usize, band: usize| {
            thresholds
                .get((pos * self.n_bands + band) * n_sat)
                .copied()
                .unwrap_or(f32::NAN)
        };
        let mut per_pos = [[f32::INFINITY; avx512::MAX_LEVELS]; 4];
        if kc == 1 {
            for (pos, t) in per_pos.iter_mut().enumerate() {
                for (level, v) in t.iter_mut().take(n_levels).enumerate() {
                    *v = threshold(pos, level);
                }
            }
        }
        let chroma = (kc > 1).then(|| {
            let coef = self.geo.chroma_coefficients();
            avx512::ChromaParams {
                coef: coef
                    .iter()
                    .map(|a| std::array::from_fn(|ch| a.get(ch).copied().unwrap_or(0.0)))
                    .collect(),
                scale: std::array::from_fn(|ch| self.chroma_scale.get(ch).copied().unwrap_or(0.0)),
                phase_channels: self.phase_channels,
                n_channels: self.geo.n_channels(),
                thresholds: (0..4 * self.n_bands)
                    .map(|i| threshold(i / self.n_bands, i % self.n_bands))
                    .collect(),
                margin: CHROMA_MARGIN,
                floor: CHROMA_MARGIN_FLOOR,
            }
        });
        let s = self.geo.size;
        // patch rows (columns) of the centre's parity, and of the other
        let same = (0..s).filter(|d| (d + s / 2).is_multiple_of(2)).count();
        let other = s - same;
        let count = [same * same, same * other, other * same, other * other].map(|n| n as f32);
        // one map per CFA position, each mean a mean of whole phases (a
        // uniform patch's mean is its value)
        let [m0, m1, m2, m3] = <&[PhaseMap; 4]>::try_from(maps).ok()?;
        let maps = [m0, m1, m2, m3];
        let whole = |t: &[f32; 4]| {
            (t.iter().zip(&count).map(|(w, n)| w * n).sum::<f32>() - 1.0).abs() <= 1e-6
        };
        if !maps.iter().all(|m| m.to_mean.iter().all(whole)) {
            return None;
        }
        let diagonal = maps
            .iter()
            .all(|m| (0..4).all(|p| (0..4).all(|q| p == q || m.to_mean[p][q] == 0.0)));
        Some(avx512::ClassParams {
            to_mean: maps.map(|m| m.to_mean),
            lum: maps.map(|m| m.lum),
            diagonal,
            count,
            inv_area: 1.0 / (s * s) as f32,
            edges,
            below,
            thresholds: per_pos,
            n_levels: n_levels as u32,
            n_chroma: kc as u32,
            chroma,
            n_sat: n_sat as u32,
            use_contrast,
            n_classes: u32::try_from(set.paired().len() / set.pstride).ok()?,
            kstride: u32::try_from(set.pstride).ok()?,
        })
    }
}
