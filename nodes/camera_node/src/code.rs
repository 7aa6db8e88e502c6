//! The stamp drawn into each test frame, so that a reader of the images can check that a
//! frame's pixels belong to its `header.stamp` (e.g. a dataset's video frames against
//! their timestamps).
//!
//! The stamp (`sec` as its 32 bits, `nanosec`) is four 16-bit words, most significant
//! bit first, plus a check word (the complement of their XOR): five rows of 16 square
//! blocks, black = 1, white = 0, on a white band at the top left of the image. A block is
//! [`Layout::block`] pixels a side (8 to 16, from the image size), large enough that JPEG
//! at any usual quality keeps its centre black or white. Below the blocks the stamp is
//! written in digits (`sec.nanosec`) for people.
//!
//! To read it back ([`read`]), decode the JPEG to RGB and pass the pixels and size: the
//! layout follows from the size alone.
//!
//! # Examples
//! ```
//! use camera_node::code;
//! use eezybot_msgs::Time;
//! let (w, h) = (320, 240);
//! let mut rgb = vec![90u8; w * h * 3];
//! let stamp = Time::new(1_764_446_400, 33_333_333);
//! code::draw(&mut rgb, w, h, stamp).unwrap();
//! assert_eq!(code::read(&rgb, w, h), Ok(stamp));
//! ```

use eezybot_msgs::Time;

/// Bits in a row of blocks.
pub const BITS: usize = 16;
/// Rows of blocks: four words of the stamp and the check word.
pub const ROWS: usize = 5;
/// The smallest block side, px.
pub const MIN_BLOCK: usize = 8;
/// The largest block side, px.
pub const MAX_BLOCK: usize = 16;
/// The smallest image that holds the code: 18 blocks wide (16 and a margin each side),
/// 16 blocks high (the code's band is 7 of them, the digits under it).
pub const MIN_WIDTH: usize = 18 * MIN_BLOCK;
/// See [`MIN_WIDTH`].
pub const MIN_HEIGHT: usize = 16 * MIN_BLOCK;

/// Where the code is in an image of a given size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Side of a block, px.
    pub block: usize,
    /// Scale of the digits' 3x5 font.
    pub digit_scale: usize,
}

impl Layout {
    /// The layout for an image `width` x `height`; `None` if it is smaller than
    /// [`MIN_WIDTH`] x [`MIN_HEIGHT`].
    pub fn of(width: usize, height: usize) -> Option<Layout> {
        let block = (width / 18).min(height / 16).min(MAX_BLOCK);
        (block >= MIN_BLOCK).then_some(Layout {
            block,
            digit_scale: (block / 5).max(1),
        })
    }

    /// Width of the white band behind the blocks, px.
    pub fn band_width(&self) -> usize {
        (BITS + 2) * self.block
    }

    /// Height of the white band behind the blocks and the digits, px.
    pub fn band_height(&self) -> usize {
        (ROWS + 2) * self.block + 7 * self.digit_scale
    }

    /// Top left corner of block `bit` of row `row`.
    fn corner(&self, row: usize, bit: usize) -> (usize, usize) {
        (self.block * (1 + bit), self.block * (1 + row))
    }
}

/// Why the code could not be drawn or read.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CodeError {
    /// The image is smaller than [`MIN_WIDTH`] x [`MIN_HEIGHT`].
    #[error("a {width}x{height} image is too small for the stamp code (at least {MIN_WIDTH}x{MIN_HEIGHT})")]
    TooSmall {
        /// width given
        width: usize,
        /// height given
        height: usize,
    },
    /// The pixel buffer is not `width * height * 3` bytes.
    #[error("{len} bytes are not a {width}x{height} RGB image")]
    WrongLength {
        /// bytes given
        len: usize,
        /// width given
        width: usize,
        /// height given
        height: usize,
    },
    /// The check word does not match the four words read: not a test frame, or damaged.
    #[error("the stamp code's check word is {found:#06x}, not {expected:#06x}: no stamp code, or a damaged one")]
    Check {
        /// the check word read
        found: u16,
        /// the check word of the four words read
        expected: u16,
    },
    /// A nanosecond field of 10⁹ or more.
    #[error("the stamp code's nanoseconds {nanosec} are not below 10^9")]
    BadNanosec {
        /// the value read
        nanosec: u32,
    },
}

