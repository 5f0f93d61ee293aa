//! Diffraction-limited optics: the incoherent OTF of a circular pupil applied
//! per wavelength in the frequency domain, and the radiance → irradiance
//! conversion.

use std::f64::consts::PI;
use std::sync::Arc;

use ndarray::Array3;
use rayon::prelude::*;
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};
use serde::{Deserialize, Serialize};

use super::CameraError;
use crate::scene::Scene;
use crate::spectral::{Extrapolation, Spectrum, WavelengthGrid, cie1931_cmfs};

/// Luminous efficacy, lm/W.
pub const KM: f64 = 683.0;

/// Mirror margin around the image, in units of `λ_max · N` (the Airy radius
/// is 1.22 λN). The Airy tail is heavy (encircled energy 1 − 2/(πv) at
/// v = πr/(λN)): beyond 16 λN lies about 1.3 % of the PSF's energy, so only
/// that much of an edge pixel's blur sees the periodic wrap instead of the
/// mirror.
const MARGIN_LAMBDA_N: f64 = 16.0;

/// Entries of the OTF look-up table over s ∈ [0, 1] (linear interpolation
/// error below 1e-5).
const OTF_LUT_LEN: usize = 4097;

/// A diffraction-limited lens (docs/design.md §3): f-number and focal length,
/// and how finely the simulation samples its image.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Optics {
    pub f_number: f64,
    pub focal_length_mm: f64,
    /// Optical-image samples per pixel side ([`DEFAULT_SAMPLES_PER_PIXEL`]).
    pub samples_per_pixel: u32,
}

/// Optical-image samples per pixel side: each scene pixel is a uniform
/// pixel-sized square, imaged on a grid `k` times finer than the pixels, and
/// each pixel integrates its `k × k` samples (its box aperture).
///
/// With one sample per pixel the lens's OTF is cut at the pixel Nyquist
/// frequency, so a chart's sharp edges ring (Gibbs) at that frequency, and
/// at f/4 the ringing is chromatic (the OTF at the pixel Nyquist falls from
/// 0.55 at 400 nm to 0.22 at 700 nm with 2.2 µm pixels). A mosaic samples
/// that ringing at a different phase in every channel, so the interior of
/// a flat patch carries a colour error that is the simulation's, not the
/// camera's. Measured on the Natural-100 chart under tungsten (noise-free,
/// a linear map fitted on the natural reflectances, mean ΔE2000 of the
/// patches' bilinear-demosaicked channel means against the same map on
/// every channel at every pixel): ISET's RGBW 2.64 against 2.02 with one
/// sample, 2.01 against 2.02 with 2, 3 or 4; AR0132AT 2.11 against 2.08,
/// then 2.08; Nikon D5100 1.89 at every `k`. Two samples remove the
/// artefact; more change nothing and cost FFT time.
pub const DEFAULT_SAMPLES_PER_PIXEL: u32 = 2;

/// The most optical-image samples per pixel side a design may ask for.
pub const MAX_SAMPLES_PER_PIXEL: u32 = 4;

impl Default for Optics {
    /// The paper's lens: f/4, 3 mm (aperture 0.75 mm).
    fn default() -> Self {
        Self {
            f_number: 4.0,
            focal_length_mm: 3.0,
            samples_per_pixel: DEFAULT_SAMPLES_PER_PIXEL,
        }
    }
}

/// The diffraction OTF of a circular pupil at normalised frequency
/// `s = f / f_c`: `(2/π)(acos s − s√(1−s²))` for `s < 1`, else 0.
pub fn diffraction_otf(s: f64) -> f64 {
    let s = s.abs();
    if s >= 1.0 {
        0.0
    } else {
        (2.0 / PI) * (s.acos() - s * (1.0 - s * s).sqrt())
    }
}

impl Optics {
    /// Aperture diameter in mm.
    pub fn aperture_mm(&self) -> f64 {
        self.focal_length_mm / self.f_number
    }

    /// Cutoff frequency `1 / (λN)` in cycles/mm at `wavelength_nm`.
    pub fn cutoff_cyc_per_mm(&self, wavelength_nm: f64) -> f64 {
        1.0 / (wavelength_nm * 1e-6 * self.f_number)
    }

    /// The diffraction-limited incoherent OTF (real, radially symmetric) at
    /// radial frequency `freq_cyc_per_mm` and `wavelength_nm`.
    pub fn otf(&self, freq_cyc_per_mm: f64, wavelength_nm: f64) -> f64 {
        diffraction_otf(freq_cyc_per_mm / self.cutoff_cyc_per_mm(wavelength_nm))
    }

