//! The front of a render: the input decoded, a DNG's CFA checked against the table (a crop
//! on another phase of the table's CFA moved to it: [`CfaShift`]), the DN levels applied (the
//! request's, else the file's, else 0 and the container's largest value), and what the file
//! says about the light.

use bytes::Bytes;

use super::error::{CfaOrigin, PipelineError};
use super::fit::{SensorMismatch, check_cfa, frame_sensor_mismatch};
use crate::camera::Cfa;
use crate::io::{
    DecodedMosaic, Limits, LoadedMosaic, RawFrame, RawMeta, decode_mosaic_with_meta,
    decode_raw_u16_le,
};
use crate::l3::L3Table;
use crate::l3::correct::{FrameMetadata, IlluminantSource};
use crate::l3::render::Mosaic;
use crate::spectral::IsetData;

/// A mosaic as a request brings it.
pub enum Input {
    /// Headerless little-endian u16 of a declared size.
    RawU16 {
        bytes: Bytes,
        width: usize,
        height: usize,
    },
    /// A PNG, TIFF, DNG or PGM, told by its bytes; its size must be the declared one, if any.
    Image {
        bytes: Bytes,
        width: Option<usize>,
        height: Option<usize>,
    },
    /// A mosaic decoded already (a file with its sidecar: [`crate::io::read_mosaic`]).
    Decoded(Box<LoadedMosaic>),
}

/// DN levels a request gives over the file's.
#[derive(Debug, Clone, Copy, Default)]
pub struct Levels {
    /// DN of zero volts.
    pub black: Option<u16>,
    /// DN of the table's voltage swing.
    pub white: Option<u16>,
}

/// A decoded frame's samples.
pub enum Samples {
    /// Integer DN with their levels: the renderers scale them to volts tile by tile, so no
    /// volts copy of the frame is made (the light estimate reads the same volts from them).
    Dn {
        data: Vec<u16>,
        black: u16,
        white: u16,
    },
    /// Volts (float input).
    Volts(Vec<f32>),
}

/// A decoded frame with what its file says about the light.
pub struct DecodedFrame {
    pub samples: Samples,
    pub width: usize,
    pub height: usize,
    /// A sidecar's `illuminant`, or a DNG's AsShotWhiteXY as `xy:x,y` (when the DNG has no
    /// AsShotNeutral).
    pub illuminant: Option<String>,
    /// A DNG's AsShotNeutral per channel.
    pub neutral: Option<Vec<(String, f64)>>,
    /// What was done to a DNG, or left undone, that its answer reports.
    pub notes: FrameNotes,
}

/// What a render of a DNG reports besides its light: opcodes left unapplied, and a frame
/// moved to the table's CFA phase.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FrameNotes {
    /// The DNG opcodes the reader did not apply ([`crate::io::DngInfo::skipped_opcodes`]).
    pub skipped_opcodes: Vec<String>,
    /// The crop moved so that the DNG's CFA is the table's.
    pub cfa_shift: Option<CfaShift>,
    /// The sensor the file names (a sidecar's `sensor`, a DNG's camera) when it is not the
    /// table's: worth a warning, not an error.
    pub sensor_mismatch: Option<SensorMismatch>,
}

/// A DNG whose crop starts on another CFA phase than the table's (an odd row or column of
/// an RG/GB sensor reads as GB/RG, GR/BG or BG/GR): its first `rows` rows and `cols` columns
/// are left out, so that the frame starts on the table's phase.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CfaShift {
    /// The CFA as the DNG's crop has it, e.g. `"BG/GR"`.
    pub from: String,
    pub rows: usize,
    pub cols: usize,
}

impl CfaShift {
    /// The shift as a sentence, for warnings.
    pub fn describe(&self) -> String {
        format!(
            "the DNG's crop starts on CFA {}: its first {} left out so that the frame starts on the table's CFA",
            self.from,
            self.left_out()
        )
    }

    /// What is left out: "1 row", "2 columns", "1 row and 1 column".
    fn left_out(&self) -> String {
        let plural = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
        let mut parts = Vec::new();
        if self.rows > 0 {
            parts.push(plural(self.rows, "row"));
        }
        if self.cols > 0 {
            parts.push(plural(self.cols, "column"));
        }
        parts.join(" and ")
    }
}

