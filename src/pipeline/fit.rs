//! Whether a frame (or a sensor design) fits a table: its CFA must be the table's (an error
//! otherwise, whichever path brings the frame), and the sensor it names should be the one the
//! table was trained for (a warning otherwise: a prototype may well be rendered with another
//! sensor's table, but its colours are then the other sensor's).

use std::fmt;

use super::error::{CfaOrigin, PipelineError};
use crate::camera::catalogue::{CameraId, match_camera};
use crate::camera::{Cfa, SensorDesign};
use crate::io::{DngInfo, RawMeta};
use crate::l3::L3Table;

/// A frame or design naming another sensor than the table's.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SensorMismatch {
    /// Who names the sensor: `the sidecar's`, `the DNG's`, `the evaluated`.
    pub origin: &'static str,
    /// The sensor (or camera) it names.
    pub named: String,
    /// The sensor the table was trained for.
    pub table: String,
}

impl fmt::Display for SensorMismatch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} sensor '{}' is not the table's sensor '{}': the colours are those of a table trained for another sensor",
            self.origin, self.named, self.table
        )
    }
}

/// The CFA `input` (from `origin`) against the table's `table`: the same pattern, however
/// spaced or cased, or [`PipelineError::CfaMismatch`]. Every path that knows a frame's CFA (a
/// DNG's, a sidecar's, a declared one, a sensor design's) checks it here.
pub fn check_cfa(input: &str, origin: CfaOrigin, table: &Cfa) -> Result<(), PipelineError> {
    let table_cfa = table.to_string();
    let same = match Cfa::parse(input) {
        Ok(cfa) => cfa.to_string().eq_ignore_ascii_case(&table_cfa),
        Err(_) => input.trim().eq_ignore_ascii_case(&table_cfa),
    };
    if same {
        return Ok(());
    }
    Err(PipelineError::CfaMismatch {
        origin,
        input: input.trim().to_string(),
        table: table_cfa,
    })
}

/// A CFA a request declares for its frame, against the table's `table`. The same pattern is
/// [`check_cfa`]'s; otherwise a string that is no CFA of the table's channels (not a
/// rectangular tile, a single channel, or a channel the table's sensor does not have) is the
/// request's mistake, [`PipelineError::Options`] naming the parameter (`cfa`), and a tile
/// of the table's channels in another arrangement is [`PipelineError::CfaMismatch`].
pub fn check_declared_cfa(input: &str, table: &Cfa) -> Result<(), PipelineError> {
    let mismatch = match check_cfa(input, CfaOrigin::Declared, table) {
        Ok(()) => return Ok(()),
        Err(e) => e,
    };
    let input = input.trim();
    let bad = |why: String| PipelineError::Options(format!("cfa '{input}': {why}"));
    let declared = Cfa::parse(input).map_err(|e| bad(e.to_string()))?;
    let theirs = &table.channel_names;
    let foreign: Vec<&str> = declared
        .channel_names
        .iter()
        .filter(|n| !theirs.iter().any(|t| t.eq_ignore_ascii_case(n)))
        .map(String::as_str)
        .collect();
    if !foreign.is_empty() {
        return Err(bad(format!(
            "{} {} of the table's sensor, whose CFA {table} has {}",
            foreign.join(", "),
            if foreign.len() == 1 {
                "is not a channel"
            } else {
                "are not channels"
            },
            theirs.join(", ")
        )));
    }
    if declared.channel_names.len() < 2 {
        return Err(bad(format!(
            "a tile of one channel is no colour filter array; the table's is {table}"
        )));
    }
    Err(mismatch)
}

/// The sensor a decoded file names, when it is not `table`'s: a sidecar's `sensor`; a DNG's
/// camera (fitting when the catalogue matches it to the table's sensor, or its model is the
/// sensor's name, as in l3's own DNGs). `None` when the file names none.
pub(crate) fn frame_sensor_mismatch(
    meta: Option<&RawMeta>,
    dng: Option<&DngInfo>,
    table: &L3Table,
) -> Option<SensorMismatch> {
    let named = meta?.sensor.as_deref()?.trim();
    let trained = table.meta.sensor_name.as_str();
    if named.is_empty() || named.eq_ignore_ascii_case(trained) {
        return None;
    }
    let origin = match dng {
        Some(d) => {
            let camera = CameraId::from(d.camera());
            let matched = match_camera(&camera).map(|m| m.sensors).unwrap_or_default();
            if matched.iter().any(|s| s.eq_ignore_ascii_case(trained)) {
                return None;
            }
            "the DNG's"
        }
        None => "the sidecar's",
    };
    Some(SensorMismatch {
        origin,
        named: named.to_string(),
        table: trained.to_string(),
    })
}