    /// Irradiance per radiance on axis for a distant object (m = 0):
    /// `E = L · π / (1 + 4N²)`.
    pub fn irradiance_factor(&self) -> f64 {
        PI / (1.0 + 4.0 * self.f_number * self.f_number)
    }

    /// The optical image of `scene` sampled at `sample_spacing_um` on the
    /// sensor: each scene pixel is one sample. Every band of the reflectance
    /// cube is blurred by this lens's OTF at that band's wavelength (the
    /// illuminant is spatially uniform, so blurring reflectance and then
    /// multiplying by the SPD is the same as blurring radiance).
    ///
    /// The blur is a 2-D FFT per band with the image mirror-padded by
    /// 16 λ_max N on each side (so edges behave as a symmetric extension, not
    /// as a periodic wrap), two bands per complex transform, in parallel.
    pub fn image(
        &self,
        scene: &Scene,
        sample_spacing_um: f64,
    ) -> Result<OpticalImage, CameraError> {
        let (bands, rows, cols) = scene.reflectance.dim();
        if !(sample_spacing_um.is_finite() && sample_spacing_um > 0.0) {
            return Err(CameraError::InvalidArgument(format!(
                "sample spacing {sample_spacing_um} µm must be positive"
            )));
        }
        if rows == 0 || cols == 0 || bands == 0 {
            return Err(CameraError::InvalidArgument(format!(
                "scene '{}' is empty ({bands} bands, {rows}×{cols})",
                scene.name
            )));
        }
        if bands != scene.grid.n || scene.illuminant.grid() != &scene.grid {
            return Err(CameraError::InvalidArgument(format!(
                "scene '{}': reflectance has {bands} bands, grid {} bands, illuminant grid {} bands",
                scene.name,
                scene.grid.n,
                scene.illuminant.grid().n
            )));
        }
        if !(self.f_number.is_finite() && self.f_number > 0.0) {
            return Err(CameraError::InvalidArgument(format!(
                "f-number {} must be positive",
                self.f_number
            )));
        }
        let refl = scene.reflectance.as_standard_layout();
        let refl = refl.as_slice().ok_or_else(|| {
            CameraError::InvalidArgument("reflectance cube is not contiguous".into())
        })?;
        let plane = rows * cols;
        // Mean reflectance per band (f64), which also checks finiteness.
        let mean_reflectance: Vec<f64> = refl
            .par_chunks(plane)
            .map(|p| p.iter().map(|&v| v as f64).sum::<f64>() / plane as f64)
            .collect();
        if let Some(b) = mean_reflectance.iter().position(|m| !m.is_finite()) {
            return Err(CameraError::InvalidArgument(format!(
                "scene '{}': band {} nm holds non-finite reflectance",
                scene.name,
                scene.grid.wavelength(b)
            )));
        }
        let lambdas: Vec<f64> = scene.grid.wavelengths();
        let blurred = blur_cube(
            refl,
            rows,
            cols,
            &lambdas,
            sample_spacing_um * 1e-3,
            self.f_number,
        );
        let mut out = OpticalImage {
            grid: scene.grid,
            blurred_reflectance: Arc::new(
                Array3::from_shape_vec((bands, rows, cols), blurred).map_err(|e| {
                    CameraError::InvalidArgument(format!("internal shape error: {e}"))
                })?,
            ),
            sample_spacing_um,
            optics: *self,
            illuminant: scene.illuminant.clone(),
            mean_luminance: 0.0,
            radiance_scale: 0.0,
            mean_reflectance,
        };
        out.set_lighting(scene.illuminant.clone(), scene.mean_luminance)?;
        Ok(out)
    }
}

/// The scene after the lens: a blurred reflectance cube with the lighting that
/// turns it into radiance, `reflectance × illuminant × radiance_scale` in
/// W/(sr·m²·nm), and irradiance at the sensor `radiance × optics.irradiance_factor()`.
#[derive(Clone, Debug)]
pub struct OpticalImage {
    pub grid: WavelengthGrid,
    /// Blurred reflectance, shape `(bands, rows, cols)`; shared by relit copies.
    pub blurred_reflectance: Arc<Array3<f32>>,
    /// Distance between samples on the sensor plane, µm.
    pub sample_spacing_um: f64,
    /// The lens that formed the image.
    pub optics: Optics,
    /// Relative SPD of the (spatially uniform) illuminant.
    pub illuminant: Spectrum,
    /// Mean scene luminance, cd/m².
    pub mean_luminance: f64,
    /// Factor turning `reflectance × illuminant` into radiance, chosen so the
    /// scene's mean luminance (unblurred) is `mean_luminance`.
    pub radiance_scale: f64,
    /// Per-band mean of the unblurred scene reflectance.
    pub mean_reflectance: Vec<f64>,
}

