//! The sensor: spectral responsivities resolved on a grid, photo-electron
//! rates, the noise model (shot, read, DSNU, PRNU, dark current), exposure,
//! and the ideal XYZ target in volts-equivalent units.

use ndarray::{Array2, Array3, ArrayView2, ArrayView3};
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{CameraError, Cfa, OpticalImage, Optics, SensorDesign};
use crate::scene::MAX_SCENE_VALUES;
use crate::spectral::{Extrapolation, IsetData, Spectrum, WavelengthGrid, cie1931_cmfs};

/// Planck constant, J·s.
const H_PLANCK: f64 = 6.626_070_15e-34;
/// Speed of light, m/s.
const C_LIGHT: f64 = 2.997_924_58e8;

/// Rows per noise chunk: every chunk has its own generator seeded from
/// `(seed, chunk index)`, so frames do not depend on the thread count.
const NOISE_CHUNK_ROWS: usize = 8;

/// Longest exposure [`Camera::auto_exposure`] returns (for black scenes), s.
pub const MAX_AUTO_EXPOSURE_S: f64 = 10.0;

/// Percentile of the mosaicked noise-free signal that auto-exposure places at
/// the target level (a robust maximum: 0.1 % of pixels may clip).
pub const AUTO_EXPOSURE_PERCENTILE: f64 = 99.9;

/// Domain tags mixed into seeds so frame noise and fixed patterns never share
/// a stream, even when `seed == fpn_seed`.
const TAG_NOISE: u64 = 0x6e6f_6973_655f_7631; // "noise_v1"
const TAG_FPN: u64 = 0x6670_6e5f_7061_7431; // "fpn_pat1"

/// Which noise sources a capture includes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NoiseSwitches {
    /// Photon shot noise (Poisson electrons).
    pub shot: bool,
    /// Read noise (Gaussian, per frame).
    pub read: bool,
    /// Dark signal non-uniformity (fixed per-pixel offset).
    pub dsnu: bool,
    /// Photo-response non-uniformity (fixed per-pixel gain).
    pub prnu: bool,
    /// Dark current electrons.
    pub dark: bool,
}

impl NoiseSwitches {
    /// Every source on (the realistic sensor).
    pub fn all() -> Self {
        Self {
            shot: true,
            read: true,
            dsnu: true,
            prnu: true,
            dark: true,
        }
    }

    /// Every source off: captures are the noise-free mean (still clipped).
    pub fn none() -> Self {
        Self {
            shot: false,
            read: false,
            dsnu: false,
            prnu: false,
            dark: false,
        }
    }
}

impl Default for NoiseSwitches {
    fn default() -> Self {
        Self::all()
    }
}

/// How the exposure time is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Exposure {
    /// The robust maximum of the frame reaches `target_fraction` of the swing
    /// (see [`Camera::auto_exposure`]).
    Auto { target_fraction: f64 },
    /// A fixed exposure time in seconds.
    Seconds(f64),
    /// `factor` times the auto-exposure time (`factor` < 1: less light than
    /// the auto-exposure collects, as at a longest-exposure limit in dim light).
    Scaled { target_fraction: f64, factor: f64 },
}

impl Default for Exposure {
    /// Auto-exposure to 95 % of the swing.
    fn default() -> Self {
        Exposure::Auto {
            target_fraction: 0.95,
        }
    }
}

/// A sensor design resolved on a wavelength grid, with its lens.
#[derive(Clone, Debug)]
pub struct Camera {
    design: SensorDesign,
    optics: Optics,
    grid: WavelengthGrid,
    cfa: Cfa,
    /// Per channel (CFA order): filter × IR-cut × QE, electrons per photon.
    responsivity: Vec<Spectrum>,
    /// Per channel: electrons/s per unit irradiance in each band,
    /// `A · ff · λ_b/(hc) · resp_c(b) · Δλ`.
    electron_weights: Vec<Vec<f64>>,
    /// Per XYZ component: volts/s per unit irradiance in each band,
    /// `A · ff · cg · gain · κ · cmf_k(b) · Δλ`.
    xyz_weights: Vec<Vec<f64>>,
    xyz_scale: f64,
}

