//! The test source's frames: a moving pattern (colour gradients that scroll and a
//! black bar that sweeps across, one step a frame) with the frame's stamp drawn in
//! ([`crate::code`]), encoded to JPEG.

use crate::code;
use eezybot_msgs::Time;

/// The RGB pixels (`width * height * 3` bytes) of frame number `index` stamped `stamp`.
pub fn frame_rgb(
    width: usize,
    height: usize,
    index: u64,
    stamp: Time,
) -> Result<Vec<u8>, code::CodeError> {
    let mut rgb = vec![0u8; width * height * 3];
    let k = index as usize;
    let bar = (k * 8) % width.max(1);
    for (y, row) in rgb.chunks_exact_mut(width * 3).enumerate() {
        let g = ((y + 2 * k) & 0xff) as u8;
        for (x, px) in row.chunks_exact_mut(3).enumerate() {
            if x >= bar && x < bar + 16 {
                px.fill(0);
            } else {
                px[0] = ((x + 4 * k) & 0xff) as u8;
                px[1] = g;
                px[2] = (((x + y) / 2 + k) & 0xff) as u8;
            }
        }
    }
    code::draw(&mut rgb, width, height, stamp)?;
    Ok(rgb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pattern_moves_from_frame_to_frame_but_not_its_code_band() {
        let (w, h) = (320, 240);
        let a = frame_rgb(w, h, 0, Time::new(5, 0)).unwrap();
        let b = frame_rgb(w, h, 1, Time::new(5, 0)).unwrap();
        assert_eq!(a.len(), w * h * 3);
        assert_ne!(a, b);
        let l = code::Layout::of(w, h).unwrap();
        let band = |img: &[u8]| -> Vec<u8> {
            (0..l.band_height())
                .flat_map(|y| img[y * w * 3..(y * w + l.band_width()) * 3].to_vec())
                .collect()
        };
        assert!(band(&a) == band(&b), "same stamp, same code band");
        assert_eq!(code::read(&b, w, h), Ok(Time::new(5, 0)));
    }
}
