//! Lossless JPEG (ITU T.81 process 14: SOF3, Huffman coded, predictors 1–7), as DNG uses it
//! for compression 7: 2–16-bit samples, 1–4 interleaved components with 1×1 sampling,
//! restart intervals of whole rows.
//!
//! Hostile input: the sample count is checked against the caller's bound and against the
//! entropy-coded data (every sample takes at least one bit) before the output is allocated,
//! and the data may not run out by more than a few bytes of padding.

use super::ifd::dng_err;
use crate::io::IoResult;

/// A decoded lossless JPEG frame: `height` rows of `width × components` interleaved samples.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Ljpeg {
    pub width: usize,
    pub height: usize,
    pub components: usize,
    pub precision: u8,
    pub samples: Vec<u16>,
}

/// A DC Huffman table in the form of T.81 Annex F.2.2.3.
#[derive(Debug, Clone)]
struct Huffman {
    maxcode: [i32; 17],
    mincode: [i32; 17],
    valptr: [usize; 17],
    values: Vec<u8>,
}

impl Huffman {
    fn new(counts: &[u8; 16], values: Vec<u8>) -> IoResult<Self> {
        let mut maxcode = [-1i32; 17];
        let mut mincode = [0i32; 17];
        let mut valptr = [0usize; 17];
        let mut code = 0i32;
        let mut k = 0usize;
        for l in 1..=16 {
            let n = i32::from(counts[l - 1]);
            mincode[l] = code;
            valptr[l] = k;
            code += n;
            k += n as usize;
            if code > (1 << l) {
                return Err(dng_err(
                    "lossless JPEG: a Huffman table has more codes than its lengths allow",
                ));
            }
            if n > 0 {
                maxcode[l] = code - 1;
            }
            code <<= 1;
        }
        if k != values.len() {
            return Err(dng_err(
                "lossless JPEG: a Huffman table's sizes do not add up",
            ));
        }
        Ok(Huffman {
            maxcode,
            mincode,
            valptr,
            values,
        })
    }
}

/// Reads the entropy-coded bits: removes stuffed zero bytes, stops at markers.
struct Bits<'a> {
    data: &'a [u8],
    pos: usize,
    buf: u64,
    n: u32,
    /// Zero bytes fed after the data ended (or a marker was reached).
    padding: u32,
}

/// Bytes of zero padding a scan may need past its end before it counts as truncated.
const MAX_PADDING: u32 = 16;

impl<'a> Bits<'a> {
    fn fill(&mut self) -> IoResult<()> {
        while self.n <= 56 {
            let b = match self.data.get(self.pos) {
                Some(&0xFF) => match self.data.get(self.pos + 1) {
                    Some(0x00) => {
                        self.pos += 2;
                        0xFF
                    }
                    _ => self.pad()?,
                },
                Some(&b) => {
                    self.pos += 1;
                    b
                }
                None => self.pad()?,
            };
            self.buf |= u64::from(b) << (56 - self.n);
            self.n += 8;
        }
        Ok(())
    }

    fn pad(&mut self) -> IoResult<u8> {
        self.padding += 1;
        if self.padding > MAX_PADDING {
            Err(dng_err("lossless JPEG: the compressed data ends early"))
        } else {
            Ok(0)
        }
    }

    /// Fails if the decoder used any of the zero bits fed past the data's end (a complete
    /// scan pads its last byte with real bits).
    fn check_complete(&self) -> IoResult<()> {
        if self.padding * 8 > self.n {
            Err(dng_err("lossless JPEG: the compressed data ends early"))
        } else {
            Ok(())
        }
    }

    fn bit(&mut self) -> IoResult<u32> {
        if self.n == 0 {
            self.fill()?;
        }
        let b = (self.buf >> 63) as u32;
        self.buf <<= 1;
        self.n -= 1;
        Ok(b)
    }

