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
    let k = index as usize;
    // one row of red and blue gradients (scrolling with k) and the black bar; each row
    // is a copy of it with its own green (scrolling down)
    let bar = (k * 8) % width.max(1);
    let mut template = vec![0u8; width * 3];
    for (x, px) in template.chunks_exact_mut(3).enumerate() {
        if !(bar..bar + 16).contains(&x) {
            px[0] = ((x + 4 * k) & 0xff) as u8;
            px[2] = ((x / 2 + k) & 0xff) as u8;
        }
    }
    let mut rgb = vec![0u8; width * height * 3];
    for (y, row) in rgb.chunks_exact_mut(width * 3).enumerate() {
        row.copy_from_slice(&template);
        let g = ((y + 2 * k) & 0xff) as u8;
        for (x, px) in row.chunks_exact_mut(3).enumerate() {
            if !(bar..bar + 16).contains(&x) {
                px[1] = g;
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
