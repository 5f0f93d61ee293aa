//! A bounded TIFF directory reader: the header, IFDs and typed tag values, with every offset
//! and count checked against the file before it is used.

use super::super::error::{IoError, IoResult};

/// Most entries an IFD may declare (a classic TIFF count is a u16; this is every value).
const MAX_ENTRIES: usize = u16::MAX as usize;

/// A classic (not Big) TIFF file: its bytes and byte order.
#[derive(Debug, Clone, Copy)]
pub(super) struct Tiff<'a> {
    bytes: &'a [u8],
    big_endian: bool,
    first_ifd: u32,
}

/// One directory entry: its tag, TIFF type and where its value bytes are.
#[derive(Debug, Clone, Copy)]
struct Entry {
    tag: u16,
    typ: u16,
    count: u32,
    /// Where the value bytes start (inline in the entry, or at the offset it holds).
    start: u64,
}

/// A parsed directory.
#[derive(Debug, Clone)]
pub(super) struct Ifd {
    entries: Vec<Entry>,
    /// Where the directory starts, for messages.
    pub offset: u32,
}

pub(super) fn dng_err(msg: impl Into<String>) -> IoError {
    IoError::Dng(msg.into())
}

/// Bytes per value of a TIFF field type, `None` for an unknown type.
fn type_size(typ: u16) -> Option<u64> {
    Some(match typ {
        1 | 2 | 6 | 7 => 1,
        3 | 8 => 2,
        4 | 9 | 11 | 13 => 4,
        5 | 10 | 12 => 8,
        _ => return None,
    })
}

/// A tag's name for messages (the tags this reader uses), else its number.
pub(super) fn tag_name(tag: u16) -> String {
    let name = match tag {
        254 => "NewSubFileType",
        256 => "ImageWidth",
        257 => "ImageLength",
        258 => "BitsPerSample",
        259 => "Compression",
        262 => "PhotometricInterpretation",
        271 => "Make",
        272 => "Model",
        273 => "StripOffsets",
        277 => "SamplesPerPixel",
        278 => "RowsPerStrip",
        279 => "StripByteCounts",
        322 => "TileWidth",
        323 => "TileLength",
        324 => "TileOffsets",
        325 => "TileByteCounts",
        330 => "SubIFDs",
        339 => "SampleFormat",
        33421 => "CFARepeatPatternDim",
        33422 => "CFAPattern",
        50706 => "DNGVersion",
        50708 => "UniqueCameraModel",
        50710 => "CFAPlaneColor",
        50711 => "CFALayout",
        50712 => "LinearizationTable",
        50713 => "BlackLevelRepeatDim",
        50714 => "BlackLevel",
        50715 => "BlackLevelDeltaH",
        50716 => "BlackLevelDeltaV",
        50717 => "WhiteLevel",
        50719 => "DefaultCropOrigin",
        50720 => "DefaultCropSize",
        50721 => "ColorMatrix1",
        50722 => "ColorMatrix2",
        50728 => "AsShotNeutral",
        50729 => "AsShotWhiteXY",
        50778 => "CalibrationIlluminant1",
        50779 => "CalibrationIlluminant2",
        50829 => "ActiveArea",
        51008 => "OpcodeList1",
        51009 => "OpcodeList2",
        51022 => "OpcodeList3",
        _ => return format!("tag {tag}"),
    };
    format!("{name} ({tag})")
}

impl<'a> Tiff<'a> {
    /// Reads the 8-byte header: byte order, magic 42 and the first IFD's offset.
    pub fn parse(bytes: &'a [u8]) -> IoResult<Self> {
        let big_endian = match bytes.get(..4) {
            Some(b"II*\0") => false,
            Some(b"MM\0*") => true,
            Some(b"II+\0") | Some(b"MM\0+") => {
                return Err(dng_err("BigTIFF is not a DNG container"));
            }
            _ => return Err(dng_err("not a TIFF file (no II*/MM* header)")),
        };
        let mut t = Tiff {
            bytes,
            big_endian,
            first_ifd: 0,
        };
        t.first_ifd = t
            .u32_at(4)
            .ok_or_else(|| dng_err("the header ends early"))?;
        Ok(t)
    }

    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    pub fn big_endian(&self) -> bool {
        self.big_endian
    }