    fn bits(&mut self, k: u32) -> IoResult<u32> {
        if k == 0 {
            return Ok(0);
        }
        if self.n < k {
            self.fill()?;
        }
        let v = (self.buf >> (64 - k)) as u32;
        self.buf <<= k;
        self.n -= k;
        Ok(v)
    }

    fn decode(&mut self, h: &Huffman) -> IoResult<u8> {
        let mut code = 0i32;
        for l in 1..=16 {
            code = (code << 1) | self.bit()? as i32;
            if code <= h.maxcode[l] {
                return usize::try_from(code - h.mincode[l])
                    .ok()
                    .and_then(|d| h.valptr[l].checked_add(d))
                    .and_then(|i| h.values.get(i))
                    .copied()
                    .ok_or_else(|| dng_err("lossless JPEG: a Huffman code has no value"));
            }
        }
        Err(dng_err("lossless JPEG: invalid Huffman code in the data"))
    }

    /// A sample difference (T.81 H.1.2.2: categories 0–16).
    fn diff(&mut self, h: &Huffman) -> IoResult<i32> {
        let ssss = u32::from(self.decode(h)?);
        Ok(match ssss {
            0 => 0,
            16 => 32768,
            1..=15 => {
                let v = self.bits(ssss)? as i32;
                if v < (1 << (ssss - 1)) {
                    v - (1 << ssss) + 1
                } else {
                    v
                }
            }
            _ => {
                return Err(dng_err(format!(
                    "lossless JPEG: difference category {ssss} (at most 16)"
                )));
            }
        })
    }

    /// Skips to and over the restart marker RSTn expected next.
    fn restart(&mut self, n: u8) -> IoResult<()> {
        self.check_complete()?;
        self.buf = 0;
        self.n = 0;
        self.padding = 0;
        let want = 0xD0 + (n & 7);
        // fill bytes (0xFF) may precede the marker
        while self.data.get(self.pos) == Some(&0xFF) && self.data.get(self.pos + 1) == Some(&0xFF) {
            self.pos += 1;
        }
        match (self.data.get(self.pos), self.data.get(self.pos + 1)) {
            (Some(0xFF), Some(&m)) if m == want => {
                self.pos += 2;
                Ok(())
            }
            _ => Err(dng_err(format!(
                "lossless JPEG: restart marker RST{} expected at byte {}",
                n & 7,
                self.pos
            ))),
        }
    }
}

/// One frame component: its Huffman table id.
#[derive(Debug, Clone, Copy)]
struct Component {
    id: u8,
    table: usize,
}

fn be16(data: &[u8], at: usize) -> IoResult<usize> {
    match (data.get(at), data.get(at + 1)) {
        (Some(&a), Some(&b)) => Ok(usize::from(u16::from_be_bytes([a, b]))),
        _ => Err(dng_err("lossless JPEG: a marker segment ends early")),
    }
}

fn byte(data: &[u8], at: usize) -> IoResult<u8> {
    data.get(at)
        .copied()
        .ok_or_else(|| dng_err("lossless JPEG: a marker segment ends early"))
}

