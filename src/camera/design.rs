//! Sensor designs as data: every parameter of the optics, pixel, noise model
//! and colour filters, loaded from TOML (`config/sensors/*.toml`).

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::optics::MAX_SAMPLES_PER_PIXEL;
use super::{CameraError, Cfa, Optics};
use crate::spectral::{IsetData, Spectrum, WavelengthGrid};

mod filter;

pub use filter::{COVERAGE_SLACK_NM, CoverageNote, FilterSpec};

/// A design loaded from a file or the catalogue, its curves read, with what they leave to
/// note: curves that cover clearly less than the simulation grid ([`CoverageNote`]).
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedDesign {
    pub design: SensorDesign,
    pub notes: Vec<CoverageNote>,
}

/// The longest design name.
pub const MAX_NAME_LEN: usize = 100;

/// The largest analog offset, as a fraction of the voltage swing.
pub const MAX_OFFSET_FRACTION: f64 = 0.5;

/// A design's name is a file name on every system, and no path: letters, digits, `-`, `_`,
/// `.`, `+`, not starting with `.`.
fn is_identifier(name: &str) -> bool {
    name.len() <= MAX_NAME_LEN
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.' | '+'))
}

/// A 1×4 tile of R, G, G and B: the way datasheets name a Bayer phase (`RGGB`), which
/// [`Cfa::parse`] reads as a stripe.
fn looks_like_bayer_in_one_row(cfa: &Cfa) -> bool {
    let mut names: Vec<&str> = cfa
        .pattern
        .iter()
        .map(|&c| cfa.channel_names[c].as_str())
        .collect();
    names.sort_unstable();
    cfa.rows == 1 && names == ["B", "G", "G", "R"]
}

/// A complete sensor design (docs/design.md §3). Units are in the field names.
/// Fields omitted from a TOML file take the paper's Figure 2 value
/// ([`SensorDesign::paper_default`]), except that a file giving its own `cfa`
/// must also give the matching `filters`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SensorDesign {
    /// Short identifier, e.g. `rgbw-paper`.
    pub name: String,
    /// Free text.
    pub description: String,
    /// Pixel pitch (square pixels), µm.
    pub pixel_size_um: f64,
    /// Photosensitive fraction of the pixel area, (0, 1].
    pub fill_factor: f64,
    /// Conversion gain, µV per electron.
    pub conversion_gain_uv_per_e: f64,
    /// Voltage swing (the saturation voltage), V.
    pub voltage_swing_v: f64,
    /// Well capacity, electrons.
    pub well_capacity_e: f64,
    /// Read noise standard deviation, mV.
    pub read_noise_mv: f64,
    /// Dark signal non-uniformity (per-pixel offset) standard deviation, mV.
    pub dsnu_mv: f64,
    /// Photo-response non-uniformity (per-pixel gain) standard deviation, %.
    pub prnu_percent: f64,
    /// Dark current expressed as a voltage rate, V/s.
    pub dark_voltage_v_per_s: f64,
    /// Analog gain applied to the pixel voltage.
    pub analog_gain: f64,
    /// Analog offset added to the pixel voltage, V.
    pub offset_v: f64,
    /// ADC bits; `None` leaves the output continuous.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub adc_bits: Option<u32>,
    /// The sensor's size in pixels, recorded with the design and its tables. The simulated
    /// scenes set their own size (`l3 simulate --scene`), so it does not size frames.
    pub rows: usize,
    pub cols: usize,
    /// Seed of the fixed patterns (DSNU, PRNU): one physical sensor.
    pub fpn_seed: u64,
    /// Lens.
    pub optics: Optics,
    /// The colour filter array, e.g. `"RG/WB"`. Channels are numbered in order
    /// of first appearance (see [`Cfa::parse`]).
    pub cfa: Cfa,
    /// Colour filter transmittance per channel name.
    pub filters: BTreeMap<String, FilterSpec>,
    /// IR-cut filter, common to all pixels.
    pub ir_cut: FilterSpec,
    /// Photodetector quantum efficiency (electrons per photon).
    pub qe: FilterSpec,
}

