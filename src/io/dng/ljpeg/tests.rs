//! The decoder on streams a minimal encoder here builds: round trips, long codes, hostile data.

use super::*;

/// SSSS codes of fixed length 5: 17 codes of 5 bits.
const FIVE_BITS: [u8; 16] = [0, 0, 0, 0, 17, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0];

/// Codes of every length from 2 to 16 bits: SSSS 0 and 1 take 2 bits, 2 takes 3, …, 15
/// and 16 take 16 bits, so large differences need the decoder's longest codes.
const ALL_LENGTHS: [u8; 16] = [0, 2, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 2];

/// A minimal lossless JPEG encoder (predictor 1 or 6, one table for every component,
/// SSSS codes of fixed length 5), to test the decoder on streams built here: `shape` is
/// (width, height, components).
pub(crate) fn encode(
    samples: &[u16],
    shape: (usize, usize, usize),
    precision: u8,
    predictor: u8,
    restart_rows: usize,
) -> Vec<u8> {
    encode_with(
        FIVE_BITS,
        samples,
        shape,
        precision,
        (predictor, restart_rows),
    )
}

/// [`encode`] with SSSS codes of the lengths `counts` gives (the DHT's 16 counts for the
/// symbols 0–16 in order).
fn encode_with(
    counts: [u8; 16],
    samples: &[u16],
    (width, height, nc): (usize, usize, usize),
    precision: u8,
    (predictor, restart_rows): (u8, usize),
) -> Vec<u8> {
    let s = Stream {
        samples,
        width,
        height,
        nc,
        precision,
        predictor,
        restart_rows,
        counts,
        codes: canonical_codes(&counts),
    };
    let mut out = vec![0xFF, 0xD8];
    s.headers(&mut out);
    s.entropy(&mut out);
    out.extend([0xFF, 0xD9]);
    out
}

/// What [`encode`] encodes.
struct Stream<'a> {
    samples: &'a [u16],
    width: usize,
    height: usize,
    nc: usize,
    precision: u8,
    predictor: u8,
    restart_rows: usize,
    counts: [u8; 16],
    /// Per SSSS value: its code and length.
    codes: Vec<(u32, u32)>,
}

/// The canonical codes (T.81 Annex C) of lengths `counts`, in symbol order.
fn canonical_codes(counts: &[u8; 16]) -> Vec<(u32, u32)> {
    let mut codes = Vec::new();
    let mut code = 0u32;
    for (l, &n) in (1u32..).zip(counts) {
        for _ in 0..n {
            codes.push((code, l));
            code += 1;
        }
        code <<= 1;
    }
    assert_eq!(codes.len(), 17, "one code per SSSS value 0–16");
    codes
}

impl Stream<'_> {
    /// DHT, SOF3, DRI (with restarts) and SOS.
    fn headers(&self, out: &mut Vec<u8>) {
        let (width, height, nc) = (self.width, self.height, self.nc);
        // DHT: 17 symbols (0–16)
        out.extend([0xFF, 0xC4]);
        out.extend(((2 + 1 + 16 + 17) as u16).to_be_bytes());
        out.push(0x00);
        out.extend(self.counts);
        out.extend(0u8..17);
        // SOF3
        out.extend([0xFF, 0xC3]);
        out.extend(((8 + 3 * nc) as u16).to_be_bytes());
        out.push(self.precision);
        out.extend((height as u16).to_be_bytes());
        out.extend((width as u16).to_be_bytes());
        out.push(nc as u8);
        for c in 0..nc {
            out.extend([c as u8 + 1, 0x11, 0]);
        }
        if self.restart_rows > 0 {
            out.extend([0xFF, 0xDD, 0, 4]);
            out.extend(((self.restart_rows * width) as u16).to_be_bytes());
        }
        // SOS
        out.extend([0xFF, 0xDA]);
        out.extend(((6 + 2 * nc) as u16).to_be_bytes());
        out.push(nc as u8);
        for c in 0..nc {
            out.extend([c as u8 + 1, 0x00]);
        }
        out.extend([self.predictor, 0, 0]);
    }

    /// The entropy-coded data, with a restart marker every `restart_rows` rows.
    fn entropy(&self, out: &mut Vec<u8>) {
        let (width, nc, restart_rows) = (self.width, self.nc, self.restart_rows);
        let mut bitbuf: Vec<bool> = Vec::new();
        let mut rst = 0u8;
        let mut first = true;
        for row in 0..self.height {
            if restart_rows > 0 && row > 0 && row % restart_rows == 0 {
                flush(&mut bitbuf, out);
                out.extend([0xFF, 0xD0 + (rst & 7)]);
                rst += 1;
                first = true;
            }
            for col in 0..width {
                for c in 0..nc {
                    let i = row * width * nc + col * nc + c;
                    let pred = self.predict(i, col, first);
                    let d = (i32::from(self.samples[i]) - pred) as i16 as i32;
                    push_diff(&mut bitbuf, d, &self.codes);
                }
            }
            first = false;
        }
        flush(&mut bitbuf, out);
    }

    /// The prediction of sample `i` (in column `col`; `first`: the first row of an
    /// interval).
    fn predict(&self, i: usize, col: usize, first: bool) -> i32 {
        let (nc, row_len) = (self.nc, self.width * self.nc);
        let s = |j: usize| i32::from(self.samples[j]);
        if first {
            if col == 0 {
                1 << (self.precision - 1)
            } else {
                s(i - nc)
            }
        } else if col == 0 {
            s(i - row_len)
        } else {
            let (a, b, cc) = (s(i - nc), s(i - row_len), s(i - row_len - nc));
            match self.predictor {
                1 => a,
                _ => b + ((a - cc) >> 1),
            }
        }
    }
}