impl OpticalImage {
    pub fn rows(&self) -> usize {
        self.blurred_reflectance.shape()[1]
    }

    pub fn cols(&self) -> usize {
        self.blurred_reflectance.shape()[2]
    }

    pub fn bands(&self) -> usize {
        self.blurred_reflectance.shape()[0]
    }

    /// Mean luminance per unit radiance scale for `illuminant`:
    /// `683 · Σ_b ȳ_b · mean_refl_b · illuminant_b · Δλ`.
    fn luminance_per_scale(&self, illuminant: &Spectrum) -> Result<f64, CameraError> {
        let ybar = cie1931_cmfs()[1].resample(&self.grid, Extrapolation::Zero);
        let mean_refl = Spectrum::new(self.grid, self.mean_reflectance.clone())?;
        Ok(KM * ybar.product(&mean_refl)?.integral_of_product(illuminant)?)
    }

    fn set_lighting(
        &mut self,
        illuminant: Spectrum,
        mean_luminance: f64,
    ) -> Result<(), CameraError> {
        if illuminant.grid() != &self.grid {
            return Err(CameraError::GridMismatch {
                what: "illuminant".into(),
                expected: self.grid,
                got: *illuminant.grid(),
            });
        }
        if !illuminant.is_finite() || illuminant.values().iter().any(|&v| v < 0.0) {
            return Err(CameraError::InvalidArgument(
                "illuminant SPD must be finite and non-negative".into(),
            ));
        }
        if !(mean_luminance.is_finite() && mean_luminance >= 0.0) {
            return Err(CameraError::InvalidArgument(format!(
                "mean luminance {mean_luminance} cd/m² must be finite and non-negative"
            )));
        }
        let per_scale = self.luminance_per_scale(&illuminant)?;
        let scale = if mean_luminance == 0.0 {
            0.0
        } else if per_scale > 0.0 && per_scale.is_finite() {
            mean_luminance / per_scale
        } else {
            return Err(CameraError::InvalidArgument(format!(
                "the scene has no luminance under this illuminant, so it cannot be set to \
                 {mean_luminance} cd/m²"
            )));
        };
        self.illuminant = illuminant;
        self.mean_luminance = mean_luminance;
        self.radiance_scale = scale;
        Ok(())
    }

    /// The same blurred scene under another illuminant, scaled to
    /// `mean_luminance` cd/m² (the blurred cube is shared, not copied).
    pub fn relit(
        &self,
        illuminant: &Spectrum,
        mean_luminance: f64,
    ) -> Result<OpticalImage, CameraError> {
        let mut out = OpticalImage {
            grid: self.grid,
            blurred_reflectance: Arc::clone(&self.blurred_reflectance),
            sample_spacing_um: self.sample_spacing_um,
            optics: self.optics,
            illuminant: self.illuminant.clone(),
            mean_luminance: self.mean_luminance,
            radiance_scale: self.radiance_scale,
            mean_reflectance: self.mean_reflectance.clone(),
        };
        out.set_lighting(illuminant.clone(), mean_luminance)?;
        Ok(out)
    }

    /// Irradiance at the sensor per unit blurred reflectance, per band,
    /// W/(m²·nm): `illuminant_b · radiance_scale · π/(1+4N²)`.
    pub fn irradiance_per_reflectance(&self) -> Vec<f64> {
        let k = self.radiance_scale * self.optics.irradiance_factor();
        self.illuminant.values().iter().map(|v| v * k).collect()
    }
}

/// Smallest `n' ≥ n` whose only prime factors are 2, 3, 5 and 7.
fn fft_friendly(n: usize) -> usize {
    let mut m = n.max(1);
    loop {
        let mut k = m;
        for p in [2, 3, 5, 7] {
            while k.is_multiple_of(p) {
                k /= p;
            }
        }
        if k == 1 {
            return m;
        }
        m += 1;
    }
}