impl Camera {
    /// Resolve `design` on `grid` (CSV curves read through `iset`).
    pub fn new(
        design: &SensorDesign,
        grid: WavelengthGrid,
        iset: Option<&IsetData>,
    ) -> Result<Camera, CameraError> {
        if grid.n == 0 {
            return Err(CameraError::InvalidArgument(
                "the wavelength grid is empty".into(),
            ));
        }
        let responsivity = design.resolve_curves(&grid, iset)?;
        let area_ff = design.pixel_area_m2() * design.fill_factor;
        let dl = grid.step_nm;
        let photons_per_joule: Vec<f64> = grid
            .wavelengths()
            .iter()
            .map(|&l| l * 1e-9 / (H_PLANCK * C_LIGHT))
            .collect();
        let electron_weights: Vec<Vec<f64>> = responsivity
            .iter()
            .map(|r| {
                r.values()
                    .iter()
                    .zip(&photons_per_joule)
                    .map(|(q, p)| area_ff * q * p * dl)
                    .collect()
            })
            .collect();
        let cmfs = cie1931_cmfs().map(|c| c.resample(&grid, Extrapolation::Zero));
        let ybar_sum: f64 = cmfs[1].values().iter().sum();
        if ybar_sum <= 0.0 {
            return Err(CameraError::InvalidArgument(format!(
                "the grid {}–{} nm does not overlap the CIE colour-matching functions",
                grid.start_nm,
                grid.end_nm()
            )));
        }
        // κ: electrons per joule such that for an equal-energy irradiance Y
        // equals the mean channel signal.
        let xyz_scale = responsivity
            .iter()
            .map(|r| {
                r.values()
                    .iter()
                    .zip(&photons_per_joule)
                    .map(|(q, p)| q * p)
                    .sum::<f64>()
            })
            .sum::<f64>()
            / responsivity.len() as f64
            / ybar_sum;
        let volts_per_e = design.conversion_gain_v() * design.analog_gain;
        let xyz_weights = cmfs
            .iter()
            .map(|c| {
                c.values()
                    .iter()
                    .map(|v| area_ff * volts_per_e * xyz_scale * v * dl)
                    .collect()
            })
            .collect();
        Ok(Camera {
            design: design.clone(),
            optics: design.optics,
            grid,
            cfa: design.cfa.clone(),
            responsivity,
            electron_weights,
            xyz_weights,
            xyz_scale,
        })
    }

    pub fn design(&self) -> &SensorDesign {
        &self.design
    }

    pub fn optics(&self) -> &Optics {
        &self.optics
    }

    pub fn grid(&self) -> &WavelengthGrid {
        &self.grid
    }

    /// The design's CFA; channel `i` of every rate cube is `cfa().channel_names[i]`.
    pub fn cfa(&self) -> &Cfa {
        &self.cfa
    }

    pub fn n_channels(&self) -> usize {
        self.responsivity.len()
    }

    /// Spectral responsivity of channel `c` (filter × IR-cut × QE, electrons
    /// per photon) on the grid, for every channel in CFA order.
    pub fn responsivity(&self) -> &[Spectrum] {
        &self.responsivity
    }

    /// κ, in electrons per joule: the fixed constant tying the ideal XYZ
    /// target to the sensor's volts. `X_k = A·ff·cg·gain·κ·Σ_b cmf_k(b)·E_b·Δλ`
    /// (volts per second, E the irradiance in W/(m²·nm)), with
    /// `κ = mean_c Σ_b resp_c(b)·λ_b/(hc) / Σ_b ȳ_b`, so that under an
    /// equal-energy irradiance Y equals the mean over channels of the channel
    /// volts. Multiply rates by the exposure time for volts-equivalent XYZ.
    pub fn xyz_scale(&self) -> f64 {
        self.xyz_scale
    }

