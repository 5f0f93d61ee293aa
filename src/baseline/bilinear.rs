//! Bilinear demosaicking for any CFA: the baseline's demosaic and the fallback of the
//! stronger ones for layouts they cannot handle.

use rayon::prelude::*;

use super::BaselineError;
use crate::camera::Cfa;
use crate::l3::classify::mirror;

/// Bilinear demosaicking: each missing channel is the mean of that
/// channel's pixels in the 3×3 neighbourhood (5×5 if none), borders mirrored.
/// Returns `width × height × n_channels`, interleaved.
pub fn bilinear_demosaic(
    volts: &[f32],
    width: usize,
    height: usize,
    cfa: &Cfa,
) -> Result<Vec<f32>, BaselineError> {
    if width == 0 || height == 0 || volts.len() != width * height {
        return Err(BaselineError::InvalidInput(format!(
            "{} values for a {width}×{height} frame",
            volts.len()
        )));
    }
    let nc = cfa.n_channels();
    let mut out = vec![0f32; width * height * nc];
    out.par_chunks_mut(width * nc)
        .enumerate()
        .for_each(|(r, row)| {
            for c in 0..width {
                let own = cfa.channel_at(r, c);
                for ch in 0..nc {
                    let v = if ch == own {
                        volts[r * width + c]
                    } else {
                        let mut got = None;
                        for rad in [1isize, 2] {
                            let (mut s, mut n) = (0f32, 0u32);
                            for dy in -rad..=rad {
                                for dx in -rad..=rad {
                                    let rr = r as isize + dy;
                                    let cc = c as isize + dx;
                                    // the CFA phase of the true neighbour decides the channel
                                    if cfa.channel_at(
                                        rr.rem_euclid(2 * cfa.rows as isize) as usize,
                                        cc.rem_euclid(2 * cfa.cols as isize) as usize,
                                    ) == ch
                                    {
                                        s += volts[mirror(rr, height) * width + mirror(cc, width)];
                                        n += 1;
                                    }
                                }
                            }
                            if n > 0 {
                                got = Some(s / n as f32);
                                break;
                            }
                        }
                        got.unwrap_or(0.0)
                    };
                    row[c * nc + ch] = v;
                }
            }
        });
    Ok(out)
}