    /// `len` bytes at `offset`, or `None` if they are not all inside the file.
    pub fn slice(&self, offset: u64, len: u64) -> Option<&'a [u8]> {
        let start = usize::try_from(offset).ok()?;
        let end = start.checked_add(usize::try_from(len).ok()?)?;
        self.bytes.get(start..end)
    }

    fn u16_at(&self, offset: u64) -> Option<u16> {
        let b = self.slice(offset, 2)?;
        let a = [*b.first()?, *b.get(1)?];
        Some(if self.big_endian {
            u16::from_be_bytes(a)
        } else {
            u16::from_le_bytes(a)
        })
    }

    fn u32_at(&self, offset: u64) -> Option<u32> {
        let b = self.slice(offset, 4)?;
        let a = [*b.first()?, *b.get(1)?, *b.get(2)?, *b.get(3)?];
        Some(if self.big_endian {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }

    /// The first IFD.
    pub fn first_ifd(&self) -> IoResult<Ifd> {
        self.ifd(self.first_ifd)
    }

    /// The IFD at `offset`: its entry count and entries must lie inside the file.
    pub fn ifd(&self, offset: u32) -> IoResult<Ifd> {
        let off = u64::from(offset);
        let n = self.u16_at(off).ok_or_else(|| {
            dng_err(format!(
                "an IFD offset ({offset}) points beyond the end of the file ({} bytes)",
                self.len()
            ))
        })?;
        let n = usize::from(n).min(MAX_ENTRIES);
        if self.slice(off + 2, n as u64 * 12).is_none() {
            return Err(dng_err(format!(
                "the IFD at offset {offset} declares {n} entries but the file ends first"
            )));
        }
        let mut entries = Vec::with_capacity(n);
        for i in 0..n as u64 {
            let e = off + 2 + 12 * i;
            let (Some(tag), Some(typ), Some(count)) =
                (self.u16_at(e), self.u16_at(e + 2), self.u32_at(e + 4))
            else {
                return Err(dng_err(format!("the IFD at offset {offset} ends early")));
            };
            let size = type_size(typ).unwrap_or(1) * u64::from(count);
            let start = if size <= 4 {
                e + 8
            } else {
                u64::from(self.u32_at(e + 8).unwrap_or(u32::MAX))
            };
            entries.push(Entry {
                tag,
                typ,
                count,
                start,
            });
        }
        Ok(Ifd { entries, offset })
    }

    /// Whether the IFD at `offset` has an entry for `tag` (no allocation; `false` when the
    /// IFD does not fit the file).
    pub fn ifd_has(&self, offset: u32, tag: u16) -> bool {
        let off = u64::from(offset);
        let Some(n) = self.u16_at(off) else {
            return false;
        };
        (0..u64::from(n)).any(|i| self.u16_at(off + 2 + 12 * i) == Some(tag))
    }

    /// The first IFD's offset.
    pub fn first_ifd_offset(&self) -> u32 {
        self.first_ifd
    }

    /// The raw value bytes of `tag` in `ifd`, with its type and count (bounds-checked). A tag
    /// written twice (PiDNG writes DNGVersion and DNGBackwardVersion itself and again when
    /// its caller sets them) is read from its first entry.
    fn value(&self, ifd: &Ifd, tag: u16) -> IoResult<Option<(u16, u32, &'a [u8])>> {
        let Some(e) = ifd.entries.iter().find(|e| e.tag == tag) else {
            return Ok(None);
        };
        let size = type_size(e.typ)
            .ok_or_else(|| dng_err(format!("{} has unknown TIFF type {}", tag_name(tag), e.typ)))?;
        let len = size * u64::from(e.count);
        let b = self.slice(e.start, len).ok_or_else(|| {
            dng_err(format!(
                "{}: its {} values ({len} bytes at offset {}) lie beyond the end of the file ({} bytes)",
                tag_name(tag),
                e.count,
                e.start,
                self.len()
            ))
        })?;
        Ok(Some((e.typ, e.count, b)))
    }

    fn read_u16(&self, b: &[u8]) -> u16 {
        let a = [
            b.first().copied().unwrap_or(0),
            b.get(1).copied().unwrap_or(0),
        ];
        if self.big_endian {
            u16::from_be_bytes(a)
        } else {
            u16::from_le_bytes(a)
        }
    }

    fn read_u32(&self, b: &[u8]) -> u32 {
        let a = [
            b.first().copied().unwrap_or(0),
            b.get(1).copied().unwrap_or(0),
            b.get(2).copied().unwrap_or(0),
            b.get(3).copied().unwrap_or(0),
        ];
        if self.big_endian {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        }
    }

    /// Unsigned integer values (BYTE, SHORT, LONG or IFD), at most `max` of them.
    /// A tag's type and bytes, refused when it holds more than `max` values.
    fn value_at_most(&self, ifd: &Ifd, tag: u16, max: usize) -> IoResult<Option<(u16, &'a [u8])>> {
        let Some((typ, count, b)) = self.value(ifd, tag)? else {
            return Ok(None);
        };
        if count as usize > max {
            return Err(dng_err(format!(
                "{} has {count} values; at most {max} are accepted",
                tag_name(tag)
            )));
        }
        Ok(Some((typ, b)))
    }

    /// The value bytes of `tag` (an UNDEFINED or BYTE tag such as an opcode list), at most
    /// `max` of them.
    pub fn bytes(&self, ifd: &Ifd, tag: u16, max: usize) -> IoResult<Option<&'a [u8]>> {
        let Some((typ, b)) = self.value_at_most(ifd, tag, max)? else {
            return Ok(None);
        };
        match typ {
            1 | 7 => Ok(Some(b)),
            other => Err(dng_err(format!(
                "{} has TIFF type {other}; BYTE or UNDEFINED is expected",
                tag_name(tag)
            ))),
        }
    }

    pub fn uints(&self, ifd: &Ifd, tag: u16, max: usize) -> IoResult<Option<Vec<u64>>> {
        let Some((typ, b)) = self.value_at_most(ifd, tag, max)? else {
            return Ok(None);
        };
        let v = match typ {
            1 | 7 => b.iter().map(|&x| u64::from(x)).collect(),
            3 => b
                .chunks_exact(2)
                .map(|c| u64::from(self.read_u16(c)))
                .collect(),
            4 | 13 => b
                .chunks_exact(4)
                .map(|c| u64::from(self.read_u32(c)))
                .collect(),
            other => {
                return Err(dng_err(format!(
                    "{} has TIFF type {other}; an unsigned integer type is expected",
                    tag_name(tag)
                )));
            }
        };
        Ok(Some(v))
    }

    /// One unsigned integer value (the first, when there are several equal ones).
    pub fn uint(&self, ifd: &Ifd, tag: u16) -> IoResult<Option<u64>> {
        match self.uints(ifd, tag, 64)? {
            None => Ok(None),
            Some(v) => match v.first() {
                None => Err(dng_err(format!("{} has no value", tag_name(tag)))),
                Some(&x) => Ok(Some(x)),
            },
        }
    }

    /// Numeric values of any numeric type as f64, at most `max` of them. Rationals with a
    /// zero denominator are an error.
    pub fn reals(&self, ifd: &Ifd, tag: u16, max: usize) -> IoResult<Option<Vec<f64>>> {
        let Some((typ, b)) = self.value_at_most(ifd, tag, max)? else {
            return Ok(None);
        };
        let ratio = |n: f64, d: f64| -> IoResult<f64> {
            if d == 0.0 {
                Err(dng_err(format!(
                    "{} holds a rational with denominator 0",
                    tag_name(tag)
                )))
            } else {
                Ok(n / d)
            }
        };
        let v: Vec<f64> = match typ {
            1 | 7 => b.iter().map(|&x| f64::from(x)).collect(),
            6 => b.iter().map(|&x| f64::from(x as i8)).collect(),
            3 => b
                .chunks_exact(2)
                .map(|c| f64::from(self.read_u16(c)))
                .collect(),
            8 => b
                .chunks_exact(2)
                .map(|c| f64::from(self.read_u16(c) as i16))
                .collect(),
            4 | 13 => b
                .chunks_exact(4)
                .map(|c| f64::from(self.read_u32(c)))
                .collect(),
            9 => b
                .chunks_exact(4)
                .map(|c| f64::from(self.read_u32(c) as i32))
                .collect(),
            5 => b
                .chunks_exact(8)
                .map(|c| {
                    let (n, d) = c.split_at(4);
                    ratio(f64::from(self.read_u32(n)), f64::from(self.read_u32(d)))
                })
                .collect::<IoResult<_>>()?,
            10 => b
                .chunks_exact(8)
                .map(|c| {
                    let (n, d) = c.split_at(4);
                    ratio(
                        f64::from(self.read_u32(n) as i32),
                        f64::from(self.read_u32(d) as i32),
                    )
                })
                .collect::<IoResult<_>>()?,
            11 => b
                .chunks_exact(4)
                .map(|c| f64::from(f32::from_bits(self.read_u32(c))))
                .collect(),
            12 => b
                .chunks_exact(8)
                .map(|c| {
                    let (hi, lo) = c.split_at(4);
                    let (hi, lo) = if self.big_endian { (hi, lo) } else { (lo, hi) };
                    f64::from_bits(
                        (u64::from(self.read_u32(hi)) << 32) | u64::from(self.read_u32(lo)),
                    )
                })
                .collect(),
            other => {
                return Err(dng_err(format!(
                    "{} has TIFF type {other}; a numeric type is expected",
                    tag_name(tag)
                )));
            }
        };
        if let Some(x) = v.iter().find(|x| !x.is_finite()) {
            return Err(dng_err(format!(
                "{} holds {x}; finite values are expected",
                tag_name(tag)
            )));
        }
        Ok(Some(v))
    }

    /// ASCII text of at most `max` bytes: leading NULs and spaces skipped, up to the next NUL
    /// (a missing terminator is no error), trimmed; invalid UTF-8 replaced.
    pub fn ascii(&self, ifd: &Ifd, tag: u16, max: usize) -> IoResult<Option<String>> {
        let Some((_, _, b)) = self.value(ifd, tag)? else {
            return Ok(None);
        };
        let b = b.get(..b.len().min(max)).unwrap_or(&[]);
        let start = b
            .iter()
            .position(|&c| c != 0 && !c.is_ascii_whitespace())
            .unwrap_or(b.len());
        let b = b.get(start..).unwrap_or(&[]);
        let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
        let s = String::from_utf8_lossy(b.get(..end).unwrap_or(&[]));
        Ok(Some(s.trim().to_string()))
    }
}