    /// Noise-free channel responses and volts-equivalent XYZ of a uniform
    /// surface with `reflectance` under `illuminant`, without optics, in a
    /// common scale (per unit radiance scale and exposure): the data colour
    /// maps are fitted on. Channels in CFA order.
    pub fn reflectance_response(
        &self,
        reflectance: &Spectrum,
        illuminant: &Spectrum,
    ) -> Result<(Vec<f64>, [f64; 3]), CameraError> {
        let e = reflectance.product(illuminant)?;
        if e.grid() != &self.grid {
            return Err(CameraError::GridMismatch {
                what: "reflectance × illuminant".into(),
                expected: self.grid,
                got: *e.grid(),
            });
        }
        let chans = self
            .electron_weights
            .iter()
            .map(|w| {
                w.iter().zip(e.values()).map(|(a, b)| a * b).sum::<f64>()
                    * self.design.conversion_gain_v()
                    * self.design.analog_gain
            })
            .collect();
        let xyz = [0, 1, 2].map(|k| {
            self.xyz_weights[k]
                .iter()
                .zip(e.values())
                .map(|(a, b)| a * b)
                .sum::<f64>()
        });
        Ok((chans, xyz))
    }

    /// The optical image of `scene` (one scene pixel per sensor pixel),
    /// sampled [`Optics::samples_per_pixel`] times per pixel side; the
    /// channel and XYZ projections integrate each pixel's samples. A scene
    /// too large for that many samples (over [`MAX_SCENE_VALUES`] values)
    /// gets the most that fit, down to one.
    pub fn optical_image(&self, scene: &crate::scene::Scene) -> Result<OpticalImage, CameraError> {
        let values = scene.bands() * scene.rows() * scene.cols();
        let mut k = self.optics.samples_per_pixel.max(1) as usize;
        while k > 1 && values.saturating_mul(k * k) > MAX_SCENE_VALUES {
            k -= 1;
        }
        if k == 1 {
            return self.optics.image(scene, self.design.pixel_size_um);
        }
        self.optics
            .image(&scene.upsampled(k), self.design.pixel_size_um / k as f64)
    }

    /// Noise-free photo-electrons per second of every channel at every pixel,
    /// shape `(channels, rows, cols)`:
    /// `A · ff · Σ_b E_b · λ_b/(hc) · resp_c(b) · Δλ`.
    ///
    /// The optical image must be sampled at the pixel pitch or an integer
    /// fraction of it (`k` samples per pixel side); in the latter case each
    /// pixel integrates its `k × k` samples (a full-pixel box aperture).
    pub fn channel_rates(&self, optical: &OpticalImage) -> Result<Array3<f32>, CameraError> {
        let irr = self.check_optical(optical)?;
        let weights = weigh(&self.electron_weights, &irr);
        self.project(optical, &weights)
    }

    /// Noise-free CIE XYZ of `optical` relit under `illuminant` at the same
    /// mean luminance, in volts-equivalent per second (see [`Camera::xyz_scale`]),
    /// shape `(rows, cols, 3)`, on the same pixel sampling as
    /// [`Camera::channel_rates`].
    pub fn xyz_rates(
        &self,
        optical: &OpticalImage,
        illuminant: &Spectrum,
    ) -> Result<Array3<f32>, CameraError> {
        let relit = optical.relit(illuminant, optical.mean_luminance)?;
        let irr = self.check_optical(&relit)?;
        let weights = weigh(&self.xyz_weights, &irr);
        let planes = self.project(&relit, &weights)?;
        Ok(planes
            .permuted_axes([1, 2, 0])
            .as_standard_layout()
            .into_owned())
    }

    /// Grid and sampling checks; returns the irradiance per reflectance.
    fn check_optical(&self, optical: &OpticalImage) -> Result<Vec<f64>, CameraError> {
        if optical.grid != self.grid {
            return Err(CameraError::GridMismatch {
                what: "optical image".into(),
                expected: self.grid,
                got: optical.grid,
            });
        }
        self.samples_per_pixel(optical)?;
        Ok(optical.irradiance_per_reflectance())
    }