/// Parametric filters of the default "near-colorimetric" RGBW sensor: broad
/// Gaussian passbands near the CIE 1931 colour-matching functions (R on x̄'s
/// long-wave lobe, G on ȳ, B on z̄), a clear W, a 650 nm IR-cut and a smooth
/// silicon QE.
///
/// The centres, widths and IR-cut edge were picked on a coarse grid (R
/// 595–610 nm, σ 35–50; G 535–550, σ 35–45; B 445–460, σ 25–35; edge
/// 650–680) for the lowest colorimetric floor with σ ≥ 30 nm (broad, for
/// sensitivity): the best noise-free linear map from the four channels to XYZ
/// over the CES + Munsell reflectances has a mean CIELAB ΔE76 of 0.42 under
/// D65, 0.43 under A and 0.31 under F11 (ISETCam's AR0132AT curves: 2.1, 2.3,
/// 1.6). Moving B from 455 to 445 nm and the IR-cut from 670 to 650 nm
/// matter most (0.42 against 1.0 under D65).
pub mod parametric {
    use super::FilterSpec;

    /// R: 600 nm, σ = 45 nm.
    pub const RED: FilterSpec = FilterSpec::Gaussian {
        center_nm: 600.0,
        sigma_nm: 45.0,
        peak: 1.0,
    };
    /// G: 540 nm, σ = 40 nm.
    pub const GREEN: FilterSpec = FilterSpec::Gaussian {
        center_nm: 540.0,
        sigma_nm: 40.0,
        peak: 1.0,
    };
    /// B: 445 nm, σ = 30 nm.
    pub const BLUE: FilterSpec = FilterSpec::Gaussian {
        center_nm: 445.0,
        sigma_nm: 30.0,
        peak: 1.0,
    };
    /// W: clear.
    pub const WHITE: FilterSpec = FilterSpec::Constant(1.0);
    /// IR-cut: logistic edge, 50 % at 650 nm, 10 nm wide (≈ 90 % at 628 nm, ≈ 10 % at 672 nm).
    pub const IR_CUT: FilterSpec = FilterSpec::ShortPass {
        edge_nm: 650.0,
        width_nm: 10.0,
    };
    /// Silicon photodiode QE: a broad hump, 0.6 at 600 nm, σ = 180 nm
    /// (≈ 0.32 at 400 nm, ≈ 0.51 at 700 nm).
    pub const SILICON_QE: FilterSpec = FilterSpec::Gaussian {
        center_nm: 600.0,
        sigma_nm: 180.0,
        peak: 0.6,
    };
}

impl Default for SensorDesign {
    fn default() -> Self {
        Self::paper_default()
    }
}

impl SensorDesign {
    /// The paper's Figure 2 sensor: 2.2 µm pixels, fill factor 0.45, 200 µV/e⁻,
    /// 1.8 V swing, 9000 e⁻ well, read noise 1.34 mV, DSNU 1.41 mV, PRNU
    /// 0.2218 %, dark voltage 1e-5 V/s, gain 1, offset 0, no ADC, 204×240,
    /// f/4 3 mm optics, `RG/WB` CFA with the [`parametric`] filters.
    pub fn paper_default() -> Self {
        let filters = [
            ("R", parametric::RED),
            ("G", parametric::GREEN),
            ("B", parametric::BLUE),
            ("W", parametric::WHITE),
        ]
        .into_iter()
        .map(|(n, f)| (n.to_string(), f))
        .collect();
        Self {
            name: "rgbw-paper".into(),
            description: "RGBW sensor of the L3 illuminant-correction paper (Figure 2), \
                          parametric near-colorimetric filters"
                .into(),
            pixel_size_um: 2.2,
            fill_factor: 0.45,
            conversion_gain_uv_per_e: 200.0,
            voltage_swing_v: 1.8,
            well_capacity_e: 9000.0,
            read_noise_mv: 1.34,
            dsnu_mv: 1.41,
            prnu_percent: 0.2218,
            dark_voltage_v_per_s: 1e-5,
            analog_gain: 1.0,
            offset_v: 0.0,
            adc_bits: None,
            rows: 204,
            cols: 240,
            fpn_seed: 1,
            optics: Optics::default(),
            cfa: Cfa {
                rows: 2,
                cols: 2,
                pattern: vec![0, 1, 2, 3],
                channel_names: ["R", "G", "W", "B"].map(String::from).to_vec(),
            },
            filters,
            ir_cut: parametric::IR_CUT,
            qe: parametric::SILICON_QE,
        }
    }

    /// Load and validate a TOML design. CSV curves are read too (on the
    /// default grid, from `iset`; `None`: the built-in data), so a missing
    /// file or column fails here.
    pub fn load(path: impl AsRef<Path>, iset: Option<&IsetData>) -> Result<Self, CameraError> {
        Ok(Self::load_noted(path, iset)?.design)
    }

