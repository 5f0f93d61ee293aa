//! Raw sensor frames: integer mosaics, their JSON sidecar metadata, DN ↔ volts conversion, and
//! the headerless little-endian `.raw` format.

use std::io::Write;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::atomic::{read_capped, write_atomic, write_bytes_atomic};
use super::error::{IoError, IoResult};
use super::limits::Limits;

/// Largest JSON sidecar a reader accepts.
pub const MAX_SIDECAR_BYTES: u64 = 1 << 20;

/// Pixels per rayon work item in the DN ↔ volts conversions.
const CONVERT_CHUNK: usize = 1 << 14;

/// A raw sensor mosaic in digital numbers (DN), row-major, `width × height` values.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawFrame {
    pub width: usize,
    pub height: usize,
    pub data: Vec<u16>,
}

/// Metadata of a raw frame, stored as the JSON sidecar next to a `.raw` file.
///
/// Unknown JSON fields are kept in `extra` and written back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RawMeta {
    pub width: usize,
    pub height: usize,
    /// CFA pattern, rows separated by '/', e.g. `"RG/WB"` (top-left filter first).
    pub cfa: String,
    /// DN of zero volts.
    pub black_level: u16,
    /// DN of the voltage swing (full scale).
    pub white_level: u16,
    /// Sensor voltage swing in volts (the value `white_level` stands for).
    pub voltage_swing: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub illuminant: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exposure_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<String>,
    /// Any further fields.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

impl RawMeta {
    /// Metadata with the required fields and no optional ones.
    pub fn new(
        width: usize,
        height: usize,
        cfa: impl Into<String>,
        black_level: u16,
        white_level: u16,
        voltage_swing: f64,
    ) -> Self {
        RawMeta {
            width,
            height,
            cfa: cfa.into(),
            black_level,
            white_level,
            voltage_swing,
            illuminant: None,
            exposure_s: None,
            seed: None,
            sensor: None,
            extra: serde_json::Map::new(),
        }
    }

    /// Checks the levels, the voltage swing, the exposure and the CFA pattern (not the size).
    pub fn validate(&self) -> IoResult<()> {
        self.check_levels()?;
        self.cfa_cells()?;
        if let Some(t) = self.exposure_s
            && !(t.is_finite() && t >= 0.0)
        {
            return Err(IoError::InvalidMeta(format!(
                "exposure_s is {t}; a finite, non-negative time in seconds is expected"
            )));
        }
        Ok(())
    }

    /// Checks what the DN ↔ volts conversion needs: black < white, 0 < swing < ∞.
    fn check_levels(&self) -> IoResult<()> {
        if self.black_level >= self.white_level {
            return Err(IoError::InvalidMeta(format!(
                "black_level {} is not below white_level {}",
                self.black_level, self.white_level
            )));
        }
        if !(self.voltage_swing.is_finite() && self.voltage_swing > 0.0) {
            return Err(IoError::InvalidMeta(format!(
                "voltage_swing is {}; a finite positive number of volts is expected",
                self.voltage_swing
            )));
        }
        Ok(())
    }

    /// The CFA's channel names row by row: `[[R, G], [W, B]]` for `"RG/WB"`, and for names of
    /// more than one character separated by spaces, as a sensor design may write them,
    /// `[[C1, C2], [C3, C4]]` for `"C1 C2 / C3 C4"`. Rows are non-empty and of equal length,
    /// names made of ASCII letters, digits or `_`.
    pub fn cfa_cells(&self) -> IoResult<Vec<Vec<&str>>> {
        let spaced = self
            .cfa
            .split('/')
            .any(|r| r.trim().contains(char::is_whitespace));
        let rows: Vec<Vec<&str>> = self
            .cfa
            .split('/')
            .map(|r| {
                if spaced {
                    r.split_whitespace().collect()
                } else {
                    let r = r.trim();
                    r.char_indices()
                        .map(|(i, c)| &r[i..i + c.len_utf8()])
                        .collect()
                }
            })
            .collect();
        let cols = rows.first().map_or(0, Vec::len);
        let name_ok = |n: &&str| n.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
        let ok = cols > 0
            && rows
                .iter()
                .all(|r| r.len() == cols && r.iter().all(name_ok));
        if !ok {
            return Err(IoError::InvalidMeta(format!(
                "cfa {:?} is not a pattern like \"RG/WB\" or \"C1 C2 / C3 C4\" (rows of equal length, separated by '/', of letters or of names separated by spaces)",
                self.cfa
            )));
        }
        Ok(rows)
    }