/// Index of padded position `i` (may be negative or ≥ n) under half-sample
/// symmetric reflection: … 1 0 | 0 1 … n−1 | n−1 n−2 …
fn reflect(i: isize, n: usize) -> usize {
    let period = 2 * n as isize;
    let j = i.rem_euclid(period) as usize;
    if j < n { j } else { 2 * n - 1 - j }
}

/// Blocked transpose of a `rows × cols` complex matrix into `dst` (`cols × rows`).
fn transpose(src: &[Complex<f32>], dst: &mut [Complex<f32>], rows: usize, cols: usize) {
    const B: usize = 32;
    for r0 in (0..rows).step_by(B) {
        for c0 in (0..cols).step_by(B) {
            for r in r0..(r0 + B).min(rows) {
                for c in c0..(c0 + B).min(cols) {
                    dst[c * rows + r] = src[r * cols + c];
                }
            }
        }
    }
}

/// Plans and frequency tables for one padded size.
struct BlurPlan {
    row_fwd: Arc<dyn Fft<f32>>,
    row_inv: Arc<dyn Fft<f32>>,
    col_fwd: Arc<dyn Fft<f32>>,
    col_inv: Arc<dyn Fft<f32>>,
    scratch_len: usize,
    /// Radial frequency (cycles/mm) at `[kx * pr + ky]` (column-frequency major,
    /// the layout after the transpose).
    radial: Vec<f32>,
    /// Index of `(−kx, −ky)` for each entry of `radial`'s layout.
    negated: Vec<u32>,
    /// OTF(s) on s = i / (OTF_LUT_LEN − 1).
    lut: Vec<f32>,
}

impl BlurPlan {
    fn new(pr: usize, pc: usize, dx_mm: f64) -> Self {
        let mut planner = FftPlanner::<f32>::new();
        let row_fwd = planner.plan_fft_forward(pc);
        let row_inv = planner.plan_fft_inverse(pc);
        let col_fwd = planner.plan_fft_forward(pr);
        let col_inv = planner.plan_fft_inverse(pr);
        let scratch_len = [&row_fwd, &row_inv, &col_fwd, &col_inv]
            .iter()
            .map(|f| f.get_inplace_scratch_len())
            .max()
            .unwrap_or(0);
        let freq = |k: usize, n: usize| {
            let k = if k <= n / 2 {
                k as f64
            } else {
                k as f64 - n as f64
            };
            k / (n as f64 * dx_mm)
        };
        let mut radial = Vec::with_capacity(pr * pc);
        let mut negated = Vec::with_capacity(pr * pc);
        for kx in 0..pc {
            let fx = freq(kx, pc);
            let nkx = (pc - kx) % pc;
            for ky in 0..pr {
                let fy = freq(ky, pr);
                radial.push((fx * fx + fy * fy).sqrt() as f32);
                let nky = (pr - ky) % pr;
                negated.push((nkx * pr + nky) as u32);
            }
        }
        let lut = (0..OTF_LUT_LEN)
            .map(|i| diffraction_otf(i as f64 / (OTF_LUT_LEN - 1) as f64) as f32)
            .collect();
        Self {
            row_fwd,
            row_inv,
            col_fwd,
            col_inv,
            scratch_len,
            radial,
            negated,
            lut,
        }
    }

    /// OTF at radial frequency `f` for a band with `λN` (mm): `s = f · λN`.
    #[inline]
    fn otf(&self, f: f32, lambda_n_mm: f32) -> f32 {
        let x = f * lambda_n_mm * (OTF_LUT_LEN - 1) as f32;
        if x >= (OTF_LUT_LEN - 1) as f32 {
            return 0.0;
        }
        let i = x as usize;
        let t = x - i as f32;
        self.lut[i] + t * (self.lut[i + 1] - self.lut[i])
    }
}

/// Per-thread work buffers of [`blur_cube`].
struct BlurScratch {
    a: Vec<Complex<f32>>,
    b: Vec<Complex<f32>>,
    fft: Vec<Complex<f32>>,
}

