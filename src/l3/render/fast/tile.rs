//! One tile: its rows and halo in a buffer, their horizontal phase sums and
//! maxima, then row by row the saturation test, the classes and the kernels.

#[cfg(target_arch = "x86_64")]
use super::avx512;
use super::kernels::KernelSet;
use super::phases::LaneMaps;
use super::scratch::{RowScratch, Scratch, resize};
use super::sink::Sink;
use super::source::Source;
use super::stages::{TileRow, add_into, contrast_row, phase_sums_row, row_dot, row_peak};
use super::{
    CHROMA_MARGIN, CHROMA_MARGIN_FLOOR, CONTRAST_MARGIN, FastRenderer, LANES, NO_CLASS, Region,
    RenderStats, mirror,
};

/// What every band and tile of one render shares: the renderer, the frame, the
/// kernels, where the linear outputs go, and the region's layout in the output.
pub(super) struct TileCtx<'a, S> {
    pub(super) fr: &'a FastRenderer,
    pub(super) src: &'a Source<'a>,
    pub(super) set: &'a KernelSet,
    pub(super) sink: &'a S,
    /// The region rendered (output pixels).
    pub(super) reg: Region,
    /// Output values per row of the region (3 per pixel).
    pub(super) row_len: usize,
}

/// Rows `r0..r0 + rows`, columns `c0..c0 + cols` of the frame.
#[derive(Clone, Copy, Debug)]
pub(super) struct Tile {
    pub(super) r0: usize,
    pub(super) c0: usize,
    pub(super) rows: usize,
    pub(super) cols: usize,
}

impl Tile {
    /// Columns of the scratch rows: whole 16-lane chunks.
    #[inline(always)]
    fn padded_cols(&self) -> usize {
        self.cols.div_ceil(2 * LANES) * 2 * LANES
    }

    /// Values per row of the tile buffer: 16 more than the padded columns, so
    /// every 8- or 16-wide read of a patch row stays inside it.
    #[inline(always)]
    fn stride(&self) -> usize {
        self.padded_cols() + 2 * LANES
    }
}

/// A tile being rendered: its layout in the scratch buffers and what was
/// decided for it once, before its rows.
struct TileRun<'t> {
    tile: Tile,
    /// The patch size (the row steps use the compile-time one where there is one).
    size: usize,
    /// Pixels per row, the padded width of the scratch rows, the buffer's stride.
    tw: usize,
    tw8: usize,
    stride: usize,
    /// Where the tile's pixels start in an output row of the band.
    offset: usize,
    /// The saturation threshold, and whether any value of the tile reaches it.
    thr: f32,
    any_sat: bool,
    /// Whether the contrast is measured, and the thresholds the classes use.
    use_contrast: bool,
    thresholds: &'t [f32],
    inv_area: f32,
    /// Where two phases share a channel (Bayer), each row parity's maps per lane.
    lane_maps: Option<[LaneMaps; 2]>,
}