/// Whether the sensor `design` fits `table`: a CFA other than the table's is an error
/// ([`PipelineError::CfaMismatch`]), another name a [`SensorMismatch`] to warn of.
pub fn design_fit(
    design: &SensorDesign,
    table: &L3Table,
) -> Result<Option<SensorMismatch>, PipelineError> {
    check_cfa(&design.cfa.to_string(), CfaOrigin::Sensor, &table.meta.cfa)?;
    let trained = table.meta.sensor_name.as_str();
    Ok(
        (!design.name.eq_ignore_ascii_case(trained)).then(|| SensorMismatch {
            origin: "the evaluated",
            named: design.name.clone(),
            table: trained.to_string(),
        }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::tiny_table;

    #[test]
    fn a_cfa_fits_however_spaced_or_cased_and_names_its_origin_otherwise() {
        let table = Cfa::parse("RG/WB").unwrap();
        assert!(check_cfa("RG/WB", CfaOrigin::Sidecar, &table).is_ok());
        assert!(check_cfa(" rg/wb ", CfaOrigin::Declared, &table).is_ok());
        let e = check_cfa("BW/GR", CfaOrigin::Sidecar, &table).unwrap_err();
        assert_eq!(
            e.to_string(),
            "the sidecar's CFA 'BW/GR' does not match the table's CFA 'RG/WB'"
        );
        let spaced = Cfa::parse("C1 C2 / C3 C4").unwrap();
        assert!(check_cfa("C1 C2/C3 C4", CfaOrigin::Dng, &spaced).is_ok());
    }

    #[test]
    fn a_declared_cfa_that_is_no_cfa_of_the_tables_channels_is_the_requests_mistake() {
        let table = Cfa::parse("RG/WB").unwrap();
        assert!(check_declared_cfa(" rg/wb ", &table).is_ok());
        for (input, needle) in [
            ("RG/G", "cfa 'RG/G': "),
            (
                "XX/YY",
                "X, Y are not channels of the table's sensor, whose CFA RG/WB has R, G, W, B",
            ),
            ("RC/WB", "C is not a channel"),
            ("R", "a tile of one channel"),
            ("", "empty"),
        ] {
            match check_declared_cfa(input, &table) {
                Err(PipelineError::Options(m)) => assert!(m.contains(needle), "{input}: {m}"),
                other => panic!("{input}: {other:?}"),
            }
        }
        // the table's channels in another arrangement (or tile) are a mismatch
        for input in ["RG/GB", "BW/GR", "RGWB"] {
            assert!(
                matches!(
                    check_declared_cfa(input, &table),
                    Err(PipelineError::CfaMismatch {
                        origin: CfaOrigin::Declared,
                        ..
                    })
                ),
                "{input}"
            );
        }
    }

    #[test]
    fn a_sidecar_naming_another_sensor_is_a_mismatch_and_the_tables_is_not() {
        let table = tiny_table();
        let trained = table.meta.sensor_name.clone();
        let mut meta = RawMeta::new(4, 4, table.meta.cfa.to_string(), 0, 1023, 1.0);
        assert_eq!(frame_sensor_mismatch(Some(&meta), None, table), None);
        meta.sensor = Some(trained.to_uppercase());
        assert_eq!(frame_sensor_mismatch(Some(&meta), None, table), None);
        meta.sensor = Some("rgbw-other".into());
        let m = frame_sensor_mismatch(Some(&meta), None, table).unwrap();
        assert_eq!(
            (m.origin, m.named.as_str()),
            ("the sidecar's", "rgbw-other")
        );
        assert!(m.to_string().contains(&trained), "{m}");
    }

    #[test]
    fn a_design_with_another_cfa_is_refused_and_another_name_warned_of() {
        let table = tiny_table();
        let mut design = SensorDesign::paper_default();
        design.cfa = table.meta.cfa.clone();
        design.name = table.meta.sensor_name.clone();
        assert_eq!(design_fit(&design, table).unwrap(), None);
        design.name = "my-prototype".into();
        let m = design_fit(&design, table).unwrap().unwrap();
        assert_eq!(m.named, "my-prototype");
        design.cfa = Cfa::parse("GR/BG").unwrap();
        assert!(matches!(
            design_fit(&design, table),
            Err(PipelineError::CfaMismatch {
                origin: CfaOrigin::Sensor,
                ..
            })
        ));
    }
}