/// The CFA `cfa` ("RG/GB") seen from pixel (`x`, `y`) of its pattern, `None` when it is not
/// a rectangle of rows.
fn cfa_seen_from(cfa: &str, x: usize, y: usize) -> Option<String> {
    let rows: Vec<Vec<char>> = cfa.trim().split('/').map(|r| r.chars().collect()).collect();
    let cols = rows.first()?.len();
    if cols == 0 || rows.iter().any(|r| r.len() != cols) {
        return None;
    }
    let n = rows.len();
    let seen: Vec<String> = (0..n)
        .map(|r| {
            (0..cols)
                .filter_map(|c| rows.get((r + y) % n)?.get((c + x) % cols).copied())
                .collect()
        })
        .collect();
    Some(seen.join("/"))
}

/// The rows and columns to leave out of a frame whose CFA is `input` so that it starts on
/// `table`'s, fewest first; `None` when no shift of `input` is `table`.
pub fn cfa_phase(input: &str, table: &str) -> Option<(usize, usize)> {
    let rows = input.split('/').count();
    let cols = input.split('/').next().map_or(0, |r| r.chars().count());
    let mut shifts: Vec<(usize, usize)> = (0..rows)
        .flat_map(|r| (0..cols).map(move |c| (r, c)))
        .collect();
    shifts.sort_by_key(|&(r, c)| (r + c, r));
    shifts.into_iter().find(|&(r, c)| {
        cfa_seen_from(input, c, r).is_some_and(|s| s.eq_ignore_ascii_case(table.trim()))
    })
}

/// A DNG's CFA checked against the table's ([`check_cfa`]): equal, a shift of it (to be
/// applied by [`shift_frame`]), else [`PipelineError::CfaMismatch`].
fn check_dng_cfa(cfa: &str, table_cfa: &Cfa) -> Result<Option<CfaShift>, PipelineError> {
    let Err(mismatch) = check_cfa(cfa, CfaOrigin::Dng, table_cfa) else {
        return Ok(None);
    };
    match cfa_phase(cfa.trim(), &table_cfa.to_string()) {
        Some((rows, cols)) => Ok(Some(CfaShift {
            from: cfa.trim().to_string(),
            rows,
            cols,
        })),
        None => Err(mismatch),
    }
}

/// `frame` without its first `shift.rows` rows and `shift.cols` columns.
fn shift_frame(frame: RawFrame, shift: &CfaShift, table: &Cfa) -> Result<RawFrame, PipelineError> {
    let (w, h) = (frame.width, frame.height);
    let (nw, nh) = (w.saturating_sub(shift.cols), h.saturating_sub(shift.rows));
    if nw == 0 || nh == 0 {
        return Err(PipelineError::CfaShiftTooSmall {
            input: shift.from.clone(),
            table: table.to_string(),
            size: (w, h),
            left_out: shift.left_out(),
        });
    }
    let data = frame
        .data
        .chunks_exact(w)
        .skip(shift.rows)
        .flat_map(|row| row.get(shift.cols..).unwrap_or(&[]).iter().copied())
        .collect();
    Ok(RawFrame {
        width: nw,
        height: nh,
        data,
    })
}

impl DecodedFrame {
    /// The frame as the renderers take it.
    pub fn mosaic(&self) -> Mosaic<'_> {
        match &self.samples {
            Samples::Dn { data, black, white } => Mosaic::Dn {
                data,
                black: *black,
                white: *white,
            },
            Samples::Volts(v) => Mosaic::Volts(v),
        }
    }

    /// The frame in volts, DN scaled by their levels to `swing`.
    pub fn into_volts(self, swing: f64) -> Result<Vec<f32>, PipelineError> {
        match self.samples {
            Samples::Volts(v) => Ok(v),
            Samples::Dn { data, black, white } => {
                let frame = RawFrame {
                    width: self.width,
                    height: self.height,
                    data,
                };
                to_volts(&frame, black, white, swing)
            }
        }
    }

    /// The light of the frame, from its metadata or its pixels, and where it came from
    /// ([`L3Table::frame_illuminant`]).
    pub fn light(
        &self,
        table: &L3Table,
        iset: Option<&IsetData>,
    ) -> Result<(String, IlluminantSource), PipelineError> {
        let metadata = FrameMetadata {
            illuminant: self.illuminant.as_deref(),
            neutral: self.neutral.as_deref(),
        };
        table
            .frame_illuminant(metadata, &self.mosaic(), self.width, self.height, iset)
            .map_err(PipelineError::FrameLight)
    }
}