impl<S> TileCtx<'_, S> {
    /// Render one tile into the band's rows (its pixels start at column
    /// `tile.c0 − reg.x` of each).
    #[inline(always)]
    pub(super) fn tile<const SIMD: bool, const WIDE: bool, const P: usize, T>(
        &self,
        tile: Tile,
        sc: &mut Scratch,
        band: &mut [T],
    ) -> RenderStats
    where
        S: Sink<T>,
    {
        let fr = self.fr;
        // P: the patch size known at compile time (0: not)
        let s = if P != 0 { P } else { fr.geo.size };
        // 1. the tile and its halo, clamped volts, mirrored at the frame's borders
        let peak = self.load(tile, s, &mut sc.buf);
        let run = self.plan(tile, s, peak);
        // 2. horizontal phase sums (and maxima where saturation is possible)
        if fr.phases.is_some() {
            run.phase_sums::<P>(sc);
        }
        if run.any_sat {
            run.row_maxima::<P>(sc);
        }
        run.prepare_rows(&mut sc.row, fr.n_features);
        #[cfg(target_arch = "x86_64")]
        let wide = if WIDE && fr.phases.is_some() {
            fr.class_params(run.thresholds, run.use_contrast, self.set)
        } else {
            None
        };
        let mut st = RenderStats::default();
        for y in 0..tile.rows {
            // 3. which pixels see a saturated value
            if run.any_sat {
                run.sat_row::<P>(sc, y);
            }
            let out_row = &mut band[y * self.row_len + run.offset..(y + 1) * self.row_len];
            #[cfg(target_arch = "x86_64")]
            if let Some(prm) = &wide
                && self.wide_row::<P, T>(&run, prm, sc, y, out_row, &mut st)
            {
                continue;
            }
            // 4. phase sums → per-phase means and luminance, then contrast and class
            if fr.phases.is_some() {
                self.classify_row::<SIMD, P>(&run, sc, y);
            }
            // 5. apply: with the AVX-512 kernel step where the tile runs with it but its
            // classification could not take the table (chroma classes, many levels)
            #[cfg(target_arch = "x86_64")]
            if WIDE && self.apply_row_wide::<P, T>(&run, sc, y, out_row, &mut st) {
                continue;
            }
            self.apply_row::<SIMD, P, T>(&run, sc, y, out_row, &mut st);
        }
        st
    }

    /// Copy the tile's rows and their halo (`s / 2` on each side) into `buf` as
    /// clamped volts, mirrored at the frame's borders; returns the largest value.
    /// Columns past the halo are never weighted (zero kernel weights), so stale
    /// finite values from an earlier tile may stay there: no clearing needed.
    #[inline(always)]
    fn load(&self, tile: Tile, s: usize, buf: &mut Vec<f32>) -> f32 {
        let src = self.src;
        let rad = s / 2;
        let tw = tile.cols;
        let stride = tile.stride();
        let brows = tile.rows + 2 * rad;
        resize(buf, brows * stride);
        let mut peak = 0f32;
        let first = tile.c0 as isize - rad as isize;
        let span = tw + 2 * rad;
        // the part of the span inside the frame, and its offset in the buffer row
        let lo = first.max(0) as usize;
        let hi = (first + span as isize).min(src.width as isize) as usize;
        let off = (lo as isize - first) as usize;
        for j in 0..brows {
            let r = mirror(tile.r0 as isize + j as isize - rad as isize, src.height);
            let row = &mut buf[j * stride..j * stride + span];
            if hi > lo {
                src.row_into(r, lo, &mut row[off..off + (hi - lo)]);
            }
            for i in (0..off).chain(off + hi.saturating_sub(lo)..span) {
                row[i] = src.at(r, mirror(first + i as isize, src.width));
            }
            peak = peak.max(row_peak(row));
        }
        peak
    }

    /// What the tile's rows share: its layout, whether saturation is possible
    /// (the largest value `peak` reaches the threshold), whether the contrast
    /// matters and by which thresholds, the phase maps per lane.
    #[inline(always)]
    fn plan(&self, tile: Tile, s: usize, peak: f32) -> TileRun<'_> {
        let fr = self.fr;
        let thr = fr.geo.sat_threshold();
        let any_sat = !fr.options.skip_unsaturated_tiles || peak >= thr;
        let use_contrast = fr.contrast_classes
            && (!fr.options.skip_equal_contrast_kernels || fr.contrast_matters.iter().any(|&m| m));
        let thresholds = if !use_contrast {
            &fr.no_thresholds
        } else if fr.options.skip_equal_contrast_kernels {
            &fr.thresholds_where_they_matter
        } else {
            &fr.contrast_thresholds
        };
        let lane_maps = match (&fr.phases, &fr.uniform_phases) {
            (Some(maps), None) => {
                Some([0, 1].map(|rpar| LaneMaps::of_row(maps, rpar, tile.c0 % 2)))
            }
            _ => None,
        };
        TileRun {
            tile,
            size: s,
            tw: tile.cols,
            tw8: tile.padded_cols(),
            stride: tile.stride(),
            offset: 3 * (tile.c0 - self.reg.x),
            thr,
            any_sat,
            use_contrast,
            thresholds,
            inv_area: 1.0 / (s * s) as f32,
            lane_maps,
        }
    }

    /// The AVX-512 classification and kernel step of output row `y`, and its
    /// output through the sink. Returns `false`, having written no output, when
    /// a kernel refuses its arguments (the portable steps then do the row).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn wide_row<const P: usize, T>(
        &self,
        run: &TileRun<'_>,
        prm: &avx512::ClassParams,
        sc: &mut Scratch,
        y: usize,
        out_row: &mut [T],
        st: &mut RenderStats,
    ) -> bool
    where
        S: Sink<T>,
    {
        let (tw, tw8, stride) = (run.tw, run.tw8, run.stride);
        let r = run.tile.r0 + y;
        let Scratch {
            buf,
            he,
            ho,
            row: rs,
            ..
        } = sc;
        let rows = &buf[y * stride..];
        let sat = run.any_sat.then_some(&rs.sat[..]);
        let (he, ho) = (&he[y * tw8..], &ho[y * tw8..]);
        let (rpar, cpar) = (r % 2, run.tile.c0 % 2);
        let classify = avx512::ClassifyRow {
            he,
            ho,
            tw_pad: tw8,
            buf: rows,
            stride,
            sat,
            tw,
            rpar,
            cpar,
        };
        // SAFETY: `wide` is only set in `tile_avx512`, which runs when the CPU has
        // the features; the kernels check the lengths of what they touch.
        let counts =
            unsafe { avx512::classify_row::<P>(&classify, prm, &mut rs.class, &mut rs.offsets) };
        let [l0, l1, l2] = &mut rs.lin;
        let kernels = avx512::KernelRow {
            buf: rows,
            stride,
            offsets: &rs.offsets,
            tw,
            kernels: self.set.paired(),
            kstride: self.set.pstride,
        };
        let applied = counts.is_some()
            // SAFETY: as above
            && unsafe {
                avx512::apply_kernels::<P>(&kernels, [&mut l0[..], &mut l1[..], &mut l2[..]])
            };
        let (true, Some(counts)) = (applied, counts) else {
            return false;
        };
        st.texture += counts.texture;
        if counts.exact > 0 {
            let row = TileRow {
                rows,
                stride,
                tw,
                r,
                c0: run.tile.c0,
            };
            self.fr.exact_pixels(self.set, &row, rs, st);
        }
        // SAFETY: as above
        unsafe { self.sink.finish_row_wide(out_row, &rs.lin, tw) };
        st.pixels += tw as u64;
        true
    }

    /// The portable classification of output row `y`: phase sums → per-phase
    /// means and luminance, the contrast, then each pixel's class
    /// ([`NO_CLASS`] where the reference code must decide).
    #[inline(always)]
    fn classify_row<const SIMD: bool, const P: usize>(
        &self,
        run: &TileRun<'_>,
        sc: &mut Scratch,
        y: usize,
    ) {
        let s = if P != 0 { P } else { run.size };
        let (tw8, stride) = (run.tw8, run.stride);
        let rpar = (run.tile.r0 + y) % 2;
        self.fr.phase_means::<P>(run, sc, y);
        let rs = &mut sc.row;
        if run.use_contrast {
            contrast_row(
                &sc.buf[y * stride..],
                stride,
                s,
                s / 2,
                &rs.means,
                run.inv_area,
                &mut rs.contrast[..tw8],
            );
        }
        self.fr.classes::<SIMD>(run, rs, rpar);
    }

    /// The AVX-512 kernel step over output row `y`, whose classes the portable
    /// code found, and its output through the sink; `false` when the kernel step
    /// refuses its arguments, having written no output.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn apply_row_wide<const P: usize, T>(
        &self,
        run: &TileRun<'_>,
        sc: &mut Scratch,
        y: usize,
        out_row: &mut [T],
        st: &mut RenderStats,
    ) -> bool
    where
        S: Sink<T>,
    {
        let row = TileRow {
            rows: &sc.buf[y * run.stride..],
            stride: run.stride,
            tw: run.tw,
            r: run.tile.r0 + y,
            c0: run.tile.c0,
        };
        // SAFETY: `WIDE` tiles run in `tile_avx512`, where the CPU has the features
        let applied = unsafe {
            self.fr
                .apply_classes_wide::<P>(self.set, &row, &mut sc.row, st)
        };
        if applied {
            // SAFETY: `WIDE` tiles run in `tile_avx512`, where the CPU has the features
            unsafe { self.sink.finish_row_wide(out_row, &sc.row.lin, run.tw) };
            st.pixels += run.tw as u64;
        }
        applied
    }

    /// The portable kernel step over output row `y` (the row kernels, or the
    /// reference path for pixels without a class), and its output through the sink.
    #[inline(always)]
    fn apply_row<const SIMD: bool, const P: usize, T>(
        &self,
        run: &TileRun<'_>,
        sc: &mut Scratch,
        y: usize,
        out_row: &mut [T],
        st: &mut RenderStats,
    ) where
        S: Sink<T>,
    {
        let s = if P != 0 { P } else { run.size };
        let (set, tw, stride) = (self.set, run.tw, run.stride);
        let row = TileRow {
            rows: &sc.buf[y * stride..],
            stride,
            tw,
            r: run.tile.r0 + y,
            c0: run.tile.c0,
        };
        let rs = &mut sc.row;
        let [l0, l1, l2] = &mut rs.lin;
        let (l0, l1, l2) = (&mut l0[..tw], &mut l1[..tw], &mut l2[..tw]);
        for i in 0..tw {
            let class = rs.class[i];
            let v = if class != NO_CLASS {
                let class = class as usize;
                st.texture += (class & 1) as u64;
                let k = &set.rows[class * set.stride..(class + 1) * set.stride];
                row_dot::<SIMD>(row.rows, stride, i, s, k)
            } else {
                let px = (&mut rs.patch[..], &mut rs.feat[..]);
                self.fr.exact_pixel(set, &row, i, px, st)
            };
            l0[i] = v[0];
            l1[i] = v[1];
            l2[i] = v[2];
        }
        self.sink.finish_row(out_row, &rs.lin, tw);
        st.pixels += tw as u64;
    }
}