    /// Samples per pixel side: `pixel_size / sample_spacing`, which must be a
    /// positive integer (within 1e-6).
    fn samples_per_pixel(&self, optical: &OpticalImage) -> Result<usize, CameraError> {
        let ratio = self.design.pixel_size_um / optical.sample_spacing_um;
        let k = ratio.round();
        if !(k >= 1.0 && (ratio - k).abs() < 1e-6 * k) {
            return Err(CameraError::InvalidArgument(format!(
                "the optical image is sampled every {} µm; the {} µm pixel must be a whole \
                 number of samples",
                optical.sample_spacing_um, self.design.pixel_size_um
            )));
        }
        let k = k as usize;
        if optical.rows() < k || optical.cols() < k {
            return Err(CameraError::InvalidArgument(format!(
                "the optical image ({}×{} samples) is smaller than one {k}×{k}-sample pixel",
                optical.rows(),
                optical.cols()
            )));
        }
        Ok(k)
    }

    /// `out[j, r, c] = mean over the pixel's samples of Σ_b w[j][b] · refl[b, ·, ·]`,
    /// accumulated in f64, parallel over output rows.
    fn project(&self, optical: &OpticalImage, w: &[Vec<f64>]) -> Result<Array3<f32>, CameraError> {
        let k = self.samples_per_pixel(optical)?;
        let cube = optical.blurred_reflectance.as_standard_layout();
        let cube = cube.view();
        Ok(project_cube(cube, w, k))
    }

    /// Exposure time (s) placing the 99.9th percentile of the mosaicked
    /// noise-free signal (photo-electrons plus dark current, in volts) at
    /// `target_fraction` of the voltage swing, accounting for the offset.
    /// A robust maximum: specular pixels (≤ 0.1 %) may clip. Returns at most
    /// [`MAX_AUTO_EXPOSURE_S`] (for black frames).
    pub fn auto_exposure(
        &self,
        rates: &Array3<f32>,
        cfa: &Cfa,
        target_fraction: f64,
    ) -> Result<f64, CameraError> {
        if !(target_fraction.is_finite() && target_fraction > 0.0 && target_fraction <= 1.0) {
            return Err(CameraError::InvalidArgument(format!(
                "auto-exposure target {target_fraction} must be within (0, 1]"
            )));
        }
        let d = &self.design;
        let level = target_fraction * d.voltage_swing_v - d.offset_v;
        if level <= 0.0 {
            return Err(CameraError::InvalidArgument(format!(
                "auto-exposure target {} V is below the offset {} V",
                target_fraction * d.voltage_swing_v,
                d.offset_v
            )));
        }
        let mut m = mosaic(rates, cfa)?.into_raw_vec_and_offset().0;
        if m.is_empty() {
            return Err(CameraError::InvalidArgument(
                "auto-exposure needs a non-empty frame".into(),
            ));
        }
        if let Some(v) = m.iter().find(|v| !v.is_finite() || **v < 0.0) {
            return Err(CameraError::InvalidArgument(format!(
                "electron rates must be finite and non-negative (found {v})"
            )));
        }
        let rank = ((AUTO_EXPOSURE_PERCENTILE / 100.0) * (m.len() - 1) as f64).round() as usize;
        let (_, robust_max, _) = m.select_nth_unstable_by(rank, |a, b| a.total_cmp(b));
        let volts_per_s = *robust_max as f64 * d.conversion_gain_v() * d.analog_gain
            + d.dark_voltage_v_per_s * d.analog_gain;
        if volts_per_s <= 0.0 {
            return Ok(MAX_AUTO_EXPOSURE_S);
        }
        Ok((level / volts_per_s).min(MAX_AUTO_EXPOSURE_S))
    }

    /// Analytic mean and variance (V, V²) of an unclipped pixel with mean
    /// photo-electron rate `rate_e_per_s` (before PRNU) over `exposure_s`,
    /// across pixels (fixed patterns included) and frames:
    /// `mean = gain·cg·(S + D) + offset`,
    /// `var = (gain·cg)²·(S + D) + (gain·cg)²·S²·σ_prnu² + σ_dsnu² + σ_read²`
    /// with `S = rate·t`, `D = dark_voltage·t / cg`, each term only when its switch is on.
    pub fn analytic_noise(
        &self,
        rate_e_per_s: f64,
        exposure_s: f64,
        noise: &NoiseSwitches,
    ) -> (f64, f64) {
        let d = &self.design;
        let g = d.conversion_gain_v() * d.analog_gain;
        let s = rate_e_per_s * exposure_s;
        let dark = if noise.dark {
            d.dark_voltage_v_per_s * exposure_s / d.conversion_gain_v()
        } else {
            0.0
        };
        let mean = g * (s + dark) + d.offset_v;
        let mut var = 0.0;
        if noise.shot {
            var += g * g * (s + dark);
        }
        if noise.prnu {
            var += (g * s * d.prnu_fraction()).powi(2);
        }
        if noise.dsnu {
            var += d.dsnu_v().powi(2);
        }
        if noise.read {
            var += d.read_noise_v().powi(2);
        }
        (mean, var)
    }

