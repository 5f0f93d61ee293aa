//! Which table renders a request, for the service and `l3 render` alike: the one the request
//! names; else, when its DNG names a camera of the sensor catalogue
//! ([`crate::camera::catalogue::match_camera`]), the newest good table trained for that
//! camera's sensor (its sensors in match order); else the default (the active table).
//!
//! A camera the catalogue knows but no stored table was trained for is an error
//! ([`PipelineError::UntrainedCamera`]) rather than a silent render with a table made for
//! another sensor. The stored tables come in as a [`StoredTables`] index, which the caller
//! builds from its store; nothing here reads a database.

use super::error::PipelineError;
use super::input::Input;
use crate::camera::catalogue::{CameraId, CameraMatch, match_camera};
use crate::io::{DngCamera, is_dng, read_camera};

/// Why a table renders a request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TableChoice {
    /// The default table (the service's active one).
    Active,
    /// The request named it (`?table=`, `--table-id`).
    Named(String),
    /// The newest good table trained for the catalogue sensor of the file's camera.
    Camera {
        table: String,
        sensor: &'static str,
        camera: CameraMatch,
    },
}

impl TableChoice {
    /// `active`, `query` or `camera` (the service's `x-l3-table-choice`).
    pub fn as_str(&self) -> &'static str {
        match self {
            TableChoice::Active => "active",
            TableChoice::Named(_) => "query",
            TableChoice::Camera { .. } => "camera",
        }
    }

    /// The chosen table's id; `None` for the default table.
    pub fn table_id(&self) -> Option<&str> {
        match self {
            TableChoice::Active => None,
            TableChoice::Named(id) | TableChoice::Camera { table: id, .. } => Some(id),
        }
    }

    /// The catalogue sensor a camera choice matched.
    pub fn sensor(&self) -> Option<&'static str> {
        match self {
            TableChoice::Camera { sensor, .. } => Some(sensor),
            _ => None,
        }
    }
}

/// The good (checksum-verified, status ok) stored tables by the catalogue sensor they were
/// trained for, newest first.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct StoredTables {
    /// (sensor name, table id), newest table first.
    by_sensor: Vec<(String, String)>,
}

impl StoredTables {
    /// From (sensor name, table id) pairs, newest table first.
    pub fn newest_first(pairs: impl IntoIterator<Item = (String, String)>) -> Self {
        StoredTables {
            by_sensor: pairs.into_iter().collect(),
        }
    }

    /// The newest good table trained for `sensor` (names compare case-insensitively).
    pub fn newest_for(&self, sensor: &str) -> Option<&str> {
        self.by_sensor
            .iter()
            .find(|(s, _)| s.eq_ignore_ascii_case(sensor))
            .map(|(_, id)| id.as_str())
    }
}

impl From<DngCamera> for CameraId {
    fn from(c: DngCamera) -> Self {
        CameraId {
            unique_model: c.unique_camera_model,
            make: c.make,
            model: c.model,
        }
    }
}

impl Input {
    /// What the input says of its camera: a DNG's UniqueCameraModel, Make and Model, read
    /// from its tags alone (no pixel is decoded here; the decode reads the same tags again,
    /// which costs a few hundred bytes of parsing). `None` for other inputs, for a DNG that
    /// names no camera, and for a DNG whose tags do not parse (its decoding says why).
    pub fn camera(&self) -> Option<CameraId> {
        let cam = match self {
            Input::RawU16 { .. } => return None,
            Input::Image { bytes, .. } if is_dng(bytes) => read_camera(bytes).ok()?,
            Input::Image { .. } => return None,
            Input::Decoded(l) => l.dng.as_ref()?.camera(),
        };
        let id = CameraId::from(cam);
        (!id.is_empty()).then_some(id)
    }
}

/// The table for a request that names `named` (if any) and whose file names `camera` (if
/// any), among `stored`: see the module's documentation.
pub fn choose_table(
    named: Option<&str>,
    camera: Option<&CameraId>,
    stored: &StoredTables,
) -> Result<TableChoice, PipelineError> {
    if let Some(id) = named {
        return Ok(TableChoice::Named(id.trim().to_string()));
    }
    let Some(m) = camera.and_then(match_camera) else {
        return Ok(TableChoice::Active);
    };
    for &sensor in &m.sensors {
        if let Some(table) = stored.newest_for(sensor) {
            return Ok(TableChoice::Camera {
                table: table.to_string(),
                sensor,
                camera: m,
            });
        }
    }
    Err(PipelineError::UntrainedCamera {
        camera: format!("{} {}", m.make, m.model),
        sensors: m.sensors.iter().map(|s| s.to_string()).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sony() -> CameraId {
        CameraId {
            unique_model: Some("Sony ILCE-9".into()),
            ..CameraId::default()
        }
    }

    #[test]
    fn the_named_table_then_the_cameras_newest_then_the_active_one() {
        let stored = StoredTables::newest_first([
            ("rgbw-paper".to_string(), "tbl_c".to_string()),
            ("bayer-sony-ilce-9".to_string(), "tbl_b".to_string()),
            ("bayer-sony-ilce-9".to_string(), "tbl_a".to_string()),
        ]);
        let c = choose_table(Some("tbl_x"), Some(&sony()), &stored).unwrap();
        assert_eq!((c.as_str(), c.table_id()), ("query", Some("tbl_x")));
        let c = choose_table(None, Some(&sony()), &stored).unwrap();
        assert_eq!((c.as_str(), c.table_id()), ("camera", Some("tbl_b")));
        assert_eq!(c.sensor(), Some("bayer-sony-ilce-9"));
        let c = choose_table(None, None, &stored).unwrap();
        assert_eq!((c.as_str(), c.table_id()), ("active", None));
        let nokia = CameraId {
            make: Some("Nokia".into()),
            model: Some("N900".into()),
            ..CameraId::default()
        };
        assert_eq!(
            choose_table(None, Some(&nokia), &stored).unwrap(),
            TableChoice::Active
        );
    }

    #[test]
    fn a_known_camera_without_a_table_is_an_error_naming_its_sensor() {
        let e = choose_table(None, Some(&sony()), &StoredTables::default()).unwrap_err();
        match &e {
            PipelineError::UntrainedCamera { camera, sensors } => {
                assert_eq!(camera, "Sony ILCE-9");
                assert_eq!(sensors, &["bayer-sony-ilce-9"]);
            }
            e => panic!("{e:?}"),
        }
        // a shipped design and its catalogue twin: the first with a table wins
        let nikon = CameraId {
            make: Some("NIKON CORPORATION".into()),
            model: Some("NIKON D5100".into()),
            ..CameraId::default()
        };
        let stored = StoredTables::newest_first([(
            "bayer-nikon-d5100-rawtoaces".to_string(),
            "tbl_n".to_string(),
        )]);
        let c = choose_table(None, Some(&nikon), &stored).unwrap();
        assert_eq!(c.sensor(), Some("bayer-nikon-d5100-rawtoaces"));
    }
}
