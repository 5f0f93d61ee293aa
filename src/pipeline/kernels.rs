//! Kernel selection for a (table, light): a same-illuminant table's kernels fused with the
//! light's correction (the camera-aware C by default, the paper's T on request:
//! [`correction_for`]), a cross-illuminant table's own kernels; the chroma classes of a table
//! that balances them by the light take its neutral.
//!
//! [`KernelChoice`] makes the selection once, and with it the [`KernelKey`] that names what a
//! prepared renderer depends on besides its table: a cache of renderers keyed on it cannot
//! drift from the selection.

use std::str::FromStr;

use super::error::PipelineError;
use crate::camera::Camera;
use crate::l3::L3Table;
use crate::l3::correct::CorrectError;
use crate::l3::correct::IlluminantEntry;
use crate::l3::correct::{camera_corrected, noise_model, with_neutral};
use crate::l3::render::RenderError;
use crate::l3::render::fuse_entry;
use crate::l3::table::{TableError, TableKind};
use crate::spectral::{IsetData, WavelengthGrid};

/// Whether `table` renders with its own kernels under every illuminant (cross-illuminant
/// tables output D65 already); otherwise its kernels are fused with the illuminant's
/// correction.
pub fn uses_own_kernels(table: &L3Table) -> bool {
    table.meta.kind == TableKind::CrossIlluminant
}

/// How a same-illuminant table's output is taken from the acquisition light to D65.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum CorrectionMode {
    /// The registry's T: XYZ under the light → XYZ under D65, from colorimetry alone (the
    /// paper's method).
    #[serde(alias = "t")]
    Colorimetric,
    /// C, fitted per level on the table's own colour maps and its sensor's response under the light
    /// (`crate::l3::camera_correction`), wherever the light's spectrum is known; T for a
    /// correction given only as a matrix.
    #[default]
    Camera,
}

impl CorrectionMode {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Colorimetric => "colorimetric",
            Self::Camera => "camera",
        }
    }
}

impl FromStr for CorrectionMode {
    type Err = PipelineError;
    fn from_str(s: &str) -> Result<Self, PipelineError> {
        match s.to_ascii_lowercase().as_str() {
            "camera" => Ok(Self::Camera),
            "colorimetric" | "t" => Ok(Self::Colorimetric),
            _ => Err(PipelineError::Options(format!(
                "correction '{s}': expected camera or colorimetric (also written t)"
            ))),
        }
    }
}

/// What the correction of a light is fitted with before the kernels are built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fit {
    /// Nothing: the light's entry as it is.
    AsGiven,
    /// C in place of T, on the table's sensor (a same-illuminant table in
    /// [`CorrectionMode::Camera`] under a light whose spectrum is known).
    CameraAware,
    /// The sensor's neutral under the light, for chroma classes that balance by it.
    Neutral,
}

impl Fit {
    fn of(table: &L3Table, entry: &IlluminantEntry, mode: CorrectionMode) -> Fit {
        let known = entry.spd.is_some();
        if known && mode == CorrectionMode::Camera && !uses_own_kernels(table) {
            Fit::CameraAware
        } else if known && table.chroma_balances() {
            Fit::Neutral
        } else {
            Fit::AsGiven
        }
    }

    fn apply(
        self,
        table: &L3Table,
        entry: &IlluminantEntry,
        iset: Option<&IsetData>,
    ) -> Result<IlluminantEntry, PipelineError> {
        if self == Fit::AsGiven {
            return Ok(entry.clone());
        }
        let design = match table.sensor_design() {
            Ok(d) => d,
            // a table with no sensor description has nothing to fit C on: T
            Err(TableError::NoSensor) => return Ok(entry.clone()),
            Err(e) => return Err(RenderError::from(e).into()),
        };
        let camera =
            Camera::new(&design, WavelengthGrid::default(), iset).map_err(CorrectError::from)?;
        if self == Fit::CameraAware {
            Ok(camera_corrected(
                &camera,
                &table
                    .level_colour_maps(&noise_model(&design))
                    .map_err(RenderError::from)?,
                entry,
                iset,
            )?)
        } else {
            Ok(with_neutral(&camera, entry)?)
        }
    }
}

/// The correction `table` renders with under `entry` in `mode`: `entry` itself, or, for a
/// same-illuminant table with a sensor description in [`CorrectionMode::Camera`] under a
/// light whose spectrum is known, `entry` with C in place of T (fitted on the table's sensor, built-in curves or
/// `iset`'s). For a table whose chroma classes balance by the light, the entry also gets the
/// sensor's neutral under a light whose spectrum is known ([`IlluminantEntry::neutral`]).
pub fn correction_for(
    table: &L3Table,
    entry: &IlluminantEntry,
    mode: CorrectionMode,
    iset: Option<&IsetData>,
) -> Result<IlluminantEntry, PipelineError> {
    Fit::of(table, entry, mode).apply(table, entry, iset)
}

/// Where a render's kernels come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum KernelSource {
    /// The table's own (a cross-illuminant table).
    Own,
    /// The table's fused with the light's correction, taken to D65 in this mode.
    Fused(CorrectionMode),
}

impl KernelSource {
    /// The source of `table`'s kernels when its output is taken to D65 in `mode`.
    pub fn of(table: &L3Table, mode: CorrectionMode) -> Self {
        if uses_own_kernels(table) {
            KernelSource::Own
        } else {
            KernelSource::Fused(mode)
        }
    }