/// Decodes one lossless JPEG stream. At most `max_samples` samples (width × height ×
/// components) are accepted.
pub(super) fn decode(data: &[u8], max_samples: usize) -> IoResult<Ljpeg> {
    if data.get(..2) != Some(&[0xFF, 0xD8]) {
        return Err(dng_err(
            "lossless JPEG: the tile does not start with an SOI marker",
        ));
    }
    let mut pos = 2;
    let mut tables: [Option<Huffman>; 4] = [None, None, None, None];
    let mut frame: Option<Frame> = None;
    let mut restart = 0usize;
    loop {
        // a marker: 0xFF (fill bytes allowed) then the code
        if byte(data, pos)? != 0xFF {
            return Err(dng_err(format!(
                "lossless JPEG: a marker is expected at byte {pos}"
            )));
        }
        while byte(data, pos)? == 0xFF {
            pos += 1;
        }
        let marker = byte(data, pos)?;
        pos += 1;
        match marker {
            0xD8 | 0x01 | 0xD0..=0xD7 => continue,
            0xD9 => return Err(dng_err("lossless JPEG: the image ends before its scan")),
            _ => {}
        }
        let len = be16(data, pos)?;
        if len < 2 || pos + len > data.len() {
            return Err(dng_err(format!(
                "lossless JPEG: marker 0xFF{marker:02X} has length {len}, beyond the data"
            )));
        }
        let seg = data.get(pos + 2..pos + len).unwrap_or(&[]);
        pos += len;
        match marker {
            0xC4 => read_huffman_tables(seg, &mut tables)?,
            0xC3 => frame = Some(read_frame(seg)?),
            0xC0..=0xCF if marker != 0xC4 && marker != 0xC8 && marker != 0xCC => {
                return Err(dng_err(format!(
                    "lossless JPEG: frame type SOF{} is not lossless Huffman (SOF3)",
                    marker - 0xC0
                )));
            }
            0xDD => restart = be16(seg, 0)?,
            0xDA => {
                let Some(frame) = frame.take() else {
                    return Err(dng_err(
                        "lossless JPEG: a scan comes before the frame header",
                    ));
                };
                let scan = read_scan(seg, frame, &tables, restart)?;
                let entropy = data.get(pos..).unwrap_or(&[]);
                return scan.decode(entropy, &tables, max_samples);
            }
            _ => {}
        }
    }
}

/// A DHT segment: one or more DC Huffman tables.
fn read_huffman_tables(seg: &[u8], tables: &mut [Option<Huffman>; 4]) -> IoResult<()> {
    let mut p = 0;
    while p < seg.len() {
        let tc_th = byte(seg, p)?;
        let (class, id) = (tc_th >> 4, usize::from(tc_th & 15));
        if class != 0 || id > 3 {
            return Err(dng_err(format!(
                "lossless JPEG: Huffman table class {class} id {id} (DC tables 0–3 are used)"
            )));
        }
        let mut counts = [0u8; 16];
        for (i, c) in counts.iter_mut().enumerate() {
            *c = byte(seg, p + 1 + i)?;
        }
        let total: usize = counts.iter().map(|&c| usize::from(c)).sum();
        let vals = seg
            .get(p + 17..p + 17 + total)
            .ok_or_else(|| dng_err("lossless JPEG: a Huffman table ends early"))?;
        tables[id] = Some(Huffman::new(&counts, vals.to_vec())?);
        p += 17 + total;
    }
    Ok(())
}

/// The frame header (SOF3).
struct Frame {
    precision: u8,
    width: usize,
    height: usize,
    comps: Vec<Component>,
}

/// An SOF3 segment: precision, size and components (1×1 sampling).
fn read_frame(seg: &[u8]) -> IoResult<Frame> {
    let precision = byte(seg, 0)?;
    let height = be16(seg, 1)?;
    let width = be16(seg, 3)?;
    let nf = usize::from(byte(seg, 5)?);
    if !(2..=16).contains(&precision) {
        return Err(dng_err(format!(
            "lossless JPEG: sample precision {precision} (2–16 bits)"
        )));
    }
    if width == 0 || height == 0 {
        return Err(dng_err(format!(
            "lossless JPEG: the frame is {width}×{height}"
        )));
    }
    if !(1..=4).contains(&nf) {
        return Err(dng_err(format!(
            "lossless JPEG: {nf} components (1–4 are supported)"
        )));
    }
    let mut comps = Vec::with_capacity(nf);
    for i in 0..nf {
        let id = byte(seg, 6 + 3 * i)?;
        let hv = byte(seg, 7 + 3 * i)?;
        if hv != 0x11 {
            return Err(dng_err(format!(
                "lossless JPEG: component {id} has sampling factors {}×{} (1×1 is supported)",
                hv >> 4,
                hv & 15
            )));
        }
        comps.push(Component { id, table: 0 });
    }
    Ok(Frame {
        precision,
        width,
        height,
        comps,
    })
}