    /// [`Self::load`], with the notes on its curves ([`Self::resolve_curves_noted`]).
    pub fn load_noted(
        path: impl AsRef<Path>,
        iset: Option<&IsetData>,
    ) -> Result<LoadedDesign, CameraError> {
        let p = path.as_ref();
        let text = std::fs::read_to_string(p).map_err(|source| CameraError::Io {
            path: p.display().to_string(),
            source,
        })?;
        let design = Self::from_toml_str(&text).map_err(|e| match e {
            CameraError::Toml { msg, .. } => CameraError::Toml {
                path: p.display().to_string(),
                msg,
            },
            CameraError::InvalidDesign(m) => {
                CameraError::InvalidDesign(format!("{}: {m}", p.display()))
            }
            other => other,
        })?;
        let dir = p.parent().unwrap_or(Path::new(""));
        let design = design.with_curves_beside(dir);
        let (_, notes) = design
            .resolve_curves_noted(&WavelengthGrid::default(), iset)
            .map_err(|e| match e {
                // the file the curve's design is in, as errors in the TOML itself name it
                CameraError::InvalidDesign(m) => {
                    let looked = if m.contains("is neither") {
                        let dir = if dir.as_os_str().is_empty() {
                            Path::new(".")
                        } else {
                            dir
                        };
                        format!(
                            "; looked first beside the sensor TOML, in {}",
                            dir.display()
                        )
                    } else {
                        String::new()
                    };
                    CameraError::InvalidDesign(format!("{}: {m}{looked}", p.display()))
                }
                other => other,
            })?;
        Ok(LoadedDesign { design, notes })
    }

    /// The design with every relative CSV path that names a file in `dir` (the sensor
    /// TOML's folder) made absolute: a user's curves beside their TOML are found from any
    /// working directory. Other relative paths stay tables of the spectral data.
    pub fn with_curves_beside(mut self, dir: &Path) -> Self {
        let beside = |f: &mut FilterSpec| {
            if let FilterSpec::Csv { path, .. } = f
                && Path::new(path.as_str()).is_relative()
            {
                let cand = dir.join(path.as_str());
                if cand.is_file() {
                    let abs = std::fs::canonicalize(&cand).unwrap_or(cand);
                    *path = abs.display().to_string();
                }
            }
        };
        self.filters.values_mut().for_each(beside);
        beside(&mut self.ir_cut);
        beside(&mut self.qe);
        self
    }

    /// The design with every CSV curve replaced by its samples ([`FilterSpec::inlined`]): a
    /// design that reads no file, as the service takes one over HTTP.
    pub fn inlined(mut self, iset: Option<&IsetData>) -> Result<Self, CameraError> {
        let name = self.name.clone();
        for (ch, f) in self.filters.iter_mut() {
            *f = f.inlined(iset, &format!("'{name}': filter '{ch}'"))?;
        }
        self.ir_cut = self.ir_cut.inlined(iset, &format!("'{name}': ir_cut"))?;
        self.qe = self.qe.inlined(iset, &format!("'{name}': qe"))?;
        Ok(self)
    }

    /// The design as a table records it: every curve [`FilterSpec::portable`], so that the
    /// table needs none of the files it was trained from.
    pub fn portable(mut self, iset: Option<&IsetData>) -> Self {
        let name = self.name.clone();
        for (ch, f) in self.filters.iter_mut() {
            *f = f.portable(iset, &format!("'{name}': filter '{ch}'"));
        }
        self.ir_cut = self.ir_cut.portable(iset, &format!("'{name}': ir_cut"));
        self.qe = self.qe.portable(iset, &format!("'{name}': qe"));
        self
    }

    /// Parse and validate TOML text: a design file, which must give its `name`
    /// (`Self::check_given`).
    pub fn from_toml_str(text: &str) -> Result<Self, CameraError> {
        let toml_err = |e: toml::de::Error| CameraError::Toml {
            path: "<text>".into(),
            msg: e.to_string(),
        };
        let mut d: Self = toml::from_str(text).map_err(toml_err)?;
        let keys: toml::Table = toml::from_str(text).map_err(toml_err)?;
        d.check_given(|k| keys.contains_key(k))?;
        d.validate()?;
        d.check_new()?;
        Ok(d)
    }