    /// The XYZ kernels of `table` under the (fitted) correction `entry`.
    fn kernels(self, table: &L3Table, entry: &IlluminantEntry) -> Result<Vec<f32>, RenderError> {
        match self {
            KernelSource::Own => Ok(table.kernels.clone()),
            KernelSource::Fused(_) => fuse_entry(table, entry),
        }
    }
}

/// The XYZ kernels `table` renders with under `entry`.
pub fn kernels_for(table: &L3Table, entry: &IlluminantEntry) -> Result<Vec<f32>, RenderError> {
    KernelSource::of(table, CorrectionMode::default()).kernels(table, entry)
}

/// What a renderer prepared for a table depends on besides the table: where the kernels come
/// from and, when it enters (fused kernels, or chroma classes balanced by its neutral), the
/// light by its lower-case name. Only [`KernelChoice::new`] makes one.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct KernelKey {
    source: KernelSource,
    light: Option<String>,
}

impl KernelKey {
    pub fn source(&self) -> KernelSource {
        self.source
    }

    /// The light the kernels depend on (lower case), `None` when they depend on none.
    pub fn light(&self) -> Option<&str> {
        self.light.as_deref()
    }
}

/// XYZ kernels with the light the chroma classes balance by.
#[derive(Debug, Clone)]
pub struct Kernels {
    pub xyz: Vec<f32>,
    /// The light's neutral (channel responses to white), when the classes balance by it.
    pub neutral: Option<Vec<f64>>,
}

/// The kernel selection for a table under a light in a correction mode, made once: its key
/// and how to build the kernels.
#[derive(Debug, Clone)]
pub struct KernelChoice<'a> {
    table: &'a L3Table,
    entry: &'a IlluminantEntry,
    fit: Fit,
    key: KernelKey,
}

impl<'a> KernelChoice<'a> {
    pub fn new(table: &'a L3Table, entry: &'a IlluminantEntry, mode: CorrectionMode) -> Self {
        let source = KernelSource::of(table, mode);
        let by_light = source != KernelSource::Own || table.chroma_balances();
        Self {
            table,
            entry,
            fit: Fit::of(table, entry, mode),
            key: KernelKey {
                source,
                light: by_light.then(|| entry.name.to_ascii_lowercase()),
            },
        }
    }

    pub fn key(&self) -> &KernelKey {
        &self.key
    }

    pub fn table(&self) -> &'a L3Table {
        self.table
    }

    /// The correction the kernels are built from ([`correction_for`]).
    pub fn correction(&self, iset: Option<&IsetData>) -> Result<IlluminantEntry, PipelineError> {
        self.fit.apply(self.table, self.entry, iset)
    }

    /// The kernels of the choice: the fitted correction ([`PipelineError::Correction`] when it
    /// cannot be fitted), then the table's own or fused kernels ([`PipelineError::Kernels`]).
    pub fn kernels(&self, iset: Option<&IsetData>) -> Result<Kernels, PipelineError> {
        let entry = self.correction(iset)?;
        Ok(Kernels {
            xyz: self
                .key
                .source
                .kernels(self.table, &entry)
                .map_err(PipelineError::Kernels)?,
            neutral: entry.neutral,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::tiny_table;

    fn entry(name: &str) -> IlluminantEntry {
        crate::l3::correct::IlluminantRegistry::with_defaults(WavelengthGrid::default(), None)
            .unwrap()
            .get(name)
            .unwrap()
            .clone()
    }

    /// The key names the light and the correction of fused kernels; for a cross-illuminant
    /// table, the light only when its chroma classes balance by it.
    #[test]
    fn the_key_follows_the_selection() {
        let si = tiny_table();
        assert!(!uses_own_kernels(si));
        let (d65, a) = (entry("D65"), entry("A"));
        fn key(t: &L3Table, e: &IlluminantEntry, m: CorrectionMode) -> KernelKey {
            KernelChoice::new(t, e, m).key().clone()
        }
        let k = key(si, &d65, CorrectionMode::Camera);
        assert_eq!(k.source(), KernelSource::Fused(CorrectionMode::Camera));
        assert_eq!(k.light(), Some("d65"));
        assert_ne!(k, key(si, &a, CorrectionMode::Camera));
        assert_ne!(k, key(si, &d65, CorrectionMode::Colorimetric));
        let mut ci = si.clone();
        ci.meta.kind = TableKind::CrossIlluminant;
        ci.meta.params.chroma = None;
        let own = key(&ci, &d65, CorrectionMode::Camera);
        assert_eq!(own.source(), KernelSource::Own);
        assert_eq!(own.light(), None);
        assert_eq!(own, key(&ci, &a, CorrectionMode::Colorimetric));
        // chroma classes balanced by the light: the renderer takes its neutral, so the key
        // names the light
        ci.meta.params.chroma = Some(crate::l3::classify::ChromaClasses {
            centroids: vec![vec![1.0; 4], vec![0.5; 4]],
            white: Some(vec![1.0; 4]),
        });
        assert!(ci.chroma_balances());
        let own = key(&ci, &d65, CorrectionMode::Camera);
        assert_eq!(own.source(), KernelSource::Own);
        assert_eq!(own.light(), Some("d65"));
        assert_ne!(own, key(&ci, &a, CorrectionMode::Camera));
        assert_eq!(own, key(&ci, &d65, CorrectionMode::Colorimetric));
    }
}
