//! The front of a render: the input decoded, a DNG's CFA checked against the table, the DN
//! levels (the request's, else the file's, else 0 and 65535) applied, and what the file says
//! about the light.

use bytes::Bytes;

use super::error::{CfaOrigin, PipelineError};
use super::fit::{SensorMismatch, check_cfa, frame_sensor_mismatch};
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

/// How integer samples become volts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Scaling {
    /// Inside the renderer, tile by tile: no volts copy of the frame (the service). The light
    /// estimate then reads the DN.
    #[default]
    InRenderer,
    /// The whole frame before anything else (`l3 render`, `l3 eval --frame`): the light
    /// estimate reads the clamped volts.
    Upfront,
}

/// A decoded frame's samples.
pub enum Samples {
    /// Integer DN with their levels.
    Dn {
        data: Vec<u16>,
        black: u16,
        white: u16,
    },
    /// Volts (float input, or DN scaled up front).
    Volts(Vec<f32>),
}

/// A decoded frame with what its file says about the light.
pub struct DecodedFrame {
    pub samples: Samples,
    pub width: usize,
    pub height: usize,
    /// A sidecar's `illuminant` (never a DNG's).
    pub illuminant: Option<String>,
    /// A DNG's AsShotNeutral per channel.
    pub neutral: Option<Vec<(String, f64)>>,
    /// The sensor the file names (a sidecar's `sensor`, a DNG's camera) when it is not the
    /// table's: worth a warning, not an error.
    pub sensor_mismatch: Option<SensorMismatch>,
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

/// Decodes `input` for `table`: its levels (`levels` over the file's, else 0 and 65535)
/// checked before and after decoding, a DNG's or a sidecar's CFA checked against the table's, the declared
/// size against the decoded one; integer samples scaled to volts as `scaling` says.
pub fn decode(
    input: Input,
    levels: Levels,
    table: &L3Table,
    scaling: Scaling,
    limits: &Limits,
) -> Result<DecodedFrame, PipelineError> {
    let (mut black, mut white) = (levels.black.unwrap_or(0), levels.white.unwrap_or(65535));
    check_levels(black, white)?;
    let (mosaic, meta, dng, declared) = match input {
        Input::RawU16 {
            bytes,
            width,
            height,
        } => {
            let frame =
                decode_raw_u16_le(&bytes, width, height, limits).map_err(PipelineError::Decode)?;
            (DecodedMosaic::U16(frame), None, None, (None, None))
        }
        Input::Image {
            bytes,
            width,
            height,
        } => {
            let l = decode_mosaic_with_meta(&bytes, limits).map_err(PipelineError::Decode)?;
            (l.mosaic, l.meta, l.dng, (width, height))
        }
        Input::Decoded(l) => {
            let LoadedMosaic {
                mosaic, meta, dng, ..
            } = *l;
            (mosaic, meta, dng, (None, None))
        }
    };
    if let Some(meta) = &meta {
        let origin = match dng {
            Some(_) => CfaOrigin::Dng,
            None => CfaOrigin::Sidecar,
        };
        check_cfa(&meta.cfa, origin, &table.meta.cfa)?;
    }
    let sensor_mismatch = frame_sensor_mismatch(meta.as_ref(), dng.as_ref(), table);
    // the file's levels (a sidecar's or a DNG's) unless the request gives others
    if let Some(meta) = &meta {
        black = levels.black.unwrap_or(meta.black_level);
        white = levels.white.unwrap_or(meta.white_level);
    }
    let neutral = dng.as_ref().and_then(|d| d.neutral());
    let illuminant = match &dng {
        None => meta.and_then(|m| m.illuminant),
        Some(_) => None,
    };
    let (width, height) = mosaic.dims();
    if declared.0.is_some_and(|w| w != width) || declared.1.is_some_and(|h| h != height) {
        return Err(PipelineError::SizeMismatch {
            image: (width, height),
            declared,
        });
    }
    check_levels(black, white)?;
    let samples = match mosaic {
        DecodedMosaic::U16(frame) if scaling == Scaling::Upfront => {
            Samples::Volts(to_volts(&frame, black, white, table.meta.voltage_swing)?)
        }
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
        sensor_mismatch,
    })
}
