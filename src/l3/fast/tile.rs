//! One tile: its rows and halo in a buffer, then classification and kernels row by row.

#[cfg(target_arch = "x86_64")]
use super::avx512;
use super::kernels::KernelSet;
use super::phases::LaneMaps;
use super::scratch::{Scratch, resize};
use super::sink::Sink;
use super::source::Source;
use super::stages::{add_into, contrast_row, phase_sums_row, row_dot, row_peak};
use super::{
    CHROMA_MARGIN, CHROMA_MARGIN_FLOOR, CONTRAST_MARGIN, FastRenderer, LANES, NO_CLASS,
    RenderStats, mirror,
};

impl FastRenderer {
    /// Render one tile: rows `r0..r0 + rows`, columns `c0..c0 + cols` of the
    /// frame, into the band's rows at `offset`.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub(super) fn tile<const SIMD: bool, const WIDE: bool, const P: usize, T, S: Sink<T>>(
        &self,
        src: &Source<'_>,
        set: &KernelSet,
        tile: Tile,
        sc: &mut Scratch,
        band: &mut [T],
        row_len: usize,
        offset: usize,
        sink: &S,
    ) -> RenderStats {
        // P: the patch size known at compile time (0: not)
        let s = if P != 0 { P } else { self.geo.size };
        let rad = s / 2;
        let nf = self.n_features;
        let tw = tile.cols;
        // scratch rows are padded to whole 16-lane chunks; the buffer has 16 more
        // columns so every 8- or 16-wide read of a patch row stays inside it
        let tw8 = tw.div_ceil(2 * LANES) * 2 * LANES;
        let stride = tw8 + 2 * LANES;
        let brows = tile.rows + 2 * rad;
        let thr = self.geo.sat_threshold();
        // 1. the tile and its halo, clamped volts, mirrored at the frame's borders.
        // Columns past the halo are never weighted (zero kernel weights), so stale
        // finite values from an earlier tile may stay there: no clearing needed.
        resize(&mut sc.buf, brows * stride);
        let mut peak = 0f32;
        let first = tile.c0 as isize - rad as isize;
        let span = tw + 2 * rad;
        // the part of the span inside the frame, and its offset in the buffer row
        let lo = first.max(0) as usize;
        let hi = (first + span as isize).min(src.width as isize) as usize;
        let off = (lo as isize - first) as usize;
        for j in 0..brows {
            let r = mirror(tile.r0 as isize + j as isize - rad as isize, src.height);
            let row = &mut sc.buf[j * stride..j * stride + span];
            if hi > lo {
                src.row_into(r, lo, &mut row[off..off + (hi - lo)]);
            }
            for i in (0..off).chain(off + hi.saturating_sub(lo)..span) {
                row[i] = src.at(r, mirror(first + i as isize, src.width));
            }
            peak = peak.max(row_peak(row));
        }
        let any_sat = !self.options.skip_unsaturated_tiles || peak >= thr;
        let use_contrast = self.contrast_classes
            && (!self.options.skip_equal_contrast_kernels
                || self.contrast_matters.iter().any(|&m| m));
        let fast_classes = self.phases.is_some();
        // 2. horizontal phase sums (and maxima where saturation is possible)
        if fast_classes {
            resize(&mut sc.he, brows * tw8);
            resize(&mut sc.ho, brows * tw8);
            for j in 0..brows {
                let row = &sc.buf[j * stride..(j + 1) * stride];
                let he = &mut sc.he[j * tw8..(j + 1) * tw8];
                let ho = &mut sc.ho[j * tw8..(j + 1) * tw8];
                if P != 0 {
                    phase_sums_row::<P>(row, he, ho);
                    continue;
                }
                he.fill(0.0);
                ho.fill(0.0);
                for d in 0..s {
                    // offset d − rad: even offsets are the centre's column phase
                    let dst = if (d + rad) % 2 == 0 {
                        &mut *he
                    } else {
                        &mut *ho
                    };
                    add_into(dst, &row[d..d + tw8]);
                }
            }
        }
        if any_sat {
            resize(&mut sc.hmax, brows * tw8);
            for j in 0..brows {
                let row = &sc.buf[j * stride..(j + 1) * stride];
                let hm = &mut sc.hmax[j * tw8..(j + 1) * tw8];
                hm.copy_from_slice(&row[..tw8]);
                for d in 1..s {
                    // (values are finite: a plain comparison, which vectorises)
                    for (o, &v) in hm.iter_mut().zip(&row[d..d + tw8]) {
                        *o = if v > *o { v } else { *o };
                    }
                }
            }
        }
        for v in sc
            .sums
            .iter_mut()
            .chain(sc.means.iter_mut())
            .chain(sc.lin.iter_mut())
        {
            resize(v, tw8);
        }
        resize(&mut sc.lum, tw8);
        resize(&mut sc.contrast, tw8);
        if sc.sat.len() < tw8 {
            sc.sat.resize(tw8, false);
        }
        sc.sat[..tw8].fill(false);
        if sc.class.len() < tw8 {
            sc.class.resize(tw8, NO_CLASS);
        }
        sc.class[..tw8].fill(NO_CLASS);
        if sc.offsets.len() < tw8 {
            sc.offsets.resize(tw8, 0);
        }
        sc.patch.clear();
        sc.patch.resize(s * s, 0.0);
        sc.feat.clear();
        sc.feat.resize(nf, 0.0);
        let inv_area = 1.0 / (s * s) as f32;
        let n_sat = self.sat_cases.len();
        let thresholds = if !use_contrast {
            &self.no_thresholds
        } else if self.options.skip_equal_contrast_kernels {
            &self.thresholds_where_they_matter
        } else {
            &self.contrast_thresholds
        };
        #[cfg(target_arch = "x86_64")]
        let wide = if WIDE && fast_classes {
            self.class_params(thresholds, use_contrast, set)
        } else {
            None
        };
        let mut st = RenderStats::default();
        // where two phases share a channel (Bayer), each row parity's maps per lane
        let lane_maps = match (&self.phases, &self.uniform_phases) {
            (Some(maps), None) => {
                Some([0, 1].map(|rpar| LaneMaps::of_row(maps, rpar, tile.c0 % 2)))
            }
            _ => None,
        };
        for y in 0..tile.rows {
            let r = tile.r0 + y;
            // 3. which pixels see a saturated value
            if any_sat {
                let sat = &mut sc.sat[..tw8];
                sat.fill(false);
                for dy in 0..s {
                    let h = &sc.hmax[(y + dy) * tw8..(y + dy + 1) * tw8];
                    for (f, &v) in sat.iter_mut().zip(h) {
                        *f |= v >= thr;
                    }
                }
            }
            #[cfg(target_arch = "x86_64")]
            if let Some(prm) = &wide {
                let rows = &sc.buf[y * stride..];
                let sat = any_sat.then_some(&sc.sat[..]);
                let (he, ho) = (&sc.he[y * tw8..], &sc.ho[y * tw8..]);
                let (rpar, cpar) = (r % 2, tile.c0 % 2);
                // SAFETY: `wide` is only set in `tile_avx512`, which runs when the CPU has
                // the features; the kernels check the lengths of what they touch.
                let counts = unsafe {
                    avx512::classify_row::<P>(
                        he,
                        ho,
                        tw8,
                        rows,
                        stride,
                        sat,
                        tw,
                        rpar,
                        cpar,
                        prm,
                        &mut sc.class,
                        &mut sc.offsets,
                    )
                };
                let [l0, l1, l2] = &mut sc.lin;
                let applied = counts.is_some()
                    // SAFETY: as above
                    && unsafe {
                        avx512::apply_kernels::<P>(
                            rows,
                            stride,
                            &sc.offsets,
                            tw,
                            set.paired(),
                            set.pstride,
                            [&mut l0[..], &mut l1[..], &mut l2[..]],
                        )
                    };
                if let (true, Some(counts)) = (applied, counts) {
                    st.texture += counts.texture;
                    if counts.exact > 0 {
                        for i in 0..tw {
                            if sc.class[i] == NO_CLASS {
                                let (patch, feat) = (&mut sc.patch, &mut sc.feat);
                                let rc = (r, tile.c0 + i);
                                let v = self
                                    .exact_pixel(set, rows, stride, i, rc, patch, feat, &mut st);
                                l0[i] = v[0];
                                l1[i] = v[1];
                                l2[i] = v[2];
                            }
                        }
                    }
                    let out_row = &mut band[y * row_len + offset..(y + 1) * row_len];
                    // SAFETY: as above
                    unsafe { sink.finish_row_wide(out_row, &sc.lin, tw) };
                    st.pixels += tw as u64;
                    continue;
                }
            }
            // 4. phase sums → per-phase means and luminance, then contrast and class
            if self.phases.is_some() {
                for v in sc.sums.iter_mut() {
                    v[..tw8].fill(0.0);
                }
                for dy in 0..s {
                    let j = y + dy;
                    let e = &sc.he[j * tw8..(j + 1) * tw8];
                    let o = &sc.ho[j * tw8..(j + 1) * tw8];
                    let [s0, s1, s2, s3] = &mut sc.sums;
                    let (se, so) = if (dy + rad) % 2 == 0 {
                        (s0, s1)
                    } else {
                        (s2, s3)
                    };
                    add_into(se, e);
                    add_into(so, o);
                }
                let rpar = r % 2;
                if let Some(u) = &self.uniform_phases {
                    // every channel on its own phase: means and luminance are position-free
                    let [s0, s1, s2, s3] = &sc.sums;
                    let [m0, m1, m2, m3] = &mut sc.means;
                    let (s0, s1, s2, s3) = (&s0[..tw8], &s1[..tw8], &s2[..tw8], &s3[..tw8]);
                    let (m0, m1, m2, m3) = (
                        &mut m0[..tw8],
                        &mut m1[..tw8],
                        &mut m2[..tw8],
                        &mut m3[..tw8],
                    );
                    let lum = &mut sc.lum[..tw8];
                    for i in 0..tw8 {
                        let q = [s0[i], s1[i], s2[i], s3[i]];
                        m0[i] = q[0] * u.inv[0];
                        m1[i] = q[1] * u.inv[1];
                        m2[i] = q[2] * u.inv[2];
                        m3[i] = q[3] * u.inv[3];
                        lum[i] =
                            q[0] * u.lum[0] + q[1] * u.lum[1] + q[2] * u.lum[2] + q[3] * u.lum[3];
                    }
                } else if let Some(lanes) = &lane_maps {
                    // two phases share a channel (Bayer): each column takes its position's map
                    lanes[rpar].apply(&sc.sums, &mut sc.means, &mut sc.lum, tw8);
                }
                if use_contrast {
                    contrast_row(
                        &sc.buf[y * stride..],
                        stride,
                        s,
                        rad,
                        &sc.means,
                        inv_area,
                        &mut sc.contrast[..tw8],
                    );
                }
                // classes of the pixels the fast path can take
                let cpar = tile.c0 % 2;
                let (sat, lum) = (&sc.sat[..tw], &sc.lum[..tw]);
                let (contrast, class) = (&sc.contrast[..tw], &mut sc.class[..tw]);
                let kc = self.n_chroma;
                if kc > 1 {
                    self.chroma_row::<SIMD>(&sc.means, (rpar, cpar), tw, &mut sc.chroma);
                }
                let cs = &sc.chroma;
                let bands = self.n_bands;
                for i in 0..tw {
                    let pos = rpar * 2 + (cpar + i) % 2;
                    let band = if sat[i] {
                        None
                    } else {
                        self.level_lut.level(lum[i]).and_then(|level| {
                            if kc == 1 {
                                Some(level)
                            } else {
                                // near a chroma boundary: the reference path
                                let margin = CHROMA_MARGIN * cs.scale[i] + CHROMA_MARGIN_FLOOR;
                                (cs.s2[i] - cs.s1[i] >= margin)
                                    .then(|| level * kc + cs.best[i] as usize)
                            }
                        })
                    };
                    class[i] = match band {
                        None => NO_CLASS,
                        Some(band) => {
                            let group = (pos * bands + band) * n_sat;
                            // +∞ where the contrast does not decide the class
                            let t = thresholds.get(group).copied().unwrap_or(f32::NAN);
                            let cv = contrast[i];
                            if (cv - t).abs() >= CONTRAST_MARGIN {
                                (group * 2 + (cv > t) as usize) as u32
                            } else {
                                // near the threshold, or NaN
                                NO_CLASS
                            }
                        }
                    };
                }
            }
            // 5. apply: with the AVX-512 kernel step where the tile runs with it but its
            // classification could not take the table (chroma classes, many levels)
            #[cfg(target_arch = "x86_64")]
            if WIDE {
                let rows = &sc.buf[y * stride..];
                let (patch, feat) = (&mut sc.patch, &mut sc.feat);
                let work = WideRow {
                    rows,
                    stride,
                    tw,
                    r,
                    c0: tile.c0,
                };
                // SAFETY: `WIDE` tiles run in `tile_avx512`, where the CPU has the features
                let applied = unsafe {
                    self.apply_classes_wide::<P>(
                        set,
                        &work,
                        &sc.class,
                        &mut sc.offsets,
                        &mut sc.lin,
                        (patch, feat),
                        &mut st,
                    )
                };
                if applied {
                    let out_row = &mut band[y * row_len + offset..(y + 1) * row_len];
                    // SAFETY: `WIDE` tiles run in `tile_avx512`, where the CPU has the features
                    unsafe { sink.finish_row_wide(out_row, &sc.lin, tw) };
                    st.pixels += tw as u64;
                    continue;
                }
            }
            let out_row = &mut band[y * row_len + offset..(y + 1) * row_len];
            let rows = &sc.buf[y * stride..];
            let [l0, l1, l2] = &mut sc.lin;
            let (l0, l1, l2) = (&mut l0[..tw], &mut l1[..tw], &mut l2[..tw]);
            for i in 0..tw {
                let class = sc.class[i];
                let v = if class != NO_CLASS {
                    let class = class as usize;
                    st.texture += (class & 1) as u64;
                    let k = &set.rows[class * set.stride..(class + 1) * set.stride];
                    row_dot::<SIMD>(rows, stride, i, s, k)
                } else {
                    let c = tile.c0 + i;
                    let (patch, feat) = (&mut sc.patch, &mut sc.feat);
                    self.exact_pixel(set, rows, stride, i, (r, c), patch, feat, &mut st)
                };
                l0[i] = v[0];
                l1[i] = v[1];
                l2[i] = v[2];
            }
            sink.finish_row(out_row, &sc.lin, tw);
            st.pixels += tw as u64;
        }
        st
    }
}

/// One tile row for the AVX-512 kernel step: the padded input rows under it,
/// their stride, its width and where it starts in the frame.
#[cfg(target_arch = "x86_64")]
pub(super) struct WideRow<'a> {
    pub(super) rows: &'a [f32],
    pub(super) stride: usize,
    pub(super) tw: usize,
    pub(super) r: usize,
    pub(super) c0: usize,
}

#[derive(Clone, Copy, Debug)]
pub(super) struct Tile {
    pub(super) r0: usize,
    pub(super) c0: usize,
    pub(super) rows: usize,
    pub(super) cols: usize,
}