fn to_volts(
    frame: &RawFrame,
    black: u16,
    white: u16,
    swing: f64,
) -> Result<Vec<f32>, PipelineError> {
    let meta = RawMeta::new(frame.width, frame.height, "", black, white, swing);
    frame.to_volts(&meta).map_err(PipelineError::Decode)
}

fn check_levels(black: u16, white: u16) -> Result<(), PipelineError> {
    if white <= black {
        return Err(PipelineError::Levels { black, white });
    }
    Ok(())
}

/// Decodes `input` for `table`: its levels (`levels` over the file's, else 0 and the largest
/// value the container holds, 65535 for raw u16) checked before and after decoding, a DNG's or a sidecar's CFA checked against the table's, the declared
/// size against the decoded one. Integer samples stay integers ([`Samples::Dn`]).
pub fn decode(
    input: Input,
    levels: Levels,
    table: &L3Table,
    limits: &Limits,
) -> Result<DecodedFrame, PipelineError> {
    let (mut black, mut white) = (levels.black.unwrap_or(0), levels.white.unwrap_or(65535));
    if white <= black {
        return Err(PipelineError::GivenLevels { black, white });
    }
    let (mosaic, meta, dng, container_white, declared) = match input {
        Input::RawU16 {
            bytes,
            width,
            height,
        } => {
            let frame =
                decode_raw_u16_le(&bytes, width, height, limits).map_err(PipelineError::Decode)?;
            (DecodedMosaic::U16(frame), None, None, None, (None, None))
        }
        Input::Image {
            bytes,
            width,
            height,
        } => {
            let l = decode_mosaic_with_meta(&bytes, limits).map_err(PipelineError::Decode)?;
            let container_white = l.info.max_value;
            (l.mosaic, l.meta, l.dng, container_white, (width, height))
        }
        Input::Decoded(l) => {
            let LoadedMosaic {
                mosaic,
                meta,
                dng,
                info,
            } = *l;
            (mosaic, meta, dng, info.max_value, (None, None))
        }
    };
    let cfa_shift = match (&meta, &dng) {
        (Some(meta), Some(_)) => check_dng_cfa(&meta.cfa, &table.meta.cfa)?,
        (Some(meta), None) => {
            check_cfa(&meta.cfa, CfaOrigin::Sidecar, &table.meta.cfa)?;
            None
        }
        _ => None,
    };
    let sensor_mismatch = frame_sensor_mismatch(meta.as_ref(), dng.as_ref(), table);
    // the file's levels (a sidecar's or a DNG's) unless the request gives others; without
    // them, white is the largest value the container holds (255 in an 8-bit PNG or TIFF, a
    // PGM's maxval), else 65535
    if let Some(meta) = &meta {
        black = levels.black.unwrap_or(meta.black_level);
        white = levels.white.unwrap_or(meta.white_level);
    } else if let (None, Some(max)) = (levels.white, container_white) {
        white = max;
    }
    let neutral = dng.as_ref().and_then(|d| d.neutral());
    // a sidecar's illuminant; a DNG's AsShotWhiteXY when it has no AsShotNeutral
    let illuminant = match &dng {
        None => meta.and_then(|m| m.illuminant),
        Some(d) => d.white_xy_light(),
    };
    let (width, height) = mosaic.dims();
    if declared.0.is_some_and(|w| w != width) || declared.1.is_some_and(|h| h != height) {
        return Err(PipelineError::SizeMismatch {
            image: (width, height),
            declared,
        });
    }
    let mosaic = match (mosaic, &cfa_shift) {
        (DecodedMosaic::U16(frame), Some(shift)) => {
            DecodedMosaic::U16(shift_frame(frame, shift, &table.meta.cfa)?)
        }
        (mosaic, _) => mosaic,
    };
    let (width, height) = mosaic.dims();
    let notes = FrameNotes {
        skipped_opcodes: dng.map(|d| d.skipped_opcodes).unwrap_or_default(),
        cfa_shift,
        sensor_mismatch,
    };
    check_levels(black, white)?;
    let samples = match mosaic {
        DecodedMosaic::U16(frame) => Samples::Dn {
            data: frame.data,
            black,
            white,
        },
        DecodedMosaic::F32 { data, .. } => Samples::Volts(data),
    };
    Ok(DecodedFrame {
        samples,
        width,
        height,
        illuminant,
        neutral,
        notes,
    })
}

#[cfg(test)]
mod tests;
