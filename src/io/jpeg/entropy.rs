//! Huffman coding of quantised blocks (T.81 F.1.2) into a byte-stuffed bit stream.
//!
//! Two things make it fast, both libjpeg-turbo's: a 64-bit mask of the nonzero coefficients
//! in zig-zag order, so the zero runs come from `trailing_zeros` instead of a test per
//! coefficient; and a 64-bit bit buffer that is written 32 bits at a time, stuffing a zero
//! after each `0xFF` byte only for a word that has one (tested for all four bytes at once).

use super::dct::{Quantised, TRANSPOSED};
use super::tables::{HuffSpec, huff_codes};

/// `ZIGZAG_BITS[r][b]`: the zig-zag positions, as bits, of the coefficients of row `r` of the
/// transposed block whose columns are the set bits of `b`. Eight look-ups turn a row-by-row
/// mask of the nonzero coefficients into the zig-zag one, without reordering the block.
static ZIGZAG_BITS: [[u64; 256]; 8] = {
    let mut position = [0u32; 64];
    let mut k = 0;
    while k < 64 {
        position[TRANSPOSED[k]] = k as u32;
        k += 1;
    }
    let mut t = [[0u64; 256]; 8];
    let mut r = 0;
    while r < 8 {
        let mut b = 0;
        while b < 256 {
            let mut l = 0;
            while l < 8 {
                if b >> l & 1 == 1 {
                    t[r][b] |= 1 << position[8 * r + l];
                }
                l += 1;
            }
            b += 1;
        }
        r += 1;
    }
    t
};

/// [`Quantised::rows`] in zig-zag order: bit `k` for the `k`-th coefficient.
#[inline(always)]
fn nonzero_zigzag(rows: u64) -> u64 {
    let mut mask = 0;
    for (r, bits) in ZIGZAG_BITS.iter().enumerate() {
        mask |= bits[(rows >> (8 * r)) as usize & 0xff];
    }
    mask
}

/// One component's code tables: `(code << 8) | length` per symbol.
pub(super) struct Codes {
    dc: [u32; 256],
    ac: [u32; 256],
}

impl Codes {
    pub fn new(dc: &HuffSpec, ac: &HuffSpec) -> Self {
        Codes {
            dc: huff_codes(dc),
            ac: huff_codes(ac),
        }
    }
}

/// A bit stream being written: the bits not yet written sit at the bottom of `acc`.
pub(super) struct BitWriter {
    acc: u64,
    bits: u32,
    pub out: Vec<u8>,
}

/// Whether any byte of `w` is `0xFF`.
#[inline(always)]
fn has_ff(w: u32) -> bool {
    let x = !w;
    x.wrapping_sub(0x0101_0101) & !x & 0x8080_8080 != 0
}

impl BitWriter {
    pub fn new(capacity: usize) -> Self {
        BitWriter {
            acc: 0,
            bits: 0,
            out: Vec::with_capacity(capacity),
        }
    }

    /// A Huffman code (`code`: the code above its length in the low byte) followed by the
    /// `size` extra bits of a coefficient, `extra`.
    #[inline(always)]
    fn put_symbol(
        out: &mut Vec<u8>,
        acc: &mut u64,
        bits: &mut u32,
        code: u32,
        (size, extra): (u32, u32),
    ) {
        Self::put(
            out,
            acc,
            bits,
            ((code >> 8) << size) | extra,
            (code & 0xff) + size,
        );
    }

    /// Appends the low `len` bits of `value` (`len` ≤ 32, higher bits zero) to the stream
    /// whose unwritten bits are `acc`'s lowest `bits`.
    #[inline(always)]
    fn put(out: &mut Vec<u8>, acc: &mut u64, bits: &mut u32, value: u32, len: u32) {
        *acc = (*acc << len) | u64::from(value);
        *bits += len;
        if *bits >= 32 {
            *bits -= 32;
            let w = (*acc >> *bits) as u32;
            if has_ff(w) {
                for b in w.to_be_bytes() {
                    out.push(b);
                    if b == 0xff {
                        out.push(0);
                    }
                }
            } else {
                out.extend_from_slice(&w.to_be_bytes());
            }
        }
    }