/// A difference: its SSSS code, then its extra bits.
fn push_diff(bitbuf: &mut Vec<bool>, d: i32, codes: &[(u32, u32)]) {
    let (ssss, extra) = if d == 0 {
        (0u32, 0u32)
    } else if d == -32768 {
        (16, 0)
    } else {
        let m = d.unsigned_abs();
        let ssss = 32 - m.leading_zeros();
        let v = if d > 0 { d } else { d + (1 << ssss) - 1 };
        (ssss, v as u32)
    };
    let (code, len) = codes[ssss as usize];
    for k in (0..len).rev() {
        bitbuf.push((code >> k) & 1 == 1);
    }
    if ssss > 0 && ssss < 16 {
        for k in (0..ssss).rev() {
            bitbuf.push((extra >> k) & 1 == 1);
        }
    }
}

/// The bits as bytes (the last padded with ones), a zero stuffed after each 0xFF.
fn flush(bitbuf: &mut Vec<bool>, out: &mut Vec<u8>) {
    while !bitbuf.len().is_multiple_of(8) {
        bitbuf.push(true);
    }
    for ch in bitbuf.chunks(8) {
        let b = ch.iter().fold(0u8, |a, &x| (a << 1) | x as u8);
        out.push(b);
        if b == 0xFF {
            out.push(0);
        }
    }
    bitbuf.clear();
}

fn ramp(n: usize, bits: u32) -> Vec<u16> {
    (0..n)
        .map(|i| ((i * 2654435761) % (1 << bits)) as u16)
        .collect()
}

#[test]
fn round_trips_components_predictors_and_restarts() {
    for (w, h, nc, p, pred, rst) in [
        (5, 4, 1, 12, 1, 0),
        (3, 6, 2, 16, 6, 0),
        (4, 3, 4, 10, 1, 0),
        (7, 6, 1, 14, 6, 2),
        (2, 2, 3, 16, 1, 1),
    ] {
        let s = ramp(w * h * nc, u32::from(p));
        let j = encode(&s, (w, h, nc), p, pred, rst);
        let d = decode(&j, 1 << 20).unwrap();
        assert_eq!((d.width, d.height, d.components), (w, h, nc));
        assert_eq!(d.samples, s, "{w}×{h}×{nc} {p}-bit predictor {pred}");
    }
}

#[test]
fn codes_longer_than_the_lookup_table_decode() {
    // differences of every size, so that every code length from 2 to 16 bits occurs
    let s: Vec<u16> = (0..40 * 9)
        .map(|i: usize| ((i * i * 2654435761) >> (i % 17)) as u16)
        .collect();
    for (nc, pred, rst) in [(1, 1, 0), (2, 6, 3), (3, 1, 1)] {
        let w = 40 / nc * 3;
        let h = s.len() / (w * nc);
        let s = &s[..w * h * nc];
        let j = encode_with(ALL_LENGTHS, s, (w, h, nc), 16, (pred, rst));
        let d = decode(&j, 1 << 20).unwrap();
        assert_eq!(d.samples, s, "{w}×{h}×{nc} predictor {pred}");
        // the same samples with 5-bit codes
        assert_eq!(
            decode(&encode(s, (w, h, nc), 16, pred, rst), 1 << 20).unwrap(),
            d
        );
    }
}

#[test]
fn hostile_streams_are_errors() {
    let s = ramp(64, 12);
    let j = encode(&s, (8, 8, 1), 12, 1, 0);
    // too many samples for the caller
    let e = decode(&j, 63).unwrap_err().to_string();
    assert!(e.contains("at most 63"), "{e}");
    // truncated entropy data
    // (without EOI the scan is still complete)
    assert_eq!(decode(&j[..j.len() - 2], 1 << 20).unwrap().samples, s);
    for cut in [j.len() - 3, j.len() - 6, j.len() - 20, 60] {
        assert!(decode(&j[..cut], 1 << 20).is_err(), "cut at {cut}");
    }
    // a frame declaring far more samples than the data can hold
    let mut big = j.clone();
    let sof = big.windows(2).position(|w| w == [0xFF, 0xC3]).unwrap();
    big[sof + 5..sof + 9].copy_from_slice(&[0xFF, 0xFF, 0xFF, 0xFF]);
    let e = decode(&big, usize::MAX).unwrap_err().to_string();
    assert!(e.contains("cannot fit"), "{e}");
    // baseline JPEG, missing SOI
    let e = decode(&[0xFF, 0xD8, 0xFF, 0xC0, 0, 2], 100)
        .unwrap_err()
        .to_string();
    assert!(e.contains("SOF0"), "{e}");
    assert!(decode(b"\x00\x00", 100).is_err());
    assert!(decode(&[], 100).is_err());
}