impl Ifd {
    pub fn has(&self, tag: u16) -> bool {
        self.entries.iter().any(|e| e.tag == tag)
    }

    /// How many values `tag`'s (first) entry declares, without reading them.
    pub fn count(&self, tag: u16) -> Option<u32> {
        self.entries.iter().find(|e| e.tag == tag).map(|e| e.count)
    }
}

/// A tag of the raw image that must be there, as one unsigned integer.
pub(super) fn required(t: &Tiff<'_>, ifd: &Ifd, tag: u16) -> IoResult<u64> {
    t.uint(ifd, tag)?
        .ok_or_else(|| dng_err(format!("the raw image has no {}", tag_name(tag))))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A little- or big-endian TIFF with one IFD holding `entries` (tag, type, count, value
    /// bytes in the file's order), values placed after the IFD.
    pub(crate) fn tiny_tiff(be: bool, entries: &[(u16, u16, u32, Vec<u8>)]) -> Vec<u8> {
        let mut out: Vec<u8> = if be {
            b"MM\0*\0\0\0\x08".to_vec()
        } else {
            b"II*\0\x08\0\0\0".to_vec()
        };
        let p16 = |v: u16| if be { v.to_be_bytes() } else { v.to_le_bytes() };
        let p32 = |v: u32| if be { v.to_be_bytes() } else { v.to_le_bytes() };
        let n = entries.len();
        out.extend(p16(n as u16));
        let mut data_at = 8 + 2 + 12 * n + 4;
        let mut data: Vec<u8> = Vec::new();
        for (tag, typ, count, val) in entries {
            out.extend(p16(*tag));
            out.extend(p16(*typ));
            out.extend(p32(*count));
            if val.len() <= 4 {
                let mut v = val.clone();
                v.resize(4, 0);
                out.extend(v);
            } else {
                out.extend(p32(data_at as u32));
                data.extend(val);
                data_at += val.len();
            }
        }
        out.extend([0u8; 4]);
        out.extend(data);
        out
    }

    #[test]
    fn typed_values_in_both_byte_orders() {
        for be in [false, true] {
            let s = |v: &[u16]| -> Vec<u8> {
                v.iter()
                    .flat_map(|x| if be { x.to_be_bytes() } else { x.to_le_bytes() })
                    .collect()
            };
            let l = |v: &[u32]| -> Vec<u8> {
                v.iter()
                    .flat_map(|x| if be { x.to_be_bytes() } else { x.to_le_bytes() })
                    .collect()
            };
            let t = tiny_tiff(
                be,
                &[
                    (256, 3, 1, s(&[640])),
                    (33421, 3, 2, s(&[2, 2])),
                    (33422, 1, 4, vec![0, 1, 6, 2]),
                    (50708, 2, 6, b"cam 1\0".to_vec()),
                    (50714, 5, 2, l(&[129, 2, 64, 1])),
                    (50728, 5, 1, l(&[1, 0])),
                    (50717, 4, 1, l(&[4095])),
                ],
            );
            let tiff = Tiff::parse(&t).unwrap();
            assert_eq!(tiff.big_endian(), be);
            let ifd = tiff.first_ifd().unwrap();
            assert_eq!(tiff.uint(&ifd, 256).unwrap(), Some(640));
            assert_eq!(tiff.uints(&ifd, 33421, 2).unwrap(), Some(vec![2, 2]));
            assert_eq!(tiff.uints(&ifd, 33422, 16).unwrap(), Some(vec![0, 1, 6, 2]));
            assert_eq!(
                tiff.ascii(&ifd, 50708, 64).unwrap().as_deref(),
                Some("cam 1")
            );
            assert_eq!(tiff.reals(&ifd, 50714, 4).unwrap(), Some(vec![64.5, 64.0]));
            assert_eq!(tiff.reals(&ifd, 50717, 1).unwrap(), Some(vec![4095.0]));
            assert_eq!(tiff.uint(&ifd, 999).unwrap(), None);
            let e = tiff.reals(&ifd, 50728, 4).unwrap_err().to_string();
            assert!(
                e.contains("AsShotNeutral") && e.contains("denominator 0"),
                "{e}"
            );
            let e = tiff.uints(&ifd, 33422, 2).unwrap_err().to_string();
            assert!(e.contains("CFAPattern (33422) has 4 values"), "{e}");
            let e = tiff.uints(&ifd, 50714, 4).unwrap_err().to_string();
            assert!(e.contains("unsigned integer type"), "{e}");
        }
    }

    #[test]
    fn offsets_beyond_the_file_are_errors() {
        let mut t = tiny_tiff(false, &[(50714, 4, 100, vec![0; 400])]);
        t.truncate(t.len() - 10);
        let tiff = Tiff::parse(&t).unwrap();
        let ifd = tiff.first_ifd().unwrap();
        let e = tiff.reals(&ifd, 50714, 1000).unwrap_err().to_string();
        assert!(e.contains("beyond the end of the file"), "{e}");
        // an IFD offset beyond the end, and an entry count larger than the file
        let e = tiff.ifd(1 << 30).unwrap_err().to_string();
        assert!(e.contains("beyond the end"), "{e}");
        let mut t = b"II*\0\x08\0\0\0\xff\xff".to_vec();
        t.extend([0u8; 20]);
        let e = Tiff::parse(&t)
            .unwrap()
            .first_ifd()
            .unwrap_err()
            .to_string();
        assert!(e.contains("65535 entries"), "{e}");
        assert!(Tiff::parse(b"II*").is_err());
        assert!(Tiff::parse(b"II+\0\x08\0\0\0").is_err());
    }
}