/// The five words of `stamp`'s code.
pub fn words(stamp: Time) -> [u16; ROWS] {
    let (sec, nanosec) = split(stamp);
    let sec = sec as u32;
    let w = [
        (sec >> 16) as u16,
        sec as u16,
        (nanosec >> 16) as u16,
        nanosec as u16,
    ];
    [w[0], w[1], w[2], w[3], check_word(&w)]
}

fn check_word(w: &[u16; 4]) -> u16 {
    !(w[0] ^ w[1] ^ w[2] ^ w[3])
}

/// `stamp` as (`sec`, `nanosec`), as builtin_interfaces/Time has it.
pub fn split(stamp: Time) -> (i32, u32) {
    let n = stamp.to_nanos();
    (
        n.div_euclid(1_000_000_000) as i32,
        n.rem_euclid(1_000_000_000) as u32,
    )
}

fn check_size(rgb: &[u8], width: usize, height: usize) -> Result<Layout, CodeError> {
    if rgb.len() != width * height * 3 {
        return Err(CodeError::WrongLength {
            len: rgb.len(),
            width,
            height,
        });
    }
    Layout::of(width, height).ok_or(CodeError::TooSmall { width, height })
}

fn fill(rgb: &mut [u8], width: usize, x: usize, y: usize, w: usize, h: usize, value: u8) {
    let height = rgb.len() / (width * 3);
    for row in y..(y + h).min(height) {
        let start = (row * width + x.min(width)) * 3;
        let end = (row * width + (x + w).min(width)) * 3;
        rgb[start..end].fill(value);
    }
}

/// Draw `stamp`'s code and digits into the RGB image `rgb` (`width * height * 3`
/// bytes, row after row).
pub fn draw(rgb: &mut [u8], width: usize, height: usize, stamp: Time) -> Result<(), CodeError> {
    let l = check_size(rgb, width, height)?;
    fill(rgb, width, 0, 0, l.band_width(), l.band_height(), 255);
    for (row, word) in words(stamp).iter().enumerate() {
        for bit in 0..BITS {
            if word >> (BITS - 1 - bit) & 1 == 1 {
                let (x, y) = l.corner(row, bit);
                fill(rgb, width, x, y, l.block, l.block, 0);
            }
        }
    }
    let (sec, nanosec) = split(stamp);
    let text = format!("{sec}.{nanosec:09}");
    let s = l.digit_scale;
    let y0 = (ROWS + 1) * l.block + s;
    for (i, c) in text.chars().enumerate() {
        let x0 = l.block + i * 4 * s;
        for (r, bits) in glyph(c).iter().enumerate() {
            for col in 0..3 {
                if bits >> (2 - col) & 1 == 1 {
                    fill(rgb, width, x0 + col * s, y0 + r * s, s, s, 0);
                }
            }
        }
    }
    Ok(())
}

/// A 3x5 glyph, a row a byte (bit 2 = left column).
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        '-' => [0, 0, 7, 0, 0],
        _ => [0; 5],
    }
}

