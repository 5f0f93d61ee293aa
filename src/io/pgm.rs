//! PGM (Netpbm grayscale): binary P5 (8-bit, or 16-bit big-endian when maxval > 255) and plain
//! P2, decoding only.

use super::error::{IoError, IoResult};
use super::limits::Limits;
use super::raw::RawFrame;

/// A decoded PGM: the frame and its maxval.
pub(crate) struct Pgm {
    pub frame: RawFrame,
    pub maxval: u16,
}

fn err(msg: impl Into<String>) -> IoError {
    IoError::Pgm(msg.into())
}

/// Netpbm whitespace.
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\n' | b'\r' | 0x0b | 0x0c)
}

/// A cursor over the bytes of a PGM stream.
struct Scanner<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Scanner<'_> {
    /// Skips whitespace and `#` comments (to the end of the line).
    fn skip_space_and_comments(&mut self) {
        while let Some(&b) = self.bytes.get(self.pos) {
            if is_space(b) {
                self.pos += 1;
            } else if b == b'#' {
                while let Some(&c) = self.bytes.get(self.pos) {
                    if c == b'\n' || c == b'\r' {
                        break;
                    }
                    self.pos += 1;
                }
            } else {
                break;
            }
        }
    }

    /// Reads a decimal number (after whitespace/comments) that must not exceed `max`.
    fn number(&mut self, name: &str, max: u64) -> IoResult<u64> {
        self.skip_space_and_comments();
        let start = self.pos;
        let mut value: u64 = 0;
        while let Some(&b) = self.bytes.get(self.pos) {
            if !b.is_ascii_digit() {
                break;
            }
            value = value.saturating_mul(10).saturating_add(u64::from(b - b'0'));
            self.pos += 1;
        }
        if self.pos == start {
            return Err(match self.bytes.get(self.pos) {
                None => err(format!("the data ends before the {name}")),
                Some(&b) => err(format!(
                    "expected the {name} (a decimal number) at byte {}, found {:?}",
                    self.pos,
                    char::from(b)
                )),
            });
        }
        if value > max {
            let digits = String::from_utf8_lossy(&self.bytes[start..self.pos.min(start + 24)]);
            return Err(err(format!("{name} {digits} exceeds {max}")));
        }
        Ok(value)
    }
}

/// Decodes a P5 or P2 PGM. Sample values above maxval are an error; values are kept as they
/// are (not rescaled). Trailing data after the raster is an error (multi-image streams are not
/// supported).
pub(crate) fn decode_pgm(bytes: &[u8], limits: &Limits) -> IoResult<Pgm> {
    let plain = match bytes.get(..2) {
        Some(b"P5") => false,
        Some(b"P2") => true,
        Some([b'P', k @ b'1'..=b'7']) => {
            let found = match k {
                b'1' | b'4' => "a bitmap (PBM)",
                b'3' | b'6' => "a colour pixmap (PPM)",
                _ => "a PAM file",
            };
            return Err(IoError::PixelLayout {
                format: "Netpbm file",
                found: format!("{found}, magic P{}", char::from(*k)),
                expected: "a grayscale PGM (P5 or P2)",
            });
        }
        _ => return Err(err("missing the P5 or P2 magic number")),
    };
    let mut s = Scanner { bytes, pos: 2 };
    if !s.bytes.get(2).is_some_and(|&b| is_space(b) || b == b'#') {
        return Err(err("the magic number must be followed by whitespace"));
    }
    let dim_max = limits.max_dim as u64;
    let width = s.number("width", dim_max)?;
    let height = s.number("height", dim_max)?;
    let maxval = s.number("maxval", 65535)?;
    let width = usize::try_from(width).unwrap_or(usize::MAX);
    let height = usize::try_from(height).unwrap_or(usize::MAX);
    let n = limits.check(width, height)?;
    if maxval == 0 {
        return Err(err("maxval is 0; it must be between 1 and 65535"));
    }
    let maxval = maxval as u16;
    // Exactly one whitespace byte separates the header from the raster.
    match s.bytes.get(s.pos) {
        Some(&b) if is_space(b) => s.pos += 1,
        Some(&b) => {
            return Err(err(format!(
                "expected whitespace after maxval at byte {}, found {:?}",
                s.pos,
                char::from(b)
            )));
        }
        None => return Err(err("the data ends before the raster")),
    }
    let data = if plain {
        decode_plain(&mut s, width, n, maxval)?
    } else {
        decode_binary(&s.bytes[s.pos..], width, height, n, maxval)?
    };
    Ok(Pgm {
        frame: RawFrame {
            width,
            height,
            data,
        },
        maxval,
    })
}