    /// A design as a JSON object with the TOML file's keys (a training job's `sensor`),
    /// checked as a file is (`Self::check_given`, [`Self::validate`]).
    pub fn from_json(value: serde_json::Value) -> Result<Self, CameraError> {
        let given = |k: &str| value.get(k).is_some_and(|v| !v.is_null());
        let keys = ["name", "description", "cfa", "filters"];
        let has = keys.map(given);
        let mut d: Self =
            serde_json::from_value(value).map_err(|e| CameraError::Json(e.to_string()))?;
        d.check_given(|k| keys.iter().zip(has).any(|(key, h)| h && *key == k))?;
        d.validate()?;
        d.check_new()?;
        Ok(d)
    }

    /// What a design must give itself rather than take from the paper's: its `name` (else
    /// it would pass for `rgbw-paper`), with its own `cfa` the matching `filters`, and with
    /// its own `filters` the `cfa` they fit (when the paper's do not match). A design without
    /// a `description` has none, not the paper sensor's. `given` says whether a key was given.
    fn check_given(&mut self, given: impl Fn(&str) -> bool) -> Result<(), CameraError> {
        if !given("description") {
            self.description.clear();
        }
        if !given("name") {
            return Err(CameraError::InvalidDesign(
                "`name` is missing: a sensor design must name itself (name = \"my-sensor\"), \
                 else it would pass for the paper's rgbw-paper"
                    .into(),
            ));
        }
        let paper = Self::paper_default();
        let mut ours: Vec<&String> = self.cfa.channel_names.iter().collect();
        let mut theirs: Vec<&String> = paper.filters.keys().collect();
        ours.sort();
        theirs.sort();
        let mut filters: Vec<&String> = self.filters.keys().collect();
        filters.sort();
        if given("filters") && !given("cfa") && filters != ours {
            return Err(CameraError::InvalidDesign(format!(
                "'{}': [filters] ({}) are given without a cfa; without one the CFA is the \
                 paper's \"{}\": give the pattern, e.g. cfa = \"RG/GB\"",
                self.name,
                self.filters.keys().cloned().collect::<Vec<_>>().join(", "),
                self.cfa
            )));
        }
        if given("cfa") && !given("filters") && ours != theirs {
            return Err(CameraError::InvalidDesign(format!(
                "'{}': cfa \"{}\" is given without [filters]: a file giving its own cfa must \
                 give the matching filters (one curve per CFA channel: {})",
                self.name,
                self.cfa,
                self.cfa.channel_names.join(", ")
            )));
        }
        Ok(())
    }

    /// What a design described now must be, beyond [`Self::validate`] (which the designs
    /// stored in older tables must keep passing): a name that is an identifier (it names
    /// folders), an offset that leaves the signal half the swing, and a CFA that is not a
    /// Bayer phase written in one row (`RGGB`).
    fn check_new(&self) -> Result<(), CameraError> {
        let err = |msg: String| {
            Err(CameraError::InvalidDesign(format!(
                "'{}': {msg}",
                self.name
            )))
        };
        if !is_identifier(&self.name) {
            return err(format!(
                "name '{}' must be an identifier: up to {MAX_NAME_LEN} letters, digits, '-', \
                 '_', '.' or '+', not starting with '.' (it names folders and tables)",
                self.name
            ));
        }
        let max_offset = MAX_OFFSET_FRACTION * self.voltage_swing_v;
        if self.offset_v.abs() > max_offset {
            return err(format!(
                "offset_v = {} must be at most {max_offset} V in magnitude (half the swing \
                 {} V: the signal needs the rest)",
                self.offset_v, self.voltage_swing_v
            ));
        }
        // the simulation takes the swing as the pixel's largest signal (auto-exposure aims at
        // 95 % of it, the saturation classes start just below it): a well that fills first
        // would clip unseen, below both
        let volts_per_e = self.conversion_gain_v() * self.analog_gain;
        let full_well_v = self.well_capacity_e * volts_per_e + self.offset_v;
        if full_well_v < self.voltage_swing_v * (1.0 - 1e-6) {
            return err(format!(
                "well_capacity_e = {} fills at {:.4} V (× {} µV/e⁻ × analog_gain {}{}), \
                 below voltage_swing_v = {} V: the pixel would clip before its swing, which \
                 the simulation takes as its largest signal; set voltage_swing_v = {:.4} (the \
                 full well's voltage) or well_capacity_e ≥ {:.0}",
                self.well_capacity_e,
                full_well_v,
                self.conversion_gain_uv_per_e,
                self.analog_gain,
                if self.offset_v != 0.0 {
                    format!(" + offset {} V", self.offset_v)
                } else {
                    String::new()
                },
                self.voltage_swing_v,
                full_well_v,
                ((self.voltage_swing_v - self.offset_v) / volts_per_e * (1.0 - 1e-9)).ceil()
            ));
        }
        if looks_like_bayer_in_one_row(&self.cfa) {
            return err(format!(
                "cfa \"{}\" is one row of four pixels; a 2×2 tile is written row by row with \
                 '/', e.g. \"RG/GB\" for RGGB",
                self.cfa
            ));
        }
        Ok(())
    }

