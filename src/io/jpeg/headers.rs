//! The marker segments around the scan: SOI, the JFIF APP0, the ICC profile in APP2, the
//! quantisation and Huffman tables, the frame and scan headers, the restart interval.

use super::tables::{CHROMA_AC, CHROMA_DC, HuffSpec, LUMA_AC, LUMA_DC, NATURAL};

/// What the headers describe.
pub(super) struct Frame<'a> {
    pub width: u16,
    pub height: u16,
    /// Luma's sampling factors, horizontal and vertical (chroma's are 1 × 1).
    pub luma_factors: (u8, u8),
    /// Row-major luminance and chrominance quantisation tables.
    pub quant: [&'a [u8; 64]; 2],
    pub icc: Option<&'a [u8]>,
    /// MCUs per restart interval, when the scan has restarts.
    pub restart_interval: Option<u16>,
}

/// The most profile bytes one APP2 segment carries (its length field counts itself, the
/// `ICC_PROFILE\0` tag and the two sequence bytes).
const ICC_CHUNK: usize = 65535 - 2 - 12 - 2;

/// Whether `icc` fits the 255 APP2 segments the sequence numbers allow.
pub(super) fn icc_fits(icc: &[u8]) -> bool {
    icc.len().div_ceil(ICC_CHUNK) < 255
}

fn segment(out: &mut Vec<u8>, marker: u8, body: &[&[u8]]) {
    let len: usize = body.iter().map(|b| b.len()).sum::<usize>() + 2;
    out.extend_from_slice(&[0xff, marker]);
    // every caller's body is far below 64 KiB (checked for the ICC chunks by their size)
    out.extend_from_slice(&(len as u16).to_be_bytes());
    for b in body {
        out.extend_from_slice(b);
    }
}

fn huffman(out: &mut Vec<u8>, class_dest: u8, spec: &HuffSpec) {
    segment(out, 0xc4, &[&[class_dest], &spec.bits, spec.vals]);
}

/// Everything from SOI to the end of the SOS segment. `icc` must pass [`icc_fits`].
pub(super) fn write_headers(out: &mut Vec<u8>, f: &Frame<'_>) {
    out.extend_from_slice(&[0xff, 0xd8]);
    // JFIF 1.02, no units, aspect ratio 1:1, no thumbnail
    segment(out, 0xe0, &[b"JFIF\0", &[1, 2, 0, 0, 1, 0, 1, 0, 0]]);
    if let Some(icc) = f.icc {
        let n = icc.len().div_ceil(ICC_CHUNK) as u8;
        for (i, chunk) in (1u8..).zip(icc.chunks(ICC_CHUNK)) {
            segment(out, 0xe2, &[b"ICC_PROFILE\0", &[i, n], chunk]);
        }
    }
    for (dest, table) in (0u8..).zip(f.quant) {
        let zigzag: [u8; 64] = NATURAL.map(|n| table[n]);
        segment(out, 0xdb, &[&[dest], &zigzag]);
    }
    let (h, v) = f.luma_factors;
    let [w0, w1] = f.width.to_be_bytes();
    let [h0, h1] = f.height.to_be_bytes();
    segment(
        out,
        0xc0,
        &[&[
            8,
            h0,
            h1,
            w0,
            w1,
            3,
            1,
            (h << 4) | v,
            0,
            2,
            0x11,
            1,
            3,
            0x11,
            1,
        ]],
    );
    huffman(out, 0x00, &LUMA_DC);
    huffman(out, 0x10, &LUMA_AC);
    huffman(out, 0x01, &CHROMA_DC);
    huffman(out, 0x11, &CHROMA_AC);
    if let Some(interval) = f.restart_interval {
        segment(out, 0xdd, &[&interval.to_be_bytes()]);
    }
    segment(out, 0xda, &[&[3, 1, 0x00, 2, 0x11, 3, 0x11, 0, 63, 0]]);
}