fn decode_binary(
    raster: &[u8],
    width: usize,
    height: usize,
    n: usize,
    maxval: u16,
) -> IoResult<Vec<u16>> {
    let bps = if maxval > 255 { 2 } else { 1 };
    let expected = n as u128 * bps as u128;
    if raster.len() as u128 != expected {
        let tail = if (raster.len() as u128) > expected {
            " (multi-image PGM streams are not supported)"
        } else {
            " (truncated file)"
        };
        return Err(err(format!(
            "raster has {} bytes; width×height×{bps} ({width}×{height}×{bps}) = {expected} expected \
             for maxval {maxval}{tail}",
            raster.len()
        )));
    }
    let data: Vec<u16> = if bps == 2 {
        raster
            .chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect()
    } else {
        raster.iter().map(|&b| u16::from(b)).collect()
    };
    if let Some(i) = data.iter().position(|&v| v > maxval) {
        return Err(err(format!(
            "pixel (x={}, y={}) is {}, above maxval {maxval}",
            i % width,
            i / width,
            data[i]
        )));
    }
    Ok(data)
}

fn decode_plain(s: &mut Scanner<'_>, width: usize, n: usize, maxval: u16) -> IoResult<Vec<u16>> {
    // Every sample takes at least one digit and one separator: refuse before allocating when
    // the remaining bytes cannot hold `n` samples.
    let remaining = s.bytes.len() - s.pos;
    if (remaining as u128 + 1) < 2 * n as u128 {
        return Err(err(format!(
            "plain raster has {remaining} bytes, too few for width×height = {n} samples (truncated file)"
        )));
    }
    let mut data = Vec::with_capacity(n);
    for i in 0..n {
        let v = s.number("sample", u64::from(maxval)).map_err(|e| match e {
            IoError::Pgm(m) => err(format!("pixel (x={}, y={}): {m}", i % width, i / width)),
            other => other,
        })?;
        data.push(v as u16);
        // Samples must be separated.
        if i + 1 < n
            && !s
                .bytes
                .get(s.pos)
                .is_some_and(|&b| is_space(b) || b == b'#')
        {
            return Err(err(format!(
                "pixel (x={}, y={}) is not followed by whitespace",
                i % width,
                i / width
            )));
        }
    }
    s.skip_space_and_comments();
    if s.pos != s.bytes.len() {
        return Err(err(format!(
            "{} bytes of extra data after {n} samples (multi-image PGM streams are not supported)",
            s.bytes.len() - s.pos
        )));
    }
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn l() -> Limits {
        Limits::default()
    }

    #[test]
    fn p5_8_and_16_bit() {
        let mut b = b"P5\n# comment\n3 1\n255\n".to_vec();
        b.extend([0, 128, 255]);
        let p = decode_pgm(&b, &l()).unwrap();
        assert_eq!(p.frame.data, vec![0, 128, 255]);
        assert_eq!(p.maxval, 255);
        let mut b = b"P5 2 1 4095 ".to_vec();
        b.extend([0x0f, 0xff, 0x01, 0x02]);
        let p = decode_pgm(&b, &l()).unwrap();
        assert_eq!(p.frame.data, vec![4095, 0x0102]);
    }

    #[test]
    fn p2_plain() {
        let p = decode_pgm(b"P2\n2 2\n# c\n1023\n0 1\n1023 #x\n 7\n", &l()).unwrap();
        assert_eq!(p.frame.data, vec![0, 1, 1023, 7]);
        let e = decode_pgm(b"P2 2 1 10 3 11", &l())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("pixel (x=1, y=0): sample 11 exceeds 10"), "{e}");
        let e = decode_pgm(b"P2 2 1 10 3 4 5", &l())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("extra data"), "{e}");
    }

    #[test]
    fn header_errors() {
        let cases: [(&[u8], &str); 7] = [
            (b"P6 1 1 255 abc", "colour pixmap (PPM)"),
            (b"P5 1 1 0 a", "maxval is 0"),
            (b"P5 1 1 65536 ab", "maxval 65536 exceeds 65535"),
            (b"P5 0 1 255 ", "0×1"),
            (b"P5 1", "ends before the height"),
            (b"P5 x", "expected the width"),
            (
                b"P5\n2 1 255\n\x01",
                "raster has 1 bytes; width×height×1 (2×1×1) = 2 expected",
            ),
        ];
        for (b, want) in cases {
            let e = decode_pgm(b, &l()).err().unwrap().to_string();
            assert!(e.contains(want), "{e:?} lacks {want:?}");
        }
        let e = decode_pgm(b"P5 2 1 200 \x01\xff", &l())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("pixel (x=1, y=0) is 255, above maxval 200"),
            "{e}"
        );
    }

    #[test]
    fn huge_dimensions_fail_before_allocating() {
        let e = decode_pgm(b"P5 99999999999999999999999 99999 255 ", &l())
            .err()
            .unwrap()
            .to_string();
        assert!(
            e.contains("width 99999999999999999999999 exceeds 30000"),
            "{e}"
        );
        let e = decode_pgm(b"P2 20000 20000 255 1 2 3", &l())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("at most 150000000 pixels"), "{e}");
        let e = decode_pgm(b"P2 5000 5000 255 1 2 3", &l())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("too few"), "{e}");
    }
}