/// An SOS segment: the scan's components and their tables, the predictor and the point
/// transform, over the `frame`.
fn read_scan(
    seg: &[u8],
    frame: Frame,
    tables: &[Option<Huffman>; 4],
    restart: usize,
) -> IoResult<Scan> {
    let Frame {
        precision,
        width,
        height,
        mut comps,
    } = frame;
    let ns = usize::from(byte(seg, 0)?);
    if ns != comps.len() {
        return Err(dng_err(format!(
            "lossless JPEG: the scan has {ns} of the frame's {} components (one interleaved scan is supported)",
            comps.len()
        )));
    }
    for i in 0..ns {
        let cs = byte(seg, 1 + 2 * i)?;
        let td = usize::from(byte(seg, 2 + 2 * i)? >> 4);
        let c = comps.iter_mut().find(|c| c.id == cs).ok_or_else(|| {
            dng_err(format!(
                "lossless JPEG: the scan names unknown component {cs}"
            ))
        })?;
        if td > 3 || tables[td].is_none() {
            return Err(dng_err(format!(
                "lossless JPEG: component {cs} uses Huffman table {td}, which is not defined"
            )));
        }
        c.table = td;
    }
    let predictor = byte(seg, 1 + 2 * ns)?;
    let pt = byte(seg, 3 + 2 * ns)? & 15;
    if !(1..=7).contains(&predictor) {
        return Err(dng_err(format!(
            "lossless JPEG: predictor {predictor} (1–7 are defined)"
        )));
    }
    if pt >= precision {
        return Err(dng_err(format!(
            "lossless JPEG: point transform {pt} for {precision}-bit samples"
        )));
    }
    Ok(Scan {
        precision,
        width,
        height,
        comps,
        predictor,
        pt,
        restart,
    })
}

struct Scan {
    precision: u8,
    width: usize,
    height: usize,
    comps: Vec<Component>,
    predictor: u8,
    pt: u8,
    restart: usize,
}

impl Scan {
    /// The scan's samples (width × height × components), checked against `max_samples` and
    /// against what `entropy_len` bytes can code, and its rows per restart interval.
    fn checked_size(&self, entropy_len: usize, max_samples: usize) -> IoResult<(usize, usize)> {
        let nc = self.comps.len();
        let total = (self.width * nc) as u128 * self.height as u128;
        if total > max_samples as u128 {
            return Err(dng_err(format!(
                "lossless JPEG: a {}×{} frame of {nc} components is {total} samples; at most {max_samples} fit the tile",
                self.width, self.height
            )));
        }
        // every sample takes at least one bit of entropy-coded data
        let bound = (entropy_len as u128 + u128::from(MAX_PADDING)) * 8;
        if total > bound {
            return Err(dng_err(format!(
                "lossless JPEG: {total} samples cannot fit in {entropy_len} bytes of data"
            )));
        }
        if self.restart != 0 && !self.restart.is_multiple_of(self.width) {
            return Err(dng_err(format!(
                "lossless JPEG: restart interval {} is not a whole number of {}-sample rows",
                self.restart, self.width
            )));
        }
        let rows_per_interval = if self.restart == 0 {
            usize::MAX
        } else {
            self.restart / self.width
        };
        // (`total` ≤ `max_samples`, a usize)
        Ok((total as usize, rows_per_interval))
    }

    /// The prediction of sample `i` (column `col`) from the samples decoded before it in
    /// `out` (T.81 H.1.2.1); `first_row`: the first row of an image or restart interval.
    fn predict(&self, out: &[u16], i: usize, col: usize, first_row: bool) -> i32 {
        let nc = self.comps.len();
        let row_len = self.width * nc;
        let at = |back: usize| i32::from(out.get(i.wrapping_sub(back)).copied().unwrap_or(0));
        if first_row {
            if col == 0 {
                1i32 << (self.precision - self.pt - 1)
            } else {
                at(nc)
            }
        } else if col == 0 {
            at(row_len)
        } else {
            let (a, b, c) = (at(nc), at(row_len), at(row_len + nc));
            match self.predictor {
                1 => a,
                2 => b,
                3 => c,
                4 => a + b - c,
                5 => a + ((b - c) >> 1),
                6 => b + ((a - c) >> 1),
                _ => (a + b) >> 1,
            }
        }
    }