    /// The design as TOML text (loads back to an equal design).
    pub fn to_toml_string(&self) -> Result<String, CameraError> {
        toml::to_string(self).map_err(|e| CameraError::Toml {
            path: "<text>".into(),
            msg: e.to_string(),
        })
    }

    /// Check every number is finite and in a sane range, the CFA is valid and
    /// every CFA channel has a filter (and every filter a CFA channel).
    pub fn validate(&self) -> Result<(), CameraError> {
        let name = if self.name.is_empty() {
            "<unnamed>"
        } else {
            &self.name
        };
        let err = |msg: String| Err(CameraError::InvalidDesign(format!("'{name}': {msg}")));
        if self.name.trim().is_empty() {
            return err("name is empty".into());
        }
        let ranges: [(&str, f64, f64, f64, bool); 12] = [
            // (field, value, low, high, low is inclusive)
            ("pixel_size_um", self.pixel_size_um, 0.1, 100.0, false),
            ("fill_factor", self.fill_factor, 0.0, 1.0, false),
            (
                "conversion_gain_uv_per_e",
                self.conversion_gain_uv_per_e,
                0.01,
                1e4,
                false,
            ),
            ("voltage_swing_v", self.voltage_swing_v, 0.0, 100.0, false),
            ("well_capacity_e", self.well_capacity_e, 1.0, 1e9, true),
            ("read_noise_mv", self.read_noise_mv, 0.0, 1e3, true),
            ("dsnu_mv", self.dsnu_mv, 0.0, 1e3, true),
            ("prnu_percent", self.prnu_percent, 0.0, 100.0, true),
            (
                "dark_voltage_v_per_s",
                self.dark_voltage_v_per_s,
                0.0,
                1e3,
                true,
            ),
            ("analog_gain", self.analog_gain, 0.0, 1e4, false),
            ("optics.f_number", self.optics.f_number, 0.5, 128.0, true),
            (
                "optics.focal_length_mm",
                self.optics.focal_length_mm,
                0.0,
                1e4,
                false,
            ),
        ];
        if !(1..=MAX_SAMPLES_PER_PIXEL).contains(&self.optics.samples_per_pixel) {
            return err(format!(
                "optics.samples_per_pixel = {} must be within 1–{MAX_SAMPLES_PER_PIXEL}",
                self.optics.samples_per_pixel
            ));
        }
        for (field, v, lo, hi, lo_incl) in ranges {
            let ok = v.is_finite() && v <= hi && if lo_incl { v >= lo } else { v > lo };
            if !ok {
                let open = if lo_incl { '[' } else { '(' };
                return err(format!("{field} = {v} must be within {open}{lo}, {hi}]"));
            }
        }
        if !(self.offset_v.is_finite() && self.offset_v.abs() < self.voltage_swing_v) {
            return err(format!(
                "offset_v = {} must be finite and smaller in magnitude than the swing {} V",
                self.offset_v, self.voltage_swing_v
            ));
        }
        if let Some(b) = self.adc_bits
            && !(1..=24).contains(&b)
        {
            return err(format!("adc_bits = {b} must be within 1–24"));
        }
        if !(1..=65_536).contains(&self.rows) || !(1..=65_536).contains(&self.cols) {
            return err(format!(
                "size {}×{} must be within 1–65536 per side",
                self.rows, self.cols
            ));
        }
        self.validate_channels(name)?;
        self.ir_cut.validate(&format!("'{name}': ir_cut"))?;
        self.qe.validate(&format!("'{name}': qe"))?;
        Ok(())
    }