    /// Pretty JSON text of the sidecar.
    pub fn to_json_pretty(&self) -> IoResult<String> {
        serde_json::to_string_pretty(self).map_err(|e| IoError::Encode {
            format: "JSON sidecar",
            msg: e.to_string(),
        })
    }

    /// Parses and validates sidecar JSON text.
    pub fn from_json(text: &str) -> IoResult<Self> {
        let meta: RawMeta = serde_json::from_str(text)
            .map_err(|e| IoError::InvalidMeta(format!("not a valid sidecar JSON: {e}")))?;
        meta.validate()?;
        Ok(meta)
    }
}

impl RawFrame {
    /// A frame from row-major data; the length must be `width × height`.
    pub fn new(width: usize, height: usize, data: Vec<u16>) -> IoResult<Self> {
        check_len("data", data.len(), width, height, 1, "values")?;
        Ok(RawFrame {
            width,
            height,
            data,
        })
    }

    /// Volts of every pixel: (dn − black) / (white − black) × swing, clamped to [0, swing].
    pub fn to_volts(&self, meta: &RawMeta) -> IoResult<Vec<f32>> {
        let mut out = crate::buffers::zeroed::<f32>(self.data.len());
        self.to_volts_into(meta, &mut out)?;
        Ok(out)
    }

    /// [`to_volts`](Self::to_volts) into a caller-owned buffer of `width × height` values.
    pub fn to_volts_into(&self, meta: &RawMeta, out: &mut [f32]) -> IoResult<()> {
        meta.check_levels()?;
        check_len(
            "output buffer",
            out.len(),
            self.width,
            self.height,
            1,
            "values",
        )?;
        check_len(
            "frame data",
            self.data.len(),
            self.width,
            self.height,
            1,
            "values",
        )?;
        let black = f64::from(meta.black_level);
        let swing = meta.voltage_swing;
        let scale = swing / (f64::from(meta.white_level) - black);
        out.par_chunks_mut(CONVERT_CHUNK)
            .zip(self.data.par_chunks(CONVERT_CHUNK))
            .for_each(|(o, d)| {
                for (v, &dn) in o.iter_mut().zip(d) {
                    *v = ((f64::from(dn) - black) * scale).clamp(0.0, swing) as f32;
                }
            });
        Ok(())
    }

    /// Quantises volts to DN: round(v / swing × (white − black)) + black, with v clamped to
    /// [0, swing]. NaN or infinite volts are an error naming the pixel.
    pub fn from_volts(
        volts: &[f32],
        width: usize,
        height: usize,
        meta: &RawMeta,
    ) -> IoResult<RawFrame> {
        meta.check_levels()?;
        check_len("volts", volts.len(), width, height, 1, "values")?;
        if let Some(i) = volts.iter().position(|v| !v.is_finite()) {
            return Err(IoError::NonFinite {
                what: "volts",
                x: i % width,
                y: i / width,
                channel: String::new(),
                value: volts[i],
            });
        }
        let black = f64::from(meta.black_level);
        let range = f64::from(meta.white_level) - black;
        let swing = meta.voltage_swing;
        let scale = range / swing;
        let mut data = crate::buffers::zeroed::<u16>(volts.len());
        data.par_chunks_mut(CONVERT_CHUNK)
            .zip(volts.par_chunks(CONVERT_CHUNK))
            .for_each(|(o, v)| {
                for (dn, &v) in o.iter_mut().zip(v) {
                    let d = (f64::from(v).clamp(0.0, swing) * scale).round() + black;
                    *dn = d.clamp(black, black + range) as u16;
                }
            });
        Ok(RawFrame {
            width,
            height,
            data,
        })
    }
}