    fn decode(
        &self,
        entropy: &[u8],
        tables: &[Option<Huffman>; 4],
        max_samples: usize,
    ) -> IoResult<Ljpeg> {
        let (total, rows_per_interval) = self.checked_size(entropy.len(), max_samples)?;
        let nc = self.comps.len();
        let row_len = self.width * nc;
        let huff: Vec<&Huffman> = self
            .comps
            .iter()
            .map(|c| {
                tables
                    .get(c.table)
                    .and_then(Option::as_ref)
                    .ok_or_else(|| dng_err("lossless JPEG: a Huffman table is missing"))
            })
            .collect::<IoResult<_>>()?;
        let mut out = vec![0u16; total];
        let mut bits = Bits {
            data: entropy,
            pos: 0,
            buf: 0,
            n: 0,
            padding: 0,
        };
        let mut rst = 0u8;
        let mut first_row = true;
        for row in 0..self.height {
            if row > 0 && row % rows_per_interval == 0 {
                bits.restart(rst)?;
                rst = rst.wrapping_add(1);
                first_row = true;
            }
            let base = row * row_len;
            for col in 0..self.width {
                for (c, h) in huff.iter().enumerate() {
                    let i = base + col * nc + c;
                    let pred = self.predict(&out, i, col, first_row);
                    let d = bits.diff(h)?;
                    if let Some(o) = out.get_mut(i) {
                        *o = (pred + d) as u16;
                    }
                }
            }
            first_row = false;
        }
        bits.check_complete()?;
        if self.pt > 0 {
            for v in &mut out {
                *v = v.wrapping_shl(u32::from(self.pt));
            }
        }
        Ok(Ljpeg {
            width: self.width,
            height: self.height,
            components: nc,
            precision: self.precision,
            samples: out,
        })
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A minimal lossless JPEG encoder (predictor 1 or 6, one table for every component,
    /// SSSS codes of fixed length 5), to test the decoder on streams built here.
    pub(crate) fn encode(
        samples: &[u16],
        width: usize,
        height: usize,
        nc: usize,
        precision: u8,
        predictor: u8,
        restart_rows: usize,
    ) -> Vec<u8> {
        let s = Stream {
            samples,
            width,
            height,
            nc,
            precision,
            predictor,
            restart_rows,
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
    }

    impl Stream<'_> {
        /// DHT, SOF3, DRI (with restarts) and SOS.
        fn headers(&self, out: &mut Vec<u8>) {
            let (width, height, nc) = (self.width, self.height, self.nc);
            // DHT: 17 symbols (0–16), all 5-bit codes
            let mut counts = [0u8; 16];
            counts[4] = 17;
            out.extend([0xFF, 0xC4]);
            out.extend(((2 + 1 + 16 + 17) as u16).to_be_bytes());
            out.push(0x00);
            out.extend(counts);
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
                        push_diff(&mut bitbuf, d);
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

    /// A difference: its 5-bit SSSS code, then its extra bits.
    fn push_diff(bitbuf: &mut Vec<bool>, d: i32) {
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
        for k in (0..5).rev() {
            bitbuf.push((ssss >> k) & 1 == 1);
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
            let j = encode(&s, w, h, nc, p, pred, rst);
            let d = decode(&j, 1 << 20).unwrap();
            assert_eq!((d.width, d.height, d.components), (w, h, nc));
            assert_eq!(d.samples, s, "{w}×{h}×{nc} {p}-bit predictor {pred}");
        }
    }

    #[test]
    fn hostile_streams_are_errors() {
        let s = ramp(64, 12);
        let j = encode(&s, 8, 8, 1, 12, 1, 0);
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
}