    /// Simulate one frame from per-pixel mean photo-electron rates (e.g. from
    /// [`mosaic`]), in volts, shape of `mean_rate`:
    ///
    /// electrons = Poisson(rate·t·(1 + PRNU) + dark) (the mean without shot
    /// noise), clipped at the well capacity; volts = electrons·cg·gain + DSNU +
    /// read noise + offset, clipped to [0, swing]; then quantised to the ADC
    /// (`round(v/lsb)·lsb`, lsb = swing/(2^bits − 1)) when the design has one.
    ///
    /// DSNU and PRNU are fixed patterns of the design's `fpn_seed` and the
    /// pixel position; shot and read noise come from `seed`. The same inputs
    /// give the same bytes whatever the number of threads.
    pub fn capture(
        &self,
        mean_rate: &Array2<f32>,
        exposure_s: f64,
        noise: &NoiseSwitches,
        seed: u64,
    ) -> Result<Array2<f32>, CameraError> {
        let mut out = Array2::zeros(mean_rate.dim());
        self.capture_into(mean_rate.view(), exposure_s, noise, seed, &mut out)?;
        Ok(out)
    }

    /// [`Camera::capture`] into a caller-owned buffer (resized if its shape differs).
    pub fn capture_into(
        &self,
        mean_rate: ArrayView2<f32>,
        exposure_s: f64,
        noise: &NoiseSwitches,
        seed: u64,
        out: &mut Array2<f32>,
    ) -> Result<(), CameraError> {
        if !(exposure_s.is_finite() && exposure_s >= 0.0) {
            return Err(CameraError::InvalidArgument(format!(
                "exposure time {exposure_s} s must be finite and non-negative"
            )));
        }
        if let Some(v) = mean_rate.iter().find(|v| !v.is_finite() || **v < 0.0) {
            return Err(CameraError::InvalidArgument(format!(
                "electron rates must be finite and non-negative (found {v})"
            )));
        }
        let (rows, cols) = mean_rate.dim();
        if out.dim() != (rows, cols) || !out.is_standard_layout() {
            *out = Array2::zeros((rows, cols));
        }
        if rows == 0 || cols == 0 {
            return Ok(());
        }
        let rates = mean_rate.as_standard_layout();
        let rates = rates
            .as_slice()
            .ok_or_else(|| CameraError::InvalidArgument("rate image is not contiguous".into()))?;
        let p = PixelModel::new(&self.design, exposure_s, noise);
        let fpn_key = seed_key(self.design.fpn_seed, TAG_FPN);
        let noise_key = seed_key(seed, TAG_NOISE);
        let dst = out
            .as_slice_mut()
            .ok_or_else(|| CameraError::InvalidArgument("output is not contiguous".into()))?;
        dst.par_chunks_mut(NOISE_CHUNK_ROWS * cols)
            .enumerate()
            .for_each_init(
                || (vec![0.0f32; cols], vec![0.0f32; cols]),
                |(dsnu, prnu), (chunk, out_rows)| {
                    let mut rng = ChaCha8Rng::from_seed(noise_key);
                    rng.set_stream(chunk as u64);
                    let r0 = chunk * NOISE_CHUNK_ROWS;
                    for (i, out_row) in out_rows.chunks_mut(cols).enumerate() {
                        let r = r0 + i;
                        fixed_pattern_row(fpn_key, r, dsnu, prnu);
                        let rate_row = &rates[r * cols..(r + 1) * cols];
                        for c in 0..cols {
                            out_row[c] = p.pixel(rate_row[c], dsnu[c], prnu[c], &mut rng);
                        }
                    }
                },
            );
        Ok(())
    }