    /// The CFA is valid, every CFA channel has a filter and every filter a CFA channel,
    /// and every filter's parameters are valid; `name` names the design in errors.
    fn validate_channels(&self, name: &str) -> Result<(), CameraError> {
        let invalid = |msg: String| CameraError::InvalidDesign(format!("'{name}': {msg}"));
        // The CFA came through `Cfa::parse` when deserialised; re-check in case
        // it was built by hand.
        if let Err(e) = Cfa::new(
            self.cfa.rows,
            self.cfa.cols,
            self.cfa.pattern.clone(),
            self.cfa.channel_names.clone(),
        ) {
            return Err(invalid(e.to_string()));
        }
        for ch in &self.cfa.channel_names {
            if !self.filters.contains_key(ch) {
                return Err(invalid(format!(
                    "CFA channel '{ch}' has no entry in [filters] (defined: {})",
                    self.filters.keys().cloned().collect::<Vec<_>>().join(", ")
                )));
            }
        }
        for (ch, f) in &self.filters {
            if self.cfa.channel_index(ch).is_none() {
                return Err(invalid(format!(
                    "filter '{ch}' is not used by the CFA \"{}\"",
                    self.cfa
                )));
            }
            f.validate(&format!("'{name}': filter '{ch}'"))?;
        }
        Ok(())
    }

    /// Per-channel responsivity on `grid`, in electrons per photon: colour
    /// filter × IR-cut × QE, in CFA channel order. Fails if a channel has no
    /// response at all on the grid.
    pub fn resolve_curves(
        &self,
        grid: &WavelengthGrid,
        iset: Option<&IsetData>,
    ) -> Result<Vec<Spectrum>, CameraError> {
        Ok(self.resolve_curves_noted(grid, iset)?.0)
    }

    /// [`Self::resolve_curves`], with a note for every curve (IR-cut, QE, then the filters in
    /// CFA channel order) whose samples cover clearly less than `grid` ([`CoverageNote`]).
    pub fn resolve_curves_noted(
        &self,
        grid: &WavelengthGrid,
        iset: Option<&IsetData>,
    ) -> Result<(Vec<Spectrum>, Vec<CoverageNote>), CameraError> {
        self.validate()?;
        let (ir, ir_note) =
            self.ir_cut
                .resolve_noted(grid, iset, &format!("'{}': ir_cut", self.name))?;
        let (qe, qe_note) = self
            .qe
            .resolve_noted(grid, iset, &format!("'{}': qe", self.name))?;
        let mut notes: Vec<CoverageNote> = ir_note.into_iter().chain(qe_note).collect();
        let common = ir.product(&qe)?;
        let mut curves = Vec::with_capacity(self.cfa.channel_names.len());
        for ch in &self.cfa.channel_names {
            let what = format!("'{}': filter '{ch}'", self.name);
            // validate() guarantees the entry exists.
            let f = self
                .filters
                .get(ch)
                .ok_or_else(|| CameraError::InvalidDesign(format!("{what}: missing")))?;
            let (r, note) = f.resolve_noted(grid, iset, &what)?;
            let r = r.product(&common)?;
            if r.max() <= 0.0 {
                // a curve sampled off the grid (in µm, say) is the likely cause: say so
                let off_grid: String = notes
                    .iter()
                    .chain(&note)
                    .map(|n| format!("; {n}"))
                    .collect();
                return Err(CameraError::InvalidDesign(format!(
                    "{what}: the channel has no response on {}–{} nm (filter × IR-cut × QE is \
                     zero){off_grid}",
                    grid.start_nm,
                    grid.end_nm()
                )));
            }
            notes.extend(note);
            curves.push(r);
        }
        Ok((curves, notes))
    }

    /// Conversion gain in V/e⁻.
    pub fn conversion_gain_v(&self) -> f64 {
        self.conversion_gain_uv_per_e * 1e-6
    }

    /// Read noise σ in V.
    pub fn read_noise_v(&self) -> f64 {
        self.read_noise_mv * 1e-3
    }

    /// DSNU σ in V.
    pub fn dsnu_v(&self) -> f64 {
        self.dsnu_mv * 1e-3
    }

    /// PRNU σ as a fraction (0.002218 for 0.2218 %).
    pub fn prnu_fraction(&self) -> f64 {
        self.prnu_percent * 1e-2
    }

    /// Pixel area in m².
    pub fn pixel_area_m2(&self) -> f64 {
        (self.pixel_size_um * 1e-6).powi(2)
    }
}

#[cfg(test)]
mod tests;
