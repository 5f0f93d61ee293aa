//! The sensor catalogue: every sensor l3 ships, by name. The six designs in `config/sensors/`
//! plus the 49 real cameras whose measured R, G, B sensitivities come from the Academy's
//! rawtoaces-data (`config/spectra/cameras/rawtoaces/`, Apache-2.0), each named
//! `bayer-<maker>-<model>` in lowercase kebab case and compiled into the binary.
//!
//! A catalogue camera is an RGGB Bayer sensor with its measured whole-channel responsivities
//! (filters, IR-cut and QE together) behind the paper's Figure 2 electronics, pixel and lens,
//! as `bayer-nikon-d5100` is: the cameras' own pixel pitch and well capacity are not in the
//! data, and the same pixel makes the sensors comparable. Two cameras already had a shipped
//! design under their name (Nikon D5100 from NPL's measurement, the same values; Canon EOS 5D
//! Mark II from rawtoaces' 2017 measurement): their catalogue entries carry `-rawtoaces`.
//!
//! [`match_camera`] finds the sensors of a camera from what a raw file says of it
//! (UniqueCameraModel, or Make and Model), through rawtoaces' table of alternative names.
//! The lookups here are plain string work over 55 entries; no crate does this matching.

use std::sync::OnceLock;

use serde::Serialize;

use super::{CameraError, Cfa, LoadedDesign, SensorDesign};
use crate::spectral::IsetData;

/// Where a catalogue sensor comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SensorSource {
    /// A design in `config/sensors/`.
    Shipped,
    /// A measured camera of rawtoaces-data.
    Rawtoaces,
}

/// One sensor of the catalogue.
#[derive(Clone, Debug, Serialize)]
pub struct CatalogueEntry {
    /// The name every `--sensor` and job `sensor` accepts.
    pub name: String,
    pub source: SensorSource,
    /// The camera it measures (maker and model as rawtoaces names them), if it is one.
    pub make: Option<String>,
    pub model: Option<String>,
    /// The spectral data file of a measured camera (relative to the spectral data root).
    pub curves: Option<String>,
    #[serde(skip)]
    toml: String,
}

impl CatalogueEntry {
    /// The design as TOML.
    pub fn toml(&self) -> &str {
        &self.toml
    }

    /// The design, validated (its curves are not read: see [`SensorDesign::resolve_curves`]).
    pub fn design(&self) -> Result<SensorDesign, CameraError> {
        SensorDesign::from_toml_str(&self.toml)
    }

    /// The design with its curves read from `iset` (`None`: the built-in data).
    pub fn load(&self, iset: Option<&IsetData>) -> Result<SensorDesign, CameraError> {
        let d = self.design()?;
        d.resolve_curves(&crate::spectral::WavelengthGrid::default(), iset)?;
        Ok(d)
    }

    /// The design's CFA.
    pub fn cfa(&self) -> Result<Cfa, CameraError> {
        Ok(self.design()?.cfa)
    }
}

/// The shipped designs: `(file name, TOML)`.
macro_rules! shipped {
    ($($name:literal),* $(,)?) => {
        [$(($name, include_str!(concat!("../../config/sensors/", $name, ".toml")))),*]
    };
}
const SHIPPED: [(&str, &str); 6] = shipped![
    "bayer-canon-eos-5d-mark-ii",
    "bayer-nikon-d5100",
    "bayer-paper",
    "rgbw-ar0132at",
    "rgbw-iset",
    "rgbw-paper",
];

/// The cameras a shipped design measures, by its name.
const SHIPPED_CAMERAS: [(&str, &str, &str); 2] = [
    ("bayer-canon-eos-5d-mark-ii", "Canon", "EOS 5D Mark II"),
    ("bayer-nikon-d5100", "Nikon", "D5100"),
];

const CAMERAS_TSV: &str = include_str!("../../config/spectra/cameras/rawtoaces/cameras.tsv");
const ALIASES_JSON: &str = include_str!("../../config/spectra/cameras/rawtoaces/aliases.json");