    /// Pads the last byte with one bits (F.1.2.3) and writes what is left.
    pub fn finish(mut self) -> Vec<u8> {
        let pad = (8 - self.bits % 8) % 8;
        self.acc = (self.acc << pad) | ((1 << pad) - 1);
        self.bits += pad;
        while self.bits > 0 {
            self.bits -= 8;
            let b = (self.acc >> self.bits) as u8;
            self.out.push(b);
            if b == 0xff {
                self.out.push(0);
            }
        }
        self.out
    }

    /// Codes one block (the transposed output of [`super::dct::fdct_quantise`]); `pred` is
    /// the component's last DC value, updated.
    #[inline(always)]
    pub fn block(&mut self, q: &Quantised, pred: &mut i32, codes: &Codes) {
        let coef = &q.coef;
        let nonzero = nonzero_zigzag(q.rows);
        let (mut acc, mut bits) = (self.acc, self.bits);
        let out = &mut self.out;
        let dc = coef[0];
        let (size, extra) = magnitude(dc - *pred);
        *pred = dc;
        Self::put_symbol(
            out,
            &mut acc,
            &mut bits,
            codes.dc[size as usize],
            (size, extra),
        );

        let mut rest = nonzero & !1;
        let mut last = 0u32;
        while rest != 0 {
            let k = rest.trailing_zeros();
            let mut run = k - last - 1;
            while run >= 16 {
                let zrl = codes.ac[0xf0];
                Self::put(out, &mut acc, &mut bits, zrl >> 8, zrl & 0xff);
                run -= 16;
            }
            let (size, extra) = magnitude(coef[TRANSPOSED[k as usize & 63]]);
            let code = codes.ac[((run << 4) | size) as usize & 255];
            Self::put_symbol(out, &mut acc, &mut bits, code, (size, extra));
            last = k;
            rest &= rest - 1;
        }
        if last != 63 {
            let eob = codes.ac[0];
            Self::put(out, &mut acc, &mut bits, eob >> 8, eob & 0xff);
        }
        (self.acc, self.bits) = (acc, bits);
    }
}

/// A value's size category and its extra bits (F.1.2.1: negative values as one's complement).
#[inline(always)]
fn magnitude(v: i32) -> (u32, u32) {
    let size = 32 - v.unsigned_abs().leading_zeros();
    let bits = if v < 0 { v - 1 } else { v } as u32;
    (size, bits & ((1u32 << size) - 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_nonzero_mask_is_in_zig_zag_order() {
        let mut seed = 1u32;
        for _ in 0..200 {
            let coef: [i32; 64] = std::array::from_fn(|_| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                i32::from(seed >> 29 == 0) * (seed >> 20) as i32
            });
            let want = (0..64).fold(0u64, |m, k| m | u64::from(coef[TRANSPOSED[k]] != 0) << k);
            let rows = (0..64).fold(0u64, |m, i| m | u64::from(coef[i] != 0) << i);
            assert_eq!(nonzero_zigzag(rows), want);
        }
    }

    #[test]
    fn magnitudes_follow_f_1_2_1() {
        assert_eq!(magnitude(0), (0, 0));
        assert_eq!(magnitude(1), (1, 1));
        assert_eq!(magnitude(-1), (1, 0));
        assert_eq!(magnitude(-3), (2, 0));
        assert_eq!(magnitude(5), (3, 5));
        assert_eq!(magnitude(-1023), (10, 0));
        assert_eq!(magnitude(2047), (11, 2047));
    }

    #[test]
    fn ff_bytes_are_stuffed_and_the_tail_padded() {
        for w in [
            0xffu32,
            0xff00,
            0x00ff_0000,
            0xff00_0000,
            0x7f7f_7f7f,
            0xfeff_fefe,
        ] {
            assert_eq!(has_ff(w), w.to_be_bytes().contains(&0xff), "{w:x}");
        }
        let mut b = BitWriter::new(16);
        for (v, len) in [(0xffff, 16), (0x1234, 16), (0b101, 3)] {
            BitWriter::put(&mut b.out, &mut b.acc, &mut b.bits, v, len);
        }
        assert_eq!(b.finish(), [0xff, 0, 0xff, 0, 0x12, 0x34, 0b1011_1111]);
    }
}