impl TileRun<'_> {
    /// Horizontal sums of every buffer row over the patch's even (`he`) and odd
    /// (`ho`) column offsets from the centre.
    #[inline(always)]
    fn phase_sums<const P: usize>(&self, sc: &mut Scratch) {
        let s = if P != 0 { P } else { self.size };
        let rad = s / 2;
        let (tw8, stride) = (self.tw8, self.stride);
        let brows = self.tile.rows + 2 * rad;
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

    /// Horizontal maxima of every buffer row over the patch's columns.
    #[inline(always)]
    fn row_maxima<const P: usize>(&self, sc: &mut Scratch) {
        let s = if P != 0 { P } else { self.size };
        let (tw8, stride) = (self.tw8, self.stride);
        let brows = self.tile.rows + 2 * (s / 2);
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

    /// Size the row buffers for this tile's width and reset the per-row flags.
    #[inline(always)]
    fn prepare_rows(&self, rs: &mut RowScratch, nf: usize) {
        let (s, tw8) = (self.size, self.tw8);
        for v in rs
            .sums
            .iter_mut()
            .chain(rs.means.iter_mut())
            .chain(rs.lin.iter_mut())
        {
            resize(v, tw8);
        }
        resize(&mut rs.lum, tw8);
        resize(&mut rs.contrast, tw8);
        if rs.sat.len() < tw8 {
            rs.sat.resize(tw8, false);
        }
        rs.sat[..tw8].fill(false);
        if rs.class.len() < tw8 {
            rs.class.resize(tw8, NO_CLASS);
        }
        rs.class[..tw8].fill(NO_CLASS);
        if rs.offsets.len() < tw8 {
            rs.offsets.resize(tw8, 0);
        }
        rs.patch.clear();
        rs.patch.resize(s * s, 0.0);
        rs.feat.clear();
        rs.feat.resize(nf, 0.0);
    }

    /// Which pixels of output row `y` have a saturated value in their patch.
    #[inline(always)]
    fn sat_row<const P: usize>(&self, sc: &mut Scratch, y: usize) {
        let s = if P != 0 { P } else { self.size };
        let tw8 = self.tw8;
        let sat = &mut sc.row.sat[..tw8];
        sat.fill(false);
        for dy in 0..s {
            let h = &sc.hmax[(y + dy) * tw8..(y + dy + 1) * tw8];
            for (f, &v) in sat.iter_mut().zip(h) {
                *f |= v >= self.thr;
            }
        }
    }
}

impl FastRenderer {
    /// The phase sums of output row `y`'s patches (from the horizontal sums of
    /// its patch rows), then each pixel's per-phase means and luminance.
    #[inline(always)]
    fn phase_means<const P: usize>(&self, run: &TileRun<'_>, sc: &mut Scratch, y: usize) {
        let s = if P != 0 { P } else { run.size };
        let rad = s / 2;
        let tw8 = run.tw8;
        let rs = &mut sc.row;
        for v in rs.sums.iter_mut() {
            v[..tw8].fill(0.0);
        }
        for dy in 0..s {
            let j = y + dy;
            let e = &sc.he[j * tw8..(j + 1) * tw8];
            let o = &sc.ho[j * tw8..(j + 1) * tw8];
            let [s0, s1, s2, s3] = &mut rs.sums;
            let (se, so) = if (dy + rad) % 2 == 0 {
                (s0, s1)
            } else {
                (s2, s3)
            };
            add_into(se, e);
            add_into(so, o);
        }
        let rpar = (run.tile.r0 + y) % 2;
        if let Some(u) = &self.uniform_phases {
            // every channel on its own phase: means and luminance are position-free
            let [s0, s1, s2, s3] = &rs.sums;
            let [m0, m1, m2, m3] = &mut rs.means;
            let (s0, s1, s2, s3) = (&s0[..tw8], &s1[..tw8], &s2[..tw8], &s3[..tw8]);
            let (m0, m1, m2, m3) = (
                &mut m0[..tw8],
                &mut m1[..tw8],
                &mut m2[..tw8],
                &mut m3[..tw8],
            );
            let lum = &mut rs.lum[..tw8];
            for i in 0..tw8 {
                let q = [s0[i], s1[i], s2[i], s3[i]];
                m0[i] = q[0] * u.inv[0];
                m1[i] = q[1] * u.inv[1];
                m2[i] = q[2] * u.inv[2];
                m3[i] = q[3] * u.inv[3];
                lum[i] = q[0] * u.lum[0] + q[1] * u.lum[1] + q[2] * u.lum[2] + q[3] * u.lum[3];
            }
        } else if let Some(lanes) = &run.lane_maps {
            // two phases share a channel (Bayer): each column takes its position's map
            lanes[rpar].apply(&rs.sums, &mut rs.means, &mut rs.lum, tw8);
        }
    }

    /// The classes of the pixels of a row (row parity `rpar`) that the fast
    /// path can take, from their luminance, chroma scores and contrast;
    /// [`NO_CLASS`] for the others.
    #[inline(always)]
    fn classes<const SIMD: bool>(&self, run: &TileRun<'_>, rs: &mut RowScratch, rpar: usize) {
        let tw = run.tw;
        let cpar = run.tile.c0 % 2;
        let n_sat = self.sat_cases.len();
        let thresholds = run.thresholds;
        let (sat, lum) = (&rs.sat[..tw], &rs.lum[..tw]);
        let (contrast, class) = (&rs.contrast[..tw], &mut rs.class[..tw]);
        let kc = self.n_chroma;
        if kc > 1 {
            self.chroma_row::<SIMD>(&rs.means, (rpar, cpar), tw, &mut rs.chroma);
        }
        let cs = &rs.chroma;
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
                        (cs.s2[i] - cs.s1[i] >= margin).then(|| level * kc + cs.best[i] as usize)
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
}