/// Lowercase kebab case: runs of anything but ASCII letters and digits become one `-`.
pub fn kebab(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if c.is_ascii_alphanumeric() {
            out.push(c.to_ascii_lowercase());
        } else if !out.is_empty() && !out.ends_with('-') {
            out.push('-');
        }
    }
    while out.ends_with('-') {
        out.pop();
    }
    out
}

/// The design of a measured camera: the paper's Figure 2 electronics and lens (as
/// `config/sensors/bayer-nikon-d5100.toml`), an RGGB CFA and the camera's curves.
fn camera_toml(name: &str, make: &str, model: &str, file: &str) -> String {
    let csv = format!("cameras/rawtoaces/{file}");
    format!(
        r#"name = "{name}"
description = "RGGB Bayer, {make} {model} measured sensitivities (rawtoaces-data), paper's Figure 2 electronics"
pixel_size_um = 2.2
fill_factor = 0.45
conversion_gain_uv_per_e = 200.0
voltage_swing_v = 1.8
well_capacity_e = 9000.0
read_noise_mv = 1.34
dsnu_mv = 1.41
prnu_percent = 0.2218
dark_voltage_v_per_s = 1e-5
analog_gain = 1.0
offset_v = 0.0
rows = 204
cols = 240
fpn_seed = 1
cfa = "RG/GB"

[optics]
f_number = 4.0
focal_length_mm = 3.0

[filters]
R = {{ csv = "{csv}", column = "R" }}
G = {{ csv = "{csv}", column = "G" }}
B = {{ csv = "{csv}", column = "B" }}

[ir_cut]
constant = 1.0

[qe]
constant = 1.0
"#
    )
}

fn build() -> Vec<CatalogueEntry> {
    let mut v: Vec<CatalogueEntry> = SHIPPED
        .iter()
        .map(|(name, toml)| {
            let cam = SHIPPED_CAMERAS.iter().find(|(n, ..)| n == name);
            CatalogueEntry {
                name: (*name).to_string(),
                source: SensorSource::Shipped,
                make: cam.map(|c| c.1.to_string()),
                model: cam.map(|c| c.2.to_string()),
                curves: None,
                toml: (*toml).to_string(),
            }
        })
        .collect();
    for line in CAMERAS_TSV.lines().skip(1) {
        let cols: Vec<&str> = line.split('\t').collect();
        let [file, make, model, ..] = cols[..] else {
            continue;
        };
        let mut name = format!("bayer-{}-{}", kebab(make), kebab(model));
        if v.iter().any(|e| e.name == name) {
            name.push_str("-rawtoaces");
        }
        let toml = camera_toml(&name, make, model, file);
        v.push(CatalogueEntry {
            name,
            source: SensorSource::Rawtoaces,
            make: Some(make.to_string()),
            model: Some(model.to_string()),
            curves: Some(format!("cameras/rawtoaces/{file}")),
            toml,
        });
    }
    v.sort_by(|a, b| a.name.cmp(&b.name));
    v
}

/// Every sensor l3 ships, sorted by name.
pub fn catalogue() -> &'static [CatalogueEntry] {
    static CAT: OnceLock<Vec<CatalogueEntry>> = OnceLock::new();
    CAT.get_or_init(build)
}

/// The catalogue sensor called `name` (case-insensitive).
pub fn find(name: &str) -> Option<&'static CatalogueEntry> {
    let name = name.trim();
    catalogue()
        .iter()
        .find(|e| e.name.eq_ignore_ascii_case(name))
}

/// A catalogue sensor as `l3 sensors` and `GET /v1/sensors` list it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SensorSummary {
    pub name: String,
    /// The CFA as text, rows separated by `/` (`RG/GB`).
    pub cfa: String,
    pub source: SensorSource,
    pub make: Option<String>,
    pub model: Option<String>,
    /// Whether a good stored table was trained for it.
    pub trained: bool,
    /// The newest such table.
    pub table_id: Option<String>,
}

