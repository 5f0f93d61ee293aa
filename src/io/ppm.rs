//! PPM (Netpbm colour, binary P6, maxval 255): 8-bit sRGB without compression, for answers
//! whose encoding must cost next to nothing. A PPM is [`ppm_header`] followed by the pixels
//! as they are, so a server can send the header and then the rendered buffer itself.

use super::error::IoResult;
use super::png_format::header_dims;
use super::raw::check_len;

/// The header of a binary PPM of `width × height` 8-bit RGB pixels; the interleaved pixels
/// (`width × height × 3` bytes, row-major) follow it unchanged.
pub fn ppm_header(width: usize, height: usize) -> IoResult<Vec<u8>> {
    let (w, h) = header_dims(width, height)?;
    Ok(format!("P6\n{w} {h}\n255\n").into_bytes())
}

/// Encodes interleaved 8-bit RGB (`width × height × 3` bytes) as an in-memory binary PPM.
pub fn encode_ppm_rgb8(width: usize, height: usize, data: &[u8]) -> IoResult<Vec<u8>> {
    let header = ppm_header(width, height)?;
    check_len("RGB data", data.len(), width, height, 3, "bytes")?;
    let mut out = crate::buffers::with_capacity(header.len() + data.len());
    out.extend_from_slice(&header);
    out.extend_from_slice(data);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ppm_is_its_header_then_the_pixels_and_decodes_to_them() {
        let (w, h) = (5, 3);
        let data: Vec<u8> = (0..w * h * 3).map(|i| (i * 17 % 256) as u8).collect();
        let ppm = encode_ppm_rgb8(w, h, &data).unwrap();
        let header = ppm_header(w, h).unwrap();
        assert_eq!(header, b"P6\n5 3\n255\n");
        assert_eq!(ppm.len(), header.len() + data.len());
        assert_eq!(&ppm[header.len()..], &data[..]);
        // an independent decoder reads it back
        let img = image::load_from_memory_with_format(&ppm, image::ImageFormat::Pnm)
            .unwrap()
            .into_rgb8();
        assert_eq!(img.dimensions(), (5, 3));
        assert_eq!(img.into_raw(), data);
    }

    #[test]
    fn wrong_sizes_are_refused() {
        assert!(encode_ppm_rgb8(5, 3, &[0; 44]).is_err());
        assert!(encode_ppm_rgb8(0, 3, &[]).is_err());
        assert!(ppm_header(3, 0).is_err());
    }
}