    /// The fixed patterns of this sensor for a `rows × cols` frame: DSNU
    /// offsets in volts and PRNU gains (1 + δ), shape `(rows, cols)` each.
    pub fn fixed_patterns(&self, rows: usize, cols: usize) -> (Array2<f32>, Array2<f32>) {
        let key = seed_key(self.design.fpn_seed, TAG_FPN);
        let (sd, sp) = (self.design.dsnu_v(), self.design.prnu_fraction());
        let mut dsnu = Array2::zeros((rows, cols));
        let mut prnu = Array2::zeros((rows, cols));
        let (mut zd, mut zp) = (vec![0.0f32; cols], vec![0.0f32; cols]);
        for r in 0..rows {
            fixed_pattern_row(key, r, &mut zd, &mut zp);
            for c in 0..cols {
                dsnu[(r, c)] = (sd * zd[c] as f64) as f32;
                prnu[(r, c)] = (1.0 + sp * zp[c] as f64) as f32;
            }
        }
        (dsnu, prnu)
    }
}

/// `w[j][b] · irr[b]`.
fn weigh(w: &[Vec<f64>], irr: &[f64]) -> Vec<Vec<f64>> {
    w.iter()
        .map(|row| row.iter().zip(irr).map(|(a, b)| a * b).collect())
        .collect()
}

/// See [`Camera::project`]: `k` samples per pixel side (the pixel box).
fn project_cube(cube: ArrayView3<f32>, w: &[Vec<f64>], k: usize) -> Array3<f32> {
    let (bands, srows, scols) = cube.dim();
    let (rows, cols) = (srows / k, scols / k);
    let n_out = w.len();
    let inv_area = 1.0 / (k * k) as f64;
    let mut out = Array3::<f32>::zeros((n_out, rows, cols));
    if rows == 0 || cols == 0 {
        return out;
    }
    let (Some(src), Some(dst)) = (cube.to_slice(), out.as_slice_mut()) else {
        // Both are standard layout by construction.
        return Array3::zeros((n_out, rows, cols));
    };
    // One task per (output plane, output row).
    dst.par_chunks_mut(cols).enumerate().for_each_init(
        || (vec![0.0f64; cols], vec![0.0f64; cols]),
        |(acc, binned), (q, out_row)| {
            let (j, r) = (q / rows, q % rows);
            acc.iter_mut().for_each(|v| *v = 0.0);
            for (b, &wb) in w[j].iter().enumerate().take(bands) {
                if wb == 0.0 {
                    continue;
                }
                let plane = &src[b * srows * scols..(b + 1) * srows * scols];
                if k == 1 {
                    let row = &plane[r * scols..r * scols + cols];
                    for (a, &v) in acc.iter_mut().zip(row) {
                        *a += wb * v as f64;
                    }
                } else {
                    binned.iter_mut().for_each(|v| *v = 0.0);
                    for sr in r * k..(r + 1) * k {
                        let row = &plane[sr * scols..sr * scols + cols * k];
                        for (c, px) in row.chunks_exact(k).enumerate() {
                            binned[c] += px.iter().map(|&v| v as f64).sum::<f64>();
                        }
                    }
                    for (a, &v) in acc.iter_mut().zip(binned.iter()) {
                        *a += wb * v * inv_area;
                    }
                }
            }
            for (o, &a) in out_row.iter_mut().zip(acc.iter()) {
                *o = a as f32;
            }
        },
    );
    out
}

/// Per-pixel rate of each pixel's CFA channel: `out[r, c] = rates[cfa(r, c), r, c]`.
pub fn mosaic(rates: &Array3<f32>, cfa: &Cfa) -> Result<Array2<f32>, CameraError> {
    let (ch, rows, cols) = rates.dim();
    if let Some(&p) = cfa.pattern.iter().find(|&&p| p >= ch) {
        return Err(CameraError::InvalidArgument(format!(
            "CFA {cfa} uses channel {p} but the rate cube has {ch} channels"
        )));
    }
    if cfa.rows == 0 || cfa.cols == 0 {
        return Err(CameraError::InvalidCfa("empty tile".into()));
    }
    Ok(Array2::from_shape_fn((rows, cols), |(r, c)| {
        rates[(cfa.channel_at(r, c), r, c)]
    }))
}