impl CatalogueEntry {
    /// The entry summarised, with the newest good table trained for it (if any).
    pub fn summary(&self, table_id: Option<&str>) -> SensorSummary {
        SensorSummary {
            name: self.name.clone(),
            cfa: self.cfa().map(|c| c.to_string()).unwrap_or_default(),
            source: self.source,
            make: self.make.clone(),
            model: self.model.clone(),
            trained: table_id.is_some(),
            table_id: table_id.map(String::from),
        }
    }
}

/// Every catalogue sensor summarised, by name; `newest_table(name)` is the newest good table
/// trained for the sensor `name`, if any.
pub fn listing<'a>(newest_table: impl Fn(&str) -> Option<&'a str>) -> Vec<SensorSummary> {
    catalogue()
        .iter()
        .map(|e| e.summary(newest_table(&e.name)))
        .collect()
}

/// What a raw file says of its camera (each possibly absent).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct CameraId {
    pub unique_model: Option<String>,
    pub make: Option<String>,
    pub model: Option<String>,
}

impl CameraId {
    /// Whether the file says nothing of its camera.
    pub fn is_empty(&self) -> bool {
        [&self.unique_model, &self.make, &self.model]
            .iter()
            .all(|f| f.as_deref().is_none_or(|s| s.trim().is_empty()))
    }
}

/// How a camera was recognised.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct CameraMatch {
    /// The catalogue sensors of that camera (more than one when a shipped design and a
    /// catalogue measurement describe the same camera), best first.
    pub sensors: Vec<&'static str>,
    /// The catalogue's maker and model of it.
    pub make: String,
    pub model: String,
    /// Which tag matched: `unique_camera_model` or `make_model`, with `+alias` when
    /// rawtoaces' table of alternative names was needed; `sensor_name` for a UniqueCameraModel
    /// that is a camera's catalogue name, as `l3 simulate` writes it.
    pub by: String,
}

/// rawtoaces' alternative names: maker → maker, and (maker, model) → (maker, model), keyed
/// by kebab case.
struct Aliases {
    makes: Vec<(String, String)>,
    models: Vec<((String, String), (String, String))>,
}

fn aliases() -> &'static Aliases {
    static A: OnceLock<Aliases> = OnceLock::new();
    A.get_or_init(|| {
        let mut a = Aliases {
            makes: Vec::new(),
            models: Vec::new(),
        };
        let Ok(v) = serde_json::from_str::<serde_json::Value>(ALIASES_JSON) else {
            return a;
        };
        let cam = &v["data"]["camera"];
        if let Some(m) = cam["make"].as_object() {
            for (k, to) in m {
                if let Some(to) = to.as_str() {
                    a.makes.push((kebab(k), kebab(to)));
                }
            }
        }
        if let Some(m) = cam["model"].as_object() {
            for (make, models) in m {
                for (model, to) in models.as_object().into_iter().flatten() {
                    if let (Some(tm), Some(tmo)) = (to["make"].as_str(), to["model"].as_str()) {
                        a.models
                            .push(((kebab(make), kebab(model)), (kebab(tm), kebab(tmo))));
                    }
                }
            }
        }
        a
    })
}

/// A maker as the catalogue spells it (kebab case): files write `NIKON CORPORATION`,
/// `SONY`, `FUJIFILM`, `Canon`; the first word usually suffices.
fn canonical_make(make: &str) -> Option<String> {
    let k = kebab(make);
    if let Some((_, to)) = aliases().makes.iter().find(|(from, _)| *from == k) {
        return Some(to.clone());
    }
    let makers = camera_makers();
    if makers.contains(&k) {
        return Some(k);
    }
    // "nikon-corporation", "olympus-imaging-corp", "sony-group": a known maker's prefix
    makers
        .iter()
        .find(|m| k.starts_with(&format!("{m}-")))
        .cloned()
}