/// Checks that `actual` equals `width × height × per_pixel`.
pub(crate) fn check_len(
    what: &str,
    actual: usize,
    width: usize,
    height: usize,
    per_pixel: usize,
    unit: &'static str,
) -> IoResult<()> {
    let expected = width as u128 * height as u128 * per_pixel as u128;
    if actual as u128 != expected {
        let formula = if per_pixel == 1 {
            format!("width×height ({width}×{height})")
        } else {
            format!("width×height×{per_pixel} ({width}×{height}×{per_pixel})")
        };
        return Err(IoError::Length {
            what: what.to_string(),
            unit,
            actual,
            formula,
            expected,
        });
    }
    Ok(())
}

/// The `.raw` file and its `.json` sidecar.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawPaths {
    pub raw: PathBuf,
    pub json: PathBuf,
}

impl RawPaths {
    /// Paths for `path`: `x.raw` → (`x.raw`, `x.json`); `x.json` → (`x.raw`, `x.json`);
    /// any other path is a base name to which `.raw` and `.json` are appended.
    pub fn for_path(path: &Path) -> RawPaths {
        match path.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("raw") => RawPaths {
                raw: path.to_path_buf(),
                json: path.with_extension("json"),
            },
            Some(e) if e.eq_ignore_ascii_case("json") => RawPaths {
                raw: path.with_extension("raw"),
                json: path.to_path_buf(),
            },
            _ => {
                let mut raw = path.as_os_str().to_owned();
                raw.push(".raw");
                let mut json = path.as_os_str().to_owned();
                json.push(".json");
                RawPaths {
                    raw: raw.into(),
                    json: json.into(),
                }
            }
        }
    }
}