/// A 32-byte ChaCha key from a seed and a domain tag.
fn seed_key(seed: u64, tag: u64) -> [u8; 32] {
    let mut k = [0u8; 32];
    k[..8].copy_from_slice(&seed.to_le_bytes());
    k[8..16].copy_from_slice(&tag.to_le_bytes());
    k
}

/// Standard-normal DSNU and PRNU deviates of row `r`: stream `r` of the FPN
/// key, two 64-bit words per pixel through Box–Muller, so pixel `(r, c)`
/// depends only on the key, `r` and `c` (not on the frame size or content).
fn fixed_pattern_row(key: [u8; 32], r: usize, zd: &mut [f32], zp: &mut [f32]) {
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_stream(r as u64);
    for (d, p) in zd.iter_mut().zip(zp.iter_mut()) {
        // u1 in (0, 1], u2 in [0, 1).
        let u1 = ((rng.next_u64() >> 11) + 1) as f64 * (1.0 / (1u64 << 53) as f64);
        let u2 = (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
        let radius = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        *d = (radius * c) as f32;
        *p = (radius * s) as f32;
    }
}

/// The per-pixel noise model with every constant folded in.
struct PixelModel {
    t: f64,
    dark_e: f64,
    well: f64,
    volts_per_e: f64,
    sigma_dsnu: f64,
    sigma_prnu: f64,
    sigma_read: f64,
    offset: f64,
    swing: f64,
    /// ADC step in volts, if quantising.
    lsb: Option<f64>,
    noise: NoiseSwitches,
}

impl PixelModel {
    fn new(d: &SensorDesign, t: f64, noise: &NoiseSwitches) -> Self {
        Self {
            t,
            dark_e: if noise.dark {
                d.dark_voltage_v_per_s * t / d.conversion_gain_v()
            } else {
                0.0
            },
            well: d.well_capacity_e,
            volts_per_e: d.conversion_gain_v() * d.analog_gain,
            sigma_dsnu: if noise.dsnu { d.dsnu_v() } else { 0.0 },
            sigma_prnu: if noise.prnu { d.prnu_fraction() } else { 0.0 },
            sigma_read: if noise.read { d.read_noise_v() } else { 0.0 },
            offset: d.offset_v,
            swing: d.voltage_swing_v,
            lsb: d
                .adc_bits
                .map(|b| d.voltage_swing_v / ((1u64 << b) - 1) as f64),
            noise: *noise,
        }
    }

    #[inline]
    fn pixel(&self, rate: f32, zd: f32, zp: f32, rng: &mut ChaCha8Rng) -> f32 {
        let signal = rate as f64 * self.t * (1.0 + self.sigma_prnu * zp as f64);
        let lambda = signal.max(0.0) + self.dark_e;
        let electrons = if self.noise.shot {
            poisson(lambda, self.well, rng)
        } else {
            lambda
        }
        .min(self.well);
        let mut v = electrons * self.volts_per_e + self.sigma_dsnu * zd as f64 + self.offset;
        if self.noise.read {
            let z: f64 = StandardNormal.sample(rng);
            v += self.sigma_read * z;
        }
        let mut v = v.clamp(0.0, self.swing);
        if let Some(lsb) = self.lsb {
            v = ((v / lsb).round() * lsb).min(self.swing);
        }
        v as f32
    }
}

/// A Poisson draw of mean `lambda`. Means so far above the well that a draw
/// below it has probability < 1e-80 (20 σ) skip sampling: the result is
/// clipped at the well anyway.
#[inline]
fn poisson(lambda: f64, well: f64, rng: &mut ChaCha8Rng) -> f64 {
    if lambda <= 0.0 {
        return 0.0;
    }
    if lambda - 20.0 * lambda.sqrt() > well {
        return lambda;
    }
    match Poisson::new(lambda) {
        Ok(p) => p.sample(rng),
        Err(_) => lambda,
    }
}

#[cfg(test)]
mod tests;