/// The makers of the catalogue's cameras, kebab case.
fn camera_makers() -> Vec<String> {
    let mut v: Vec<String> = catalogue()
        .iter()
        .filter_map(|e| e.make.as_deref().map(kebab))
        .collect();
    v.sort();
    v.dedup();
    v
}

/// The sensors of (maker, model) (kebab case), following an alias if needed.
fn lookup(make: &str, model: &str) -> Option<(Vec<&'static str>, String, String, bool)> {
    let direct = |mk: &str, mo: &str| -> Option<(Vec<&'static str>, String, String)> {
        let hits: Vec<&'static CatalogueEntry> = catalogue()
            .iter()
            .filter(|e| {
                e.make.as_deref().map(kebab).as_deref() == Some(mk)
                    && e.model.as_deref().map(kebab).as_deref() == Some(mo)
            })
            .collect();
        let first = hits.first()?;
        // the shipped design first, then the catalogue measurement
        let mut names: Vec<&'static CatalogueEntry> = hits.clone();
        names.sort_by_key(|e| (e.source != SensorSource::Shipped, e.name.clone()));
        Some((
            names.iter().map(|e| e.name.as_str()).collect(),
            first.make.clone().unwrap_or_default(),
            first.model.clone().unwrap_or_default(),
        ))
    };
    // a model often repeats its maker ("Canon EOS 5D Mark II", "NIKON D5100")
    let model = model.strip_prefix(&format!("{make}-")).unwrap_or(model);
    for model in model_spellings(model) {
        if let Some((s, mk, mo)) = direct(make, &model) {
            return Some((s, mk, mo, false));
        }
        let alias = aliases()
            .models
            .iter()
            .find(|((am, amo), _)| am == make && *amo == model);
        if let Some((_, (tm, tmo))) = alias {
            return direct(tm, tmo).map(|(s, mk, mo)| (s, mk, mo, true));
        }
    }
    None
}

/// The spellings of an EXIF model (kebab case, its maker removed) to look up, as written
/// first. Canon's EXIF models of the 2000s end in `DIGITAL` ("Canon EOS 400D DIGITAL") or
/// put it after EOS ("Canon EOS DIGITAL REBEL XTi", "Canon EOS Kiss Digital X"), where
/// rawtoaces names the camera "EOS 400D", "Digital Rebel XTi" and "Kiss Digital X": the
/// model without its trailing `digital`, and without a leading `eos` before `digital` or
/// `kiss`, are the same camera. Nothing else is guessed.
fn model_spellings(model: &str) -> Vec<String> {
    let mut v = vec![model.to_string()];
    if let Some(m) = model.strip_suffix("-digital") {
        v.push(m.to_string());
    }
    if let Some(m) = model.strip_prefix("eos-")
        && (m.starts_with("digital-") || m.starts_with("kiss-"))
    {
        v.push(m.to_string());
    }
    v
}

