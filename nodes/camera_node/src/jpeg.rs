//! JPEG encoding of RGB frames (the test pattern) and of YUYV frames (webcams that
//! offer no MJPEG), with the pure-Rust `jpeg-encoder`.

/// Why a frame could not be encoded.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// JPEG sizes are 16-bit.
    #[error("{width}x{height} is too large for JPEG (65535 at most)")]
    TooLarge {
        /// width given
        width: usize,
        /// height given
        height: usize,
    },
    /// The buffer does not hold a whole frame of the size and format given.
    #[error("{len} bytes are not a {width}x{height} {format} frame")]
    WrongLength {
        /// bytes given
        len: usize,
        /// width given
        width: usize,
        /// height given
        height: usize,
        /// `RGB` or `YUYV`
        format: &'static str,
    },
    /// The encoder's own error.
    #[error("JPEG encoder: {0}")]
    Encoder(String),
}

/// Encode an RGB image (`width * height * 3` bytes) to a JPEG file at `quality` (1-100).
pub fn encode_rgb(
    rgb: &[u8],
    width: usize,
    height: usize,
    quality: u8,
) -> Result<Vec<u8>, EncodeError> {
    let (w, h) = match (u16::try_from(width), u16::try_from(height)) {
        (Ok(w), Ok(h)) => (w, h),
        _ => return Err(EncodeError::TooLarge { width, height }),
    };
    if rgb.len() != width * height * 3 {
        return Err(EncodeError::WrongLength {
            len: rgb.len(),
            width,
            height,
            format: "RGB",
        });
    }
    let mut out = Vec::with_capacity(width * height / 4);
    jpeg_encoder::Encoder::new(&mut out, quality.clamp(1, 100))
        .encode(rgb, w, h, jpeg_encoder::ColorType::Rgb)
        .map_err(|e| EncodeError::Encoder(e.to_string()))?;
    Ok(out)
}

/// YUYV 4:2:2 (V4L2's `YUYV`: Y0 U Y1 V for each two pixels, BT.601 limited range, as
/// UVC webcams send it) to RGB. `stride`: bytes from one row to the next (V4L2's
/// `bytesperline`, at least `width * 2`; some drivers pad rows).
pub fn yuyv_to_rgb(
    yuyv: &[u8],
    width: usize,
    height: usize,
    stride: usize,
) -> Result<Vec<u8>, EncodeError> {
    let wrong = || EncodeError::WrongLength {
        len: yuyv.len(),
        width,
        height,
        format: "YUYV",
    };
    let stride = stride.max(width * 2);
    if width % 2 != 0 || height == 0 || yuyv.len() < stride * (height - 1) + width * 2 {
        return Err(wrong());
    }
    let mut rgb = Vec::with_capacity(width * height * 3);
    for row in 0..height {
        let start = row * stride;
        for q in yuyv[start..start + width * 2].chunks_exact(4) {
            let (u, v) = (i32::from(q[1]) - 128, i32::from(q[3]) - 128);
            for y in [q[0], q[2]] {
                let c = 298 * (i32::from(y) - 16);
                rgb.push(((c + 409 * v + 128) >> 8).clamp(0, 255) as u8);
                rgb.push(((c - 100 * u - 208 * v + 128) >> 8).clamp(0, 255) as u8);
                rgb.push(((c + 516 * u + 128) >> 8).clamp(0, 255) as u8);
            }
        }
    }
    Ok(rgb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yuyv_limited_range_black_white_and_red_convert_to_rgb() {
        // black, white (Y 16, 235, no chroma), then a red pair (BT.601: Y 81, U 90, V 240)
        let px = [16, 128, 235, 128, 81, 90, 81, 240];
        let rgb = yuyv_to_rgb(&px, 4, 1, 8).unwrap();
        assert_eq!(rgb[..6], [0, 0, 0, 255, 255, 255]);
        assert!(rgb[6] > 250 && rgb[7] < 5 && rgb[8] < 5, "{:?}", &rgb[6..]);
        assert!(matches!(
            yuyv_to_rgb(&px, 3, 1, 8),
            Err(EncodeError::WrongLength { .. })
        ));
        assert!(matches!(
            yuyv_to_rgb(&px, 4, 2, 8),
            Err(EncodeError::WrongLength { .. })
        ));
    }

    #[test]
    fn padded_yuyv_rows_skip_their_padding() {
        // two rows of one black-white pair, each padded with 4 bytes of grey
        let px = [16, 128, 235, 128, 99, 99, 99, 99, 235, 128, 16, 128];
        let rgb = yuyv_to_rgb(&px, 2, 2, 8).unwrap();
        assert_eq!(rgb, [0, 0, 0, 255, 255, 255, 255, 255, 255, 0, 0, 0]);
    }

    #[test]
    fn an_encoded_frame_decodes_to_its_size_and_colours() {
        let (w, h) = (64, 48);
        let rgb: Vec<u8> = (0..w * h).flat_map(|_| [200u8, 40, 40]).collect();
        let jpeg = encode_rgb(&rgb, w, h, 90).unwrap();
        assert_eq!(jpeg[..2], [0xff, 0xd8]);
        let mut d = jpeg_decoder::Decoder::new(&jpeg[..]);
        let back = d.decode().unwrap();
        let info = d.info().unwrap();
        assert_eq!((info.width, info.height), (64, 48));
        assert!(back.iter().zip(&rgb).all(|(a, b)| a.abs_diff(*b) < 8));
        assert!(matches!(
            encode_rgb(&rgb[1..], w, h, 90),
            Err(EncodeError::WrongLength { .. })
        ));
        assert!(matches!(
            encode_rgb(&[], 70_000, 1, 90),
            Err(EncodeError::TooLarge { .. })
        ));
    }
}