/// Blur each `rows × cols` band of `refl` (band-major) with the diffraction
/// OTF of its wavelength; returns the blurred cube in the same layout.
fn blur_cube(
    refl: &[f32],
    rows: usize,
    cols: usize,
    lambdas_nm: &[f64],
    dx_mm: f64,
    f_number: f64,
) -> Vec<f32> {
    let plane = rows * cols;
    let lambda_max = lambdas_nm.iter().copied().fold(0.0, f64::max);
    let margin = (MARGIN_LAMBDA_N * lambda_max * 1e-6 * f_number / dx_mm).ceil() as usize + 1;
    let pr = fft_friendly(rows + 2 * margin);
    let pc = fft_friendly(cols + 2 * margin);
    // Put the image in the middle of the padded frame.
    let (off_r, off_c) = ((pr - rows) / 2, (pc - cols) / 2);
    let plan = BlurPlan::new(pr, pc, dx_mm);
    let row_src: Vec<usize> = (0..pr)
        .map(|i| reflect(i as isize - off_r as isize, rows))
        .collect();
    let col_src: Vec<usize> = (0..pc)
        .map(|j| reflect(j as isize - off_c as isize, cols))
        .collect();
    let norm = 1.0 / (pr * pc) as f32;

    let mut out = vec![0.0f32; refl.len()];
    out.par_chunks_mut(2 * plane).enumerate().for_each_init(
        || BlurScratch {
            a: vec![Complex::default(); pr * pc],
            b: vec![Complex::default(); pr * pc],
            fft: vec![Complex::default(); plan.scratch_len],
        },
        |s, (pair, dst)| {
            let b0 = 2 * pair;
            let has_second = dst.len() == 2 * plane;
            let p0 = &refl[b0 * plane..(b0 + 1) * plane];
            let p1 = if has_second {
                &refl[(b0 + 1) * plane..(b0 + 2) * plane]
            } else {
                p0
            };
            // Pack band b0 in the real part and b0+1 in the imaginary part.
            for (i, &sr) in row_src.iter().enumerate() {
                let row = &mut s.a[i * pc..(i + 1) * pc];
                for (v, &sc) in row.iter_mut().zip(&col_src) {
                    let k = sr * cols + sc;
                    *v = Complex::new(p0[k], if has_second { p1[k] } else { 0.0 });
                }
            }
            plan.row_fwd.process_with_scratch(&mut s.a, &mut s.fft);
            transpose(&s.a, &mut s.b, pr, pc);
            plan.col_fwd.process_with_scratch(&mut s.b, &mut s.fft);
            // Filter. With Z = FFT(a + i·b) and Z*(−k) its conjugate mirror,
            // A = (Z + Z*(−k))/2 and B = (Z − Z*(−k))/(2i) are the spectra of
            // the two real bands; the result is Ha·A + i·Hb·B, whose inverse is
            // (a ⊛ ha) + i (b ⊛ hb) because both OTFs are real and even.
            let ln0 = (lambdas_nm[b0] * 1e-6 * f_number) as f32;
            let ln1 = if has_second {
                (lambdas_nm[b0 + 1] * 1e-6 * f_number) as f32
            } else {
                ln0
            };
            for (k, o) in s.a.iter_mut().enumerate() {
                let f = plan.radial[k];
                let ha = plan.otf(f, ln0);
                let hb = plan.otf(f, ln1);
                let z = s.b[k];
                let zn = s.b[plan.negated[k] as usize].conj();
                let hs = 0.5 * (ha + hb);
                let hd = 0.5 * (ha - hb);
                // Ha·(z+zn)/2 + Hb·(z−zn)/2 = hs·z + hd·zn
                *o = z * hs + zn * hd;
            }
            plan.col_inv.process_with_scratch(&mut s.a, &mut s.fft);
            transpose(&s.a, &mut s.b, pc, pr);
            plan.row_inv.process_with_scratch(&mut s.b, &mut s.fft);
            let (d0, d1) = dst.split_at_mut(plane);
            for r in 0..rows {
                let src = &s.b[(r + off_r) * pc + off_c..(r + off_r) * pc + off_c + cols];
                let o0 = &mut d0[r * cols..(r + 1) * cols];
                for (o, v) in o0.iter_mut().zip(src) {
                    *o = v.re * norm;
                }
                if has_second {
                    let o1 = &mut d1[r * cols..(r + 1) * cols];
                    for (o, v) in o1.iter_mut().zip(src) {
                        *o = v.im * norm;
                    }
                }
            }
        },
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn otf_formula_values() {
        assert_eq!(diffraction_otf(0.0), 1.0);
        assert_eq!(diffraction_otf(1.0), 0.0);
        assert_eq!(diffraction_otf(1.5), 0.0);
        let half = (2.0 / PI) * ((0.5f64).acos() - 0.5 * (0.75f64).sqrt());
        assert!((diffraction_otf(0.5) - half).abs() < 1e-15);
        assert!((half - 0.391).abs() < 1e-3);
        let o = Optics::default();
        // f/4 at 500 nm: cutoff 500 cycles/mm.
        assert!((o.cutoff_cyc_per_mm(500.0) - 500.0).abs() < 1e-9);
        assert!((o.otf(250.0, 500.0) - half).abs() < 1e-12);
        assert!((o.irradiance_factor() - PI / 65.0).abs() < 1e-15);
        assert!((o.aperture_mm() - 0.75).abs() < 1e-15);
    }

    #[test]
    fn lut_matches_formula() {
        let plan = BlurPlan::new(8, 8, 1e-3);
        for i in 0..=1000 {
            let s = i as f64 / 1000.0 * 1.2;
            let approx = plan.otf(s as f32, 1.0) as f64;
            assert!((approx - diffraction_otf(s)).abs() < 2e-5, "s {s}");
        }
    }

    #[test]
    fn reflection_and_sizes() {
        let idx: Vec<usize> = (-3..7).map(|i| reflect(i, 4)).collect();
        assert_eq!(idx, vec![2, 1, 0, 0, 1, 2, 3, 3, 2, 1]);
        assert_eq!(reflect(-9, 4), 0); // −9 ≡ 7 (mod 8) → 0
        assert_eq!(fft_friendly(532), 540);
        assert_eq!(fft_friendly(1), 1);
        assert_eq!(fft_friendly(11), 12);
    }

    #[test]
    fn blur_preserves_constants_and_energy_and_pairs_bands_independently() {
        // Band 0: constant 0.5, band 1: a single bright pixel, band 2: ramp
        // (odd band count exercises the unpaired path).
        let (rows, cols) = (64, 70);
        let (ir, ic) = (32, 35);
        let plane = rows * cols;
        let mut refl = vec![0.5f32; 3 * plane];
        for v in &mut refl[plane..2 * plane] {
            *v = 0.0;
        }
        refl[plane + ir * cols + ic] = 1.0;
        for r in 0..rows {
            for c in 0..cols {
                refl[2 * plane + r * cols + c] = c as f32 / cols as f32;
            }
        }
        let out = blur_cube(&refl, rows, cols, &[450.0, 550.0, 650.0], 2.2e-3, 4.0);
        for v in &out[..plane] {
            assert!((v - 0.5).abs() < 1e-5);
        }
        // The impulse spreads but keeps its energy and its symmetry. The
        // Airy tail beyond 32 pixels (v = 100) holds 2/(πv) ≈ 0.6 % of it;
        // the mirror returns part of that.
        let psf = &out[plane..2 * plane];
        let sum: f32 = psf.iter().sum();
        assert!(sum < 1.0 && (sum - 1.0).abs() < 6e-3, "{sum}");
        let peak = psf[ir * cols + ic];
        assert!(peak < 0.9 && peak > 0.3, "{peak}");
        assert!((psf[ir * cols + ic - 1] - psf[ir * cols + ic + 1]).abs() < 1e-5);
        assert!((psf[(ir - 1) * cols + ic] - psf[(ir + 1) * cols + ic]).abs() < 1e-5);
        let (v, h) = (psf[(ir - 1) * cols + ic], psf[ir * cols + ic + 1]);
        assert!((v - h).abs() < 1e-4, "{v} {h}"); // padded sizes differ per axis
        // Pairing is exact: blurring (impulse, ramp) as one pair gives what
        // (constant, impulse) + (ramp alone) gave, with the same padding.
        let repaired = blur_cube(&refl[plane..], rows, cols, &[550.0, 650.0], 2.2e-3, 4.0);
        for (a, b) in repaired.iter().zip(&out[plane..]) {
            assert!((a - b).abs() < 1e-6, "{a} {b}");
        }
        // A ramp stays nearly a ramp. Not exactly: the mirror folds it into
        // a triangle wave, and the Airy line-spread tail (∝ 1/x²) feels the
        // folds logarithmically far away, flattening the slope by ~1 %.
        let ramp = &out[2 * plane..];
        for c in 10..cols - 10 {
            let e = ramp[10 * cols + c] - c as f32 / cols as f32;
            assert!(e.abs() < 4e-3, "{c}: {e}");
        }
        let mid = ramp[10 * cols + cols / 2] - 0.5;
        assert!(mid.abs() < 1e-4, "{mid}");
    }
}