/// The catalogue sensors of the camera `id` describes: UniqueCameraModel first (split into
/// a known maker and the model), then Make + Model. Case, spaces and punctuation do not
/// matter; rawtoaces' alternative names are followed.
pub fn match_camera(id: &CameraId) -> Option<CameraMatch> {
    let found = |(sensors, make, model, alias): (Vec<&'static str>, String, String, bool),
                 tag: &str| CameraMatch {
        sensors,
        make,
        model,
        by: if alias {
            format!("{tag}+alias")
        } else {
            tag.to_string()
        },
    };
    // `l3 simulate --sensor bayer-sony-ilce-9` names the sensor it simulated
    if let Some(e) = id.unique_model.as_deref().and_then(find)
        && let (Some(make), Some(model)) = (&e.make, &e.model)
    {
        return Some(CameraMatch {
            sensors: vec![e.name.as_str()],
            make: make.clone(),
            model: model.clone(),
            by: "sensor_name".into(),
        });
    }
    if let Some(u) = id.unique_model.as_deref() {
        let k = kebab(u);
        let mut makers = camera_makers();
        makers.extend(aliases().makes.iter().map(|(from, _)| from.clone()));
        for m in makers {
            if let Some(rest) = k.strip_prefix(&format!("{m}-"))
                && let Some(make) = canonical_make(&m)
                && let Some(hit) = lookup(&make, rest)
            {
                return Some(found(hit, "unique_camera_model"));
            }
        }
    }
    let make = canonical_make(id.make.as_deref()?)?;
    let model = kebab(id.model.as_deref()?);
    lookup(&make, &model).map(|hit| found(hit, "make_model"))
}

/// A sensor named on a command line: a TOML file when `arg` is one, else a catalogue name,
/// with the notes on its curves ([`SensorDesign::load_noted`]). The error for neither names
/// both.
pub fn load_named_or_file(
    arg: &std::path::Path,
    iset: Option<&IsetData>,
) -> Result<LoadedDesign, CameraError> {
    if arg.is_file() {
        return SensorDesign::load_noted(arg, iset);
    }
    match arg.to_str().and_then(find) {
        Some(e) => {
            let design = e.design()?;
            let grid = crate::spectral::WavelengthGrid::default();
            let (_, notes) = design.resolve_curves_noted(&grid, iset)?;
            Ok(LoadedDesign { design, notes })
        }
        None => Err(CameraError::InvalidArgument(format!(
            "sensor '{}' is neither a TOML file nor a catalogue sensor (`l3 sensors` lists the {} of them)",
            arg.display(),
            catalogue().len()
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(u: Option<&str>, make: Option<&str>, model: Option<&str>) -> CameraId {
        CameraId {
            unique_model: u.map(String::from),
            make: make.map(String::from),
            model: model.map(String::from),
        }
    }

    #[test]
    fn the_catalogue_has_the_six_designs_and_the_49_cameras() {
        let c = catalogue();
        assert_eq!(c.len(), 55);
        let shipped = c
            .iter()
            .filter(|e| e.source == SensorSource::Shipped)
            .count();
        assert_eq!(shipped, 6);
        let mut names: Vec<&str> = c.iter().map(|e| e.name.as_str()).collect();
        names.dedup();
        assert_eq!(names.len(), 55, "names are unique");
        for e in c {
            assert_eq!(e.name, kebab(&e.name), "{} is kebab case", e.name);
            let d = e
                .load(None)
                .unwrap_or_else(|err| panic!("{}: {err}", e.name));
            assert_eq!(d.name, e.name);
        }
        for n in [
            "bayer-sony-ilce-9",
            "bayer-canon-eos-1d-x-mark-ii",
            "bayer-nikon-z-f",
            "bayer-fujifilm-gfx-100",
            "bayer-canon-eos-5d-mark-ii-rawtoaces",
            "bayer-nikon-d5100-rawtoaces",
            "rgbw-iset",
        ] {
            assert!(find(n).is_some(), "{n}");
        }
        assert_eq!(
            find("BAYER-SONY-ILCE-9").map(|e| e.name.as_str()),
            Some("bayer-sony-ilce-9")
        );
        assert!(find("bayer-sony-ilce-10").is_none());
    }

    #[test]
    fn cameras_are_matched_from_what_files_write() {
        let m = match_camera(&id(Some("Sony ILCE-9"), None, None)).unwrap();
        assert_eq!(m.sensors, ["bayer-sony-ilce-9"]);
        assert_eq!(m.by, "unique_camera_model");
        // a simulated frame names its sensor; a sensor that is no camera matches none
        let m = match_camera(&id(Some("bayer-nikon-d5100-rawtoaces"), None, None)).unwrap();
        assert_eq!(
            (m.sensors.as_slice(), m.by.as_str()),
            (["bayer-nikon-d5100-rawtoaces"].as_slice(), "sensor_name")
        );
        assert!(match_camera(&id(Some("rgbw-paper"), None, None)).is_none());
        let m = match_camera(&id(None, Some("SONY"), Some("ILCE-9"))).unwrap();
        assert_eq!(
            (m.sensors[0], m.by.as_str()),
            ("bayer-sony-ilce-9", "make_model")
        );
        let m = match_camera(&id(None, Some("NIKON CORPORATION"), Some("NIKON D5100"))).unwrap();
        assert_eq!(
            m.sensors,
            ["bayer-nikon-d5100", "bayer-nikon-d5100-rawtoaces"]
        );
        let m = match_camera(&id(None, Some("Canon"), Some("Canon EOS 5D Mark II"))).unwrap();
        assert_eq!(m.sensors[0], "bayer-canon-eos-5d-mark-ii");
        let m = match_camera(&id(None, Some("Canon"), Some("Canon EOS 400D"))).unwrap();
        assert_eq!(m.sensors, ["bayer-canon-digital-rebel-xti"]);
        assert_eq!(m.by, "make_model+alias");
        let m = match_camera(&id(None, Some("Canon"), Some("Canon EOS 4000D"))).is_none();
        assert!(m, "a model the catalogue lacks is not guessed");
        assert!(match_camera(&id(None, Some("Canon"), Some("Canon EOS 4000D DIGITAL"))).is_none());
        let m = match_camera(&id(Some("Fujifilm GFX100S"), None, None)).unwrap();
        assert_eq!(m.sensors, ["bayer-fujifilm-gfx-100"]);
        // UniqueCameraModel that names no catalogue camera falls back to Make + Model
        let m = match_camera(&id(Some("Prototype 7"), Some("Sony"), Some("ILCE-7M4"))).unwrap();
        assert_eq!(m.sensors, ["bayer-sony-ilce-7m4"]);
        assert!(match_camera(&id(Some("Nokia N900"), Some("Nokia"), Some("N900"))).is_none());
        assert!(match_camera(&CameraId::default()).is_none());
    }

    /// The 400D's EXIF models: "DIGITAL" after the model (Europe), the Rebel name after
    /// "EOS DIGITAL" (America), the Kiss name (Japan); in Make + Model and UniqueCameraModel.
    #[test]
    fn canon_models_with_digital_and_regional_names() {
        let xti = ["bayer-canon-digital-rebel-xti"];
        for (model, by) in [
            ("Canon EOS 400D DIGITAL", "make_model+alias"),
            ("Canon EOS DIGITAL REBEL XTi", "make_model"),
            ("Canon EOS Kiss Digital X", "make_model+alias"),
        ] {
            let m = match_camera(&id(None, Some("Canon"), Some(model))).unwrap();
            assert_eq!(
                (m.sensors.as_slice(), m.by.as_str()),
                (&xti[..], by),
                "{model}"
            );
            let u = match_camera(&id(Some(model), None, None)).unwrap();
            assert_eq!(u.sensors, xti, "UniqueCameraModel {model}");
        }
        assert_eq!(model_spellings("eos-5d"), ["eos-5d"]);
        assert_eq!(model_spellings("eos-digital"), ["eos-digital", "eos"]);
    }

    #[test]
    fn the_listing_marks_trained_sensors() {
        let l = listing(|n| (n == "bayer-sony-ilce-9").then_some("tbl_1"));
        assert_eq!(l.len(), 55);
        let sony = l.iter().find(|s| s.name == "bayer-sony-ilce-9").unwrap();
        assert_eq!((sony.cfa.as_str(), sony.trained), ("RG/GB", true));
        assert_eq!(sony.table_id.as_deref(), Some("tbl_1"));
        assert_eq!(sony.make.as_deref(), Some("Sony"));
        assert_eq!(l.iter().filter(|s| s.trained).count(), 1);
        let rgbw = l.iter().find(|s| s.name == "rgbw-paper").unwrap();
        assert_eq!(rgbw.cfa, "RG/WB");
    }

    #[test]
    fn kebab_case() {
        assert_eq!(kebab("EOS-1D X Mark II"), "eos-1d-x-mark-ii");
        assert_eq!(kebab("  Z f "), "z-f");
        assert_eq!(kebab("Insta360 X5"), "insta360-x5");
    }
}