/// Read the stamp drawn by [`draw`] from an RGB image (e.g. a decoded JPEG): each
/// block's centre half is averaged, dark (< 128) = 1.
pub fn read(rgb: &[u8], width: usize, height: usize) -> Result<Time, CodeError> {
    let l = check_size(rgb, width, height)?;
    let mut w = [0u16; ROWS];
    let (q, half) = (l.block / 4, l.block / 2);
    for (row, word) in w.iter_mut().enumerate() {
        for bit in 0..BITS {
            let (x, y) = l.corner(row, bit);
            let mut sum = 0u64;
            for py in y + q..y + q + half {
                let start = (py * width + x + q) * 3;
                sum += rgb[start..start + half * 3]
                    .iter()
                    .map(|&v| u64::from(v))
                    .sum::<u64>();
            }
            let mean = sum / (half * half * 3) as u64;
            *word = *word << 1 | u16::from(mean < 128);
        }
    }
    let data = [w[0], w[1], w[2], w[3]];
    if check_word(&data) != w[4] {
        return Err(CodeError::Check {
            found: w[4],
            expected: check_word(&data),
        });
    }
    let sec = ((u32::from(w[0]) << 16) | u32::from(w[1])) as i32;
    let nanosec = (u32::from(w[2]) << 16) | u32::from(w[3]);
    if nanosec >= 1_000_000_000 {
        return Err(CodeError::BadNanosec { nanosec });
    }
    Ok(Time::new(sec, nanosec))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: usize, h: usize) -> Vec<u8> {
        (0..w * h * 3).map(|i| (i * 7 % 251) as u8).collect()
    }

    #[test]
    fn the_code_reads_back_what_was_drawn_for_stamps_of_every_kind() {
        let (w, h) = (200, 150);
        for stamp in [
            Time::new(0, 0),
            Time::new(1_764_446_400, 999_999_999),
            Time::new(-1, 5),
            Time::new(i32::MAX, 123_456_789),
            Time::new(i32::MIN, 1),
        ] {
            let mut rgb = image(w, h);
            draw(&mut rgb, w, h, stamp).unwrap();
            assert_eq!(read(&rgb, w, h), Ok(stamp), "{stamp:?}");
        }
    }

    #[test]
    fn an_image_without_the_code_is_refused_by_its_check_word() {
        let (w, h) = (320, 240);
        assert!(matches!(
            read(&vec![255; w * h * 3], w, h),
            Err(CodeError::Check { .. })
        ));
        let mut rgb = image(w, h);
        draw(&mut rgb, w, h, Time::new(12, 34)).unwrap();
        // one block of the first word flipped
        let l = Layout::of(w, h).unwrap();
        fill(&mut rgb, w, l.block * 3, l.block, l.block, l.block, 0);
        assert!(matches!(read(&rgb, w, h), Err(CodeError::Check { .. })));
    }

    #[test]
    fn the_layout_follows_the_size_and_refuses_small_images() {
        assert_eq!(Layout::of(640, 480).unwrap().block, 16);
        assert_eq!(Layout::of(MIN_WIDTH, MIN_HEIGHT).unwrap().block, 8);
        assert_eq!(Layout::of(MIN_WIDTH - 1, 480), None);
        let mut small = vec![0; 100 * 100 * 3];
        assert_eq!(
            draw(&mut small, 100, 100, Time::ZERO),
            Err(CodeError::TooSmall {
                width: 100,
                height: 100
            })
        );
        assert!(matches!(
            read(&[0; 5], 100, 100),
            Err(CodeError::WrongLength { len: 5, .. })
        ));
    }

    #[test]
    fn the_digits_are_drawn_under_the_blocks_inside_the_band() {
        let (w, h) = (640, 480);
        let mut rgb = vec![128; w * h * 3];
        draw(&mut rgb, w, h, Time::new(8, 0)).unwrap();
        let l = Layout::of(w, h).unwrap();
        let digits_top = (ROWS + 1) * l.block;
        let dark_under_blocks = (digits_top..l.band_height())
            .flat_map(|y| (0..w).map(move |x| (y * w + x) * 3))
            .filter(|&i| rgb[i] == 0)
            .count();
        assert!(dark_under_blocks > 0);
        // nothing of the band is left grey, and nothing outside it was touched
        assert!((0..l.band_height())
            .flat_map(|y| (0..l.band_width()).map(move |x| (y * w + x) * 3))
            .all(|i| rgb[i] == 0 || rgb[i] == 255));
        assert_eq!(rgb[(l.band_height() * w + 1) * 3], 128);
    }
}