/// Little-endian u16 bytes of the frame (the `.raw` body).
pub fn encode_raw_u16_le(frame: &RawFrame) -> Vec<u8> {
    frame.data.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Decodes a headerless little-endian u16 mosaic of the given size. The byte count must be
/// exactly `width × height × 2`.
pub fn decode_raw_u16_le(
    bytes: &[u8],
    width: usize,
    height: usize,
    limits: &Limits,
) -> IoResult<RawFrame> {
    limits.check(width, height)?;
    check_len("body", bytes.len(), width, height, 2, "bytes")?;
    let mut data: Vec<u16> = crate::buffers::zeroed(width * height);
    for (d, c) in data.iter_mut().zip(bytes.chunks_exact(2)) {
        *d = u16::from_le_bytes([c[0], c[1]]);
    }
    Ok(RawFrame {
        width,
        height,
        data,
    })
}

/// Writes `frame` as `.raw` (little-endian u16) plus its pretty JSON sidecar, each atomically
/// (the `.raw` first). `path` is resolved with [`RawPaths::for_path`]. The metadata must match
/// the frame's size and be valid.
pub fn write_raw(path: &Path, frame: &RawFrame, meta: &RawMeta) -> IoResult<RawPaths> {
    let paths = RawPaths::for_path(path);
    write_raw_to(&paths, frame, meta)?;
    Ok(paths)
}

/// [`write_raw`] with explicit paths.
pub fn write_raw_to(paths: &RawPaths, frame: &RawFrame, meta: &RawMeta) -> IoResult<()> {
    if (meta.width, meta.height) != (frame.width, frame.height) {
        return Err(IoError::InvalidMeta(format!(
            "metadata says {}×{} but the frame is {}×{}",
            meta.width, meta.height, frame.width, frame.height
        )));
    }
    check_len(
        "frame data",
        frame.data.len(),
        frame.width,
        frame.height,
        1,
        "values",
    )?;
    meta.validate()?;
    let json = meta.to_json_pretty()?;
    write_atomic(&paths.raw, |w| {
        let mut buf = Vec::with_capacity(2 * CONVERT_CHUNK);
        for chunk in frame.data.chunks(CONVERT_CHUNK) {
            buf.clear();
            buf.extend(chunk.iter().flat_map(|v| v.to_le_bytes()));
            w.write_all(&buf)
                .map_err(|e| IoError::file("write", &paths.raw, e))?;
        }
        Ok(())
    })?;
    let mut text = json.into_bytes();
    text.push(b'\n');
    write_bytes_atomic(&paths.json, &text)
}

/// Reads and validates a JSON sidecar (at most [`MAX_SIDECAR_BYTES`]).
pub fn read_sidecar(json_path: &Path) -> IoResult<RawMeta> {
    let bytes = read_capped(json_path, MAX_SIDECAR_BYTES).map_err(|e| match e {
        IoError::Length { actual, .. } => IoError::Sidecar {
            path: json_path.to_path_buf(),
            msg: format!("has {actual} bytes; at most {MAX_SIDECAR_BYTES} are accepted"),
        },
        other => other,
    })?;
    let text = std::str::from_utf8(&bytes).map_err(|e| IoError::Sidecar {
        path: json_path.to_path_buf(),
        msg: format!("not UTF-8 text: {e}"),
    })?;
    RawMeta::from_json(text).map_err(|e| IoError::Sidecar {
        path: json_path.to_path_buf(),
        msg: e.to_string(),
    })
}

/// Reads a `.raw` file and its sidecar (paths resolved with [`RawPaths::for_path`]). The size
/// comes from the sidecar; it is checked against `limits` and the file length before reading.
pub fn read_raw(path: &Path, limits: &Limits) -> IoResult<(RawFrame, RawMeta)> {
    let paths = RawPaths::for_path(path);
    let meta = read_sidecar(&paths.json)?;
    limits
        .check(meta.width, meta.height)
        .map_err(|e| IoError::Sidecar {
            path: paths.json.clone(),
            msg: e.to_string(),
        })?;
    let expected = meta.width as u64 * meta.height as u64 * 2;
    let len = std::fs::metadata(&paths.raw)
        .map_err(|e| IoError::file("read", &paths.raw, e))?
        .len();
    if len != expected {
        return Err(IoError::Length {
            what: format!(
                "file {} (size from {})",
                paths.raw.display(),
                paths.json.display()
            ),
            unit: "bytes",
            actual: usize::try_from(len).unwrap_or(usize::MAX),
            formula: format!("width×height×2 ({}×{}×2)", meta.width, meta.height),
            expected: u128::from(expected),
        });
    }
    let bytes = read_capped(&paths.raw, expected)?;
    let frame = decode_raw_u16_le(&bytes, meta.width, meta.height, limits)?;
    Ok((frame, meta))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta(w: usize, h: usize) -> RawMeta {
        RawMeta::new(w, h, "RG/WB", 64, 4095, 1.8)
    }

    #[test]
    fn volts_follow_the_formula_and_clamp() {
        let m = meta(4, 1);
        let f = RawFrame::new(4, 1, vec![0, 64, 2079, 65535]).unwrap();
        let v = f.to_volts(&m).unwrap();
        assert_eq!(v[0], 0.0);
        assert_eq!(v[1], 0.0);
        let mid = (2079.0 - 64.0) / (4095.0 - 64.0) * 1.8;
        assert!((f64::from(v[2]) - mid).abs() < 1e-6);
        assert_eq!(v[3], 1.8f32);
    }

    #[test]
    fn dn_volts_dn_is_exact_over_the_whole_range() {
        let m = RawMeta::new(65536, 1, "RG/WB", 0, 65535, 1.8);
        let f = RawFrame::new(65536, 1, (0..=65535u16).collect()).unwrap();
        let v = f.to_volts(&m).unwrap();
        let back = RawFrame::from_volts(&v, 65536, 1, &m).unwrap();
        assert_eq!(back, f);
        let m2 = RawMeta::new(4032, 1, "RG/WB", 64, 4095, 0.7);
        let f2 = RawFrame::new(4032, 1, (64..=4095u16).collect()).unwrap();
        let back2 = RawFrame::from_volts(&f2.to_volts(&m2).unwrap(), 4032, 1, &m2).unwrap();
        assert_eq!(back2, f2);
    }

    #[test]
    fn from_volts_clamps_and_rejects_nan() {
        let m = meta(3, 1);
        let f = RawFrame::from_volts(&[-1.0, 5.0, 0.45], 3, 1, &m).unwrap();
        assert_eq!(f.data[0], 64);
        assert_eq!(f.data[1], 4095);
        assert_eq!(f.data[2], 1008 + 64); // 0.45 / 1.8 × 4031 = 1007.75
        let e = RawFrame::from_volts(&[0.0, 0.1, 0.2, f32::NAN], 2, 2, &m)
            .unwrap_err()
            .to_string();
        assert!(e.contains("(x=1, y=1)") && e.contains("NaN"), "{e}");
        let e = RawFrame::from_volts(&[0.0; 3], 2, 2, &m)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("volts has 3 values; width×height (2×2) = 4 expected"),
            "{e}"
        );
    }

    #[test]
    fn bad_levels_are_rejected() {
        let f = RawFrame::new(1, 1, vec![0]).unwrap();
        let mut m = meta(1, 1);
        m.white_level = 64;
        assert!(
            f.to_volts(&m)
                .unwrap_err()
                .to_string()
                .contains("black_level 64")
        );
        let mut m = meta(1, 1);
        m.voltage_swing = f64::NAN;
        assert!(f.to_volts(&m).is_err());
        m.voltage_swing = 0.0;
        assert!(RawFrame::from_volts(&[0.0], 1, 1, &m).is_err());
    }

    #[test]
    fn cfa_patterns() {
        let mut m = meta(1, 1);
        assert_eq!(m.cfa_cells().unwrap(), vec![vec!["R", "G"], vec!["W", "B"]]);
        m.cfa = "C1 C2 / C3 C4".into();
        assert_eq!(
            m.cfa_cells().unwrap(),
            vec![vec!["C1", "C2"], vec!["C3", "C4"]]
        );
        for bad in ["", "RG/W", "R G/WB", "/", "RG//WB", "R-/WB", "C1 C2 / C3"] {
            m.cfa = bad.into();
            assert!(m.validate().is_err(), "{bad:?} accepted");
        }
        m.cfa = "RGGB".into();
        assert!(m.validate().is_ok());
    }

    #[test]
    fn sidecar_json_keeps_extra_fields() {
        let text = r#"{"width":2,"height":3,"cfa":"RG/WB","black_level":0,"white_level":1023,
            "voltage_swing":1.8,"seed":18446744073709551615,"gain":2.5,"notes":{"a":[1,2]}}"#;
        let m = RawMeta::from_json(text).unwrap();
        assert_eq!(m.seed, Some(u64::MAX));
        assert_eq!(m.extra["gain"], serde_json::json!(2.5));
        let again = RawMeta::from_json(&m.to_json_pretty().unwrap()).unwrap();
        assert_eq!(again, m);
        let e = RawMeta::from_json(r#"{"width":2}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing field"), "{e}");
    }

    #[test]
    fn raw_paths() {
        let p = RawPaths::for_path(Path::new("/a/f.v2"));
        assert_eq!(p.raw, Path::new("/a/f.v2.raw"));
        assert_eq!(p.json, Path::new("/a/f.v2.json"));
        let p = RawPaths::for_path(Path::new("/a/f.RAW"));
        assert_eq!(p.json, Path::new("/a/f.json"));
        let p = RawPaths::for_path(Path::new("f.json"));
        assert_eq!(p.raw, Path::new("f.raw"));
    }

    #[test]
    fn decode_checks_exact_length() {
        let l = Limits::default();
        let e = decode_raw_u16_le(&[0u8; 1000], 32, 32, &l)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "body has 1000 bytes; width×height×2 (32×32×2) = 2048 expected"
        );
        let f = decode_raw_u16_le(&[1, 2, 3, 4], 2, 1, &l).unwrap();
        assert_eq!(f.data, vec![0x0201, 0x0403]);
    }
}
