//! Cameras: the frames a [`crate::Frame`] carries ([`Image`]), and one `ffmpeg` child
//! per camera that encodes an episode live as lerobot 0.6.1 encodes it (see the crate
//! docs, "Cameras").
//!
//! An `Encoder` owns the child: a writer thread feeds its stdin from a queue of one
//! second of frames (`Encoder::push` never waits for ffmpeg: a full queue is refused
//! before any camera takes the frame, see `Encoder::has_room`), and a
//! reader thread takes ffmpeg's second output, every frame decoded to RGB, and appends
//! each frame's pixel counts ([`crate::stats::PixelCounts`], lerobot's downsampling) to a
//! file: the episode's image statistics are then a sum over the sampled frames at save.
//! Dropping an `Encoder` kills its child.

use std::fs::{self, File};
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;

use serde_json::Value;

use crate::stats::PixelCounts;

/// lerobot 0.6.1's default video encoder (`RGBEncoderConfig()`): libsvtav1, yuv420p,
/// GOP 2, CRF 30, preset 12 (`LIBSVTAV1_DEFAULT_PRESET`), fast-decode 0.
pub const VCODEC: &str = "libsvtav1";
/// See [`VCODEC`].
pub const PIX_FMT: &str = "yuv420p";
/// See [`VCODEC`].
pub const GOP: u32 = 2;
/// See [`VCODEC`].
pub const CRF: u32 = 30;
/// See [`VCODEC`].
pub const PRESET: u32 = 12;

/// A raw pixel layout of sensor_msgs/Image (`encoding`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RawEncoding {
    /// `rgb8`: 3 bytes per pixel.
    Rgb8,
    /// `bgr8`.
    Bgr8,
    /// `rgba8`: the alpha byte is ignored.
    Rgba8,
    /// `bgra8`.
    Bgra8,
    /// `mono8`: one grey byte, recorded as R = G = B.
    Mono8,
}

impl RawEncoding {
    /// The encoding named as in sensor_msgs/Image (`rgb8`, `bgr8`, `rgba8`, `bgra8`,
    /// `mono8`); `None` for any other.
    pub fn from_ros(name: &str) -> Option<Self> {
        Some(match name {
            "rgb8" => RawEncoding::Rgb8,
            "bgr8" => RawEncoding::Bgr8,
            "rgba8" => RawEncoding::Rgba8,
            "bgra8" => RawEncoding::Bgra8,
            "mono8" => RawEncoding::Mono8,
            _ => return None,
        })
    }

    fn bytes_per_pixel(self) -> usize {
        match self {
            RawEncoding::Rgb8 | RawEncoding::Bgr8 => 3,
            RawEncoding::Rgba8 | RawEncoding::Bgra8 => 4,
            RawEncoding::Mono8 => 1,
        }
    }
}

/// One camera's image of a frame.
#[derive(Debug, Clone, Copy)]
pub enum Image<'a> {
    /// A JPEG (sensor_msgs/CompressedImage `data`, format `jpeg`): passed to ffmpeg as is.
    Jpeg(&'a [u8]),
    /// Raw pixels (sensor_msgs/Image): `height` rows of `step` bytes.
    Raw {
        /// The pixel layout.
        encoding: RawEncoding,
        /// Pixels per row.
        width: u32,
        /// Rows.
        height: u32,
        /// Bytes per row (at least `width` × bytes per pixel).
        step: u32,
        /// The rows.
        data: &'a [u8],
    },
}

/// How a camera's frames reach ffmpeg in one episode: fixed by its first frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum InputKind {
    Jpeg,
    Rgb24,
}

/// The size of a JPEG from its SOF marker: `(width, height)`.
pub fn jpeg_size(jpeg: &[u8]) -> Result<(u32, u32), String> {
    if jpeg.len() < 4 || jpeg[0] != 0xFF || jpeg[1] != 0xD8 {
        return Err("not a JPEG (no SOI marker)".into());
    }
    let mut i = 2;
    while i + 4 <= jpeg.len() {
        if jpeg[i] != 0xFF {
            return Err(format!("not a JPEG: no marker at byte {i}"));
        }
        let marker = jpeg[i + 1];
        if marker == 0xFF {
            i += 1; // fill byte
            continue;
        }
        if marker == 0xD8 || marker == 0x01 || (0xD0..=0xD7).contains(&marker) {
            i += 2;
            continue;
        }
        let len = usize::from(u16::from_be_bytes([jpeg[i + 2], jpeg[i + 3]]));
        // SOF0..SOF15 except DHT (C4), JPG (C8) and DAC (CC)
        if (0xC0..=0xCF).contains(&marker) && ![0xC4, 0xC8, 0xCC].contains(&marker) {
            if i + 9 > jpeg.len() {
                break;
            }
            let h = u16::from_be_bytes([jpeg[i + 5], jpeg[i + 6]]);
            let w = u16::from_be_bytes([jpeg[i + 7], jpeg[i + 8]]);
            return Ok((u32::from(w), u32::from(h)));
        }
        if marker == 0xDA || len < 2 {
            break;
        }
        i += 2 + len;
    }
    Err("a JPEG without a frame header (SOF)".into())
}

impl Image<'_> {
    /// The image's `(width, height)`: a JPEG's from its header (an error if it is not a
    /// JPEG), a raw image's as given. A camera's spec can be made from its first image.
    pub fn size(&self) -> Result<(u32, u32), String> {
        match *self {
            Image::Jpeg(bytes) => jpeg_size(bytes),
            Image::Raw { width, height, .. } => Ok((width, height)),
        }
    }

    /// Checks the image against the camera's size; returns how it reaches ffmpeg.
    pub(crate) fn check(&self, width: u32, height: u32) -> Result<InputKind, String> {
        match *self {
            Image::Jpeg(bytes) => {
                let (w, h) = jpeg_size(bytes)?;
                if (w, h) != (width, height) {
                    return Err(format!("a {w}x{h} JPEG, expected {width}x{height}"));
                }
                Ok(InputKind::Jpeg)
            }
            Image::Raw {
                encoding,
                width: w,
                height: h,
                step,
                data,
            } => {
                if (w, h) != (width, height) {
                    return Err(format!("a {w}x{h} image, expected {width}x{height}"));
                }
                let row = w as usize * encoding.bytes_per_pixel();
                if (step as usize) < row {
                    return Err(format!("step {step} is less than a row ({row} bytes)"));
                }
                let need = step as usize * (h as usize).saturating_sub(1) + row;
                if data.len() < need {
                    return Err(format!(
                        "{} bytes of pixels, {need} needed for {w}x{h} with step {step}",
                        data.len()
                    ));
                }
                Ok(InputKind::Rgb24)
            }
        }
    }

    /// The bytes for ffmpeg's stdin: the JPEG, or the pixels as packed RGB.
    fn to_input(self) -> Vec<u8> {
        match self {
            Image::Jpeg(bytes) => bytes.to_vec(),
            Image::Raw {
                encoding,
                width,
                height,
                step,
                data,
            } => {
                let (w, h, step) = (width as usize, height as usize, step as usize);
                let bpp = encoding.bytes_per_pixel();
                let mut out = Vec::with_capacity(w * h * 3);
                for y in 0..h {
                    let row = &data[y * step..y * step + w * bpp];
                    match encoding {
                        RawEncoding::Rgb8 => out.extend_from_slice(row),
                        RawEncoding::Bgr8 | RawEncoding::Bgra8 => {
                            for p in row.chunks_exact(bpp) {
                                out.extend_from_slice(&[p[2], p[1], p[0]]);
                            }
                        }
                        RawEncoding::Rgba8 => {
                            for p in row.chunks_exact(4) {
                                out.extend_from_slice(&p[..3]);
                            }
                        }
                        RawEncoding::Mono8 => {
                            for &g in row {
                                out.extend_from_slice(&[g, g, g]);
                            }
                        }
                    }
                }
                out
            }
        }
    }
}

/// The last lines of an ffmpeg log, for an error message.
fn log_tail(log: &Path) -> String {
    let text = fs::read_to_string(log).unwrap_or_default();
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| !l.starts_with("Svt[info]") && !l.trim().is_empty())
        .collect();
    let tail = lines[lines.len().saturating_sub(3)..].join(" | ");
    if tail.is_empty() {
        "no message".into()
    } else {
        tail
    }
}

/// Checks that `ffmpeg` runs and has lerobot's encoder.
pub(crate) fn check_ffmpeg(ffmpeg: &Path) -> Result<(), String> {
    let out = Command::new(ffmpeg)
        .args(["-hide_banner", "-encoders"])
        .stdin(Stdio::null())
        .output()
        .map_err(|e| {
            format!(
                "cannot run {}: {e} (install Debian's ffmpeg)",
                ffmpeg.display()
            )
        })?;
    if !out.status.success() {
        return Err(format!(
            "{} -encoders failed: {}",
            ffmpeg.display(),
            out.status
        ));
    }
    if !String::from_utf8_lossy(&out.stdout).contains(VCODEC) {
        return Err(format!("{} has no {VCODEC} encoder", ffmpeg.display()));
    }
    Ok(())
}

/// The files of one camera's episode in progress, under `.recording/`.
pub(crate) struct EpisodeFiles {
    /// The episode's mp4.
    pub video: PathBuf,
    /// Its frames' pixel counts, [`PixelCounts::RECORD_BYTES`] per frame.
    pub counts: PathBuf,
    /// ffmpeg's messages.
    pub log: PathBuf,
}

impl EpisodeFiles {
    pub fn new(recording: &Path, feature: &str) -> Self {
        EpisodeFiles {
            video: recording.join(format!("{feature}.mp4")),
            counts: recording.join(format!("{feature}.counts")),
            log: recording.join(format!("{feature}.ffmpeg.log")),
        }
    }

    pub fn remove(&self) {
        for p in [&self.video, &self.counts, &self.log] {
            let _ = fs::remove_file(p);
        }
    }
}

/// A running ffmpeg encoding one camera's episode.
pub(crate) struct Encoder {
    child: Child,
    queue: Option<SyncSender<Vec<u8>>>,
    /// Frames pushed and not yet written to ffmpeg.
    queued: Arc<AtomicUsize>,
    capacity: usize,
    writer: Option<JoinHandle<Result<(), String>>>,
    reader: Option<JoinHandle<Result<u64, String>>>,
    kind: InputKind,
    log: PathBuf,
}

fn feed(
    mut stdin: ChildStdin,
    frames: Receiver<Vec<u8>>,
    queued: Arc<AtomicUsize>,
) -> Result<(), String> {
    for f in frames {
        stdin
            .write_all(&f)
            .map_err(|e| format!("writing to ffmpeg: {e}"))?;
        queued.fetch_sub(1, Ordering::AcqRel);
    }
    Ok(())
}

fn count_pixels(
    mut out: impl Read,
    counts: &Path,
    width: usize,
    height: usize,
) -> Result<u64, String> {
    let file = File::create(counts).map_err(|e| format!("{}: {e}", counts.display()))?;
    let mut file = BufWriter::new(file);
    let mut frame = vec![0u8; width * height * 3];
    let mut frames = 0;
    loop {
        match out.read_exact(&mut frame) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(e) => return Err(format!("reading ffmpeg's frames: {e}")),
        }
        let mut c = PixelCounts::default();
        c.add_frame(&frame, height, width);
        file.write_all(&c.to_record())
            .map_err(|e| format!("{}: {e}", counts.display()))?;
        frames += 1;
    }
    file.flush()
        .map_err(|e| format!("{}: {e}", counts.display()))?;
    Ok(frames)
}

impl Encoder {
    /// Starts ffmpeg for a camera of `width` × `height` at `fps`, its input `kind`.
    pub fn start(
        ffmpeg: &Path,
        files: &EpisodeFiles,
        kind: InputKind,
        width: u32,
        height: u32,
        fps: u32,
    ) -> Result<Self, String> {
        let log = File::create(&files.log).map_err(|e| format!("{}: {e}", files.log.display()))?;
        let fps_s = fps.to_string();
        let size = format!("{width}x{height}");
        let mut cmd = Command::new(ffmpeg);
        cmd.args(["-hide_banner", "-nostdin", "-nostats", "-loglevel", "error"]);
        match kind {
            InputKind::Jpeg => cmd.args(["-f", "mjpeg", "-framerate", &fps_s]),
            InputKind::Rgb24 => cmd.args([
                "-f",
                "rawvideo",
                "-pix_fmt",
                "rgb24",
                "-video_size",
                &size,
                "-framerate",
                &fps_s,
            ]),
        };
        let (g, crf, preset) = (GOP.to_string(), CRF.to_string(), PRESET.to_string());
        cmd.args([
            "-i", "pipe:0", "-map", "0:v", "-c:v", VCODEC, "-pix_fmt", PIX_FMT,
        ])
        .args(["-g", &g, "-crf", &crf, "-preset", &preset])
        .args([
            "-svtav1-params",
            "fast-decode=0",
            "-fps_mode",
            "passthrough",
        ])
        .args(["-f", "mp4", "-y"])
        .arg(&files.video)
        .args(["-map", "0:v", "-f", "rawvideo", "-pix_fmt", "rgb24"])
        .args(["-fps_mode", "passthrough", "pipe:1"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::from(log));
        let mut child = cmd
            .spawn()
            .map_err(|e| format!("cannot run {}: {e}", ffmpeg.display()))?;
        let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            let _ = child.kill();
            let _ = child.wait();
            return Err("ffmpeg's pipes were not opened".into());
        };
        // one second of frames may wait for ffmpeg; push is refused beyond (has_room), so
        // it never blocks
        let capacity = fps.max(1) as usize;
        let (tx, rx) = sync_channel::<Vec<u8>>(capacity);
        let queued = Arc::new(AtomicUsize::new(0));
        let q = queued.clone();
        let writer = std::thread::Builder::new()
            .name("ffmpeg-in".into())
            .spawn(move || feed(stdin, rx, q));
        let counts = files.counts.clone();
        let (w, h) = (width as usize, height as usize);
        let reader = std::thread::Builder::new()
            .name("ffmpeg-out".into())
            .spawn(move || count_pixels(stdout, &counts, w, h));
        let (writer, reader) = match (writer, reader) {
            (Ok(a), Ok(b)) => (a, b),
            _ => {
                let _ = child.kill();
                let _ = child.wait();
                return Err("cannot start the threads feeding ffmpeg".into());
            }
        };
        Ok(Encoder {
            child,
            queue: Some(tx),
            queued,
            capacity,
            writer: Some(writer),
            reader: Some(reader),
            kind,
            log: files.log.clone(),
        })
    }

    /// How this episode's frames reach ffmpeg.
    pub fn kind(&self) -> InputKind {
        self.kind
    }

    /// Frames queued for ffmpeg and not yet written to it.
    pub fn behind(&self) -> usize {
        self.queued.load(Ordering::Acquire)
    }

    /// Whether [`Encoder::push`] can queue a frame (less than a second of frames waits).
    pub fn has_room(&self) -> bool {
        self.behind() < self.capacity
    }

    /// Queues a frame (call [`Encoder::has_room`] first: a full queue would block); an
    /// error if ffmpeg has stopped.
    pub fn push(&mut self, image: Image<'_>) -> Result<(), String> {
        let q = self.queue.as_ref().ok_or("the encoder is closed")?;
        self.queued.fetch_add(1, Ordering::AcqRel);
        if q.send(image.to_input()).is_err() {
            // the writer thread ended: ffmpeg stopped reading
            let why = self.stop_reason();
            self.queue = None;
            return Err(why);
        }
        Ok(())
    }

    fn stop_reason(&mut self) -> String {
        let status = self.child.wait().ok();
        let err = self
            .writer
            .take()
            .and_then(|w| w.join().ok())
            .and_then(|r| r.err())
            .unwrap_or_default();
        format!(
            "ffmpeg stopped ({}; {err}): {}",
            status.map_or("not waited for".to_string(), |s| s.to_string()),
            log_tail(&self.log)
        )
    }

    /// Closes the input, waits for ffmpeg to finish the file; returns the frames it
    /// decoded (and counted).
    pub fn finish(mut self) -> Result<u64, String> {
        self.queue = None; // the writer thread ends once the queue is written
        let fed = self
            .writer
            .take()
            .map(|w| {
                w.join()
                    .unwrap_or(Err("the feeding thread panicked".into()))
            })
            .unwrap_or(Ok(()));
        let status = self
            .child
            .wait()
            .map_err(|e| format!("waiting for ffmpeg: {e}"))?;
        let counted = self
            .reader
            .take()
            .map(|r| {
                r.join()
                    .unwrap_or(Err("the reading thread panicked".into()))
            })
            .unwrap_or(Ok(0));
        if !status.success() {
            return Err(format!("ffmpeg failed ({status}): {}", log_tail(&self.log)));
        }
        fed?;
        counted
    }
}

impl Drop for Encoder {
    fn drop(&mut self) {
        // never outlive the writer: kill, reap, let the threads see the pipes close
        if self.writer.is_some() || self.reader.is_some() {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
        self.queue = None;
        if let Some(w) = self.writer.take() {
            let _ = w.join();
        }
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
    }
}

/// What ffprobe says of an mp4's first video stream.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Probe {
    pub codec: String,
    pub pix_fmt: String,
    pub width: u64,
    pub height: u64,
    pub fps: u64,
    pub frames: u64,
    /// The stream's duration in seconds, as PyAV computes it (`duration * time_base`).
    pub duration_s: f64,
}

fn ratio(s: &str) -> Option<(u64, u64)> {
    let (a, b) = s.split_once('/')?;
    Some((a.parse().ok()?, b.parse().ok()?))
}

/// ffprobe beside `ffmpeg` (the same Debian package).
fn ffprobe_of(ffmpeg: &Path) -> PathBuf {
    ffmpeg.with_file_name("ffprobe")
}

pub(crate) fn probe(ffmpeg: &Path, mp4: &Path) -> Result<Probe, String> {
    let ffprobe = ffprobe_of(ffmpeg);
    let out = Command::new(&ffprobe)
        .args(["-v", "error", "-select_streams", "v:0", "-show_entries"])
        .arg("stream=codec_name,pix_fmt,width,height,r_frame_rate,time_base,duration_ts,nb_frames")
        .args(["-of", "json"])
        .arg(mp4)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot run {}: {e}", ffprobe.display()))?;
    if !out.status.success() {
        return Err(format!(
            "ffprobe {}: {}",
            mp4.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    let v: Value = serde_json::from_slice(&out.stdout).map_err(|e| format!("ffprobe: {e}"))?;
    let s = v
        .get("streams")
        .and_then(|s| s.get(0))
        .ok_or_else(|| format!("{}: no video stream", mp4.display()))?;
    let text = |k: &str| {
        s.get(k)
            .and_then(Value::as_str)
            .unwrap_or_default()
            .to_string()
    };
    let int = |k: &str| -> Option<u64> {
        let f = s.get(k)?;
        f.as_u64().or_else(|| f.as_str()?.parse().ok())
    };
    let bad = |what: &str| format!("{}: ffprobe gave no {what}", mp4.display());
    let (tb_num, tb_den) = ratio(&text("time_base")).ok_or_else(|| bad("time_base"))?;
    let (fr_num, fr_den) = ratio(&text("r_frame_rate")).ok_or_else(|| bad("r_frame_rate"))?;
    let duration_ts = int("duration_ts").ok_or_else(|| bad("duration_ts"))?;
    Ok(Probe {
        codec: text("codec_name"),
        pix_fmt: text("pix_fmt"),
        width: int("width").ok_or_else(|| bad("width"))?,
        height: int("height").ok_or_else(|| bad("height"))?,
        fps: fr_num.checked_div(fr_den).unwrap_or(0),
        frames: int("nb_frames").ok_or_else(|| bad("nb_frames"))?,
        // float(Fraction(duration_ts * num, den)): exact integers, one rounding
        duration_s: (duration_ts * tb_num) as f64 / tb_den as f64,
    })
}

/// lerobot's `concatenate_video_files`: `first` then `second` remuxed (no re-encoding)
/// into `out` with `+faststart`, through ffmpeg's concat demuxer. `second` starts at
/// `first_duration_s`, `first`'s stream duration: without it the demuxer starts it at
/// `first`'s container duration, which MP4 keeps in milliseconds (60.434 s for 1813
/// frames at 30 fps, 60.4333 s), and the episode's frames would sit up to 1 ms off its
/// `from_timestamp`, beyond lerobot's 1e-4 s tolerance.
pub(crate) fn concatenate(
    ffmpeg: &Path,
    first: &Path,
    first_duration_s: f64,
    second: &Path,
    out: &Path,
    list: &Path,
) -> Result<(), String> {
    let quote = |p: &Path| -> Result<String, String> {
        let abs = fs::canonicalize(p).map_err(|e| format!("{}: {e}", p.display()))?;
        Ok(format!(
            "file '{}'\n",
            abs.to_string_lossy().replace('\'', r"'\''")
        ))
    };
    let body = format!(
        "ffconcat version 1.0\n{}duration {first_duration_s:.6}\n{}",
        quote(first)?,
        quote(second)?
    );
    fs::write(list, body).map_err(|e| format!("{}: {e}", list.display()))?;
    let out_run = Command::new(ffmpeg)
        .args(["-hide_banner", "-nostdin", "-loglevel", "error"])
        .args(["-f", "concat", "-safe", "0", "-i"])
        .arg(list)
        .args([
            "-map",
            "0",
            "-c",
            "copy",
            "-movflags",
            "+faststart",
            "-f",
            "mp4",
            "-y",
        ])
        .arg(out)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot run {}: {e}", ffmpeg.display()));
    let _ = fs::remove_file(list);
    let out_run = out_run?;
    if !out_run.status.success() {
        let _ = fs::remove_file(out);
        return Err(format!(
            "concatenating {} and {}: {}",
            first.display(),
            second.display(),
            String::from_utf8_lossy(&out_run.stderr).trim()
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jpeg_size_from_sof() {
        // SOI, APP0 (length 4: two bytes of payload), SOF0 640x480
        let jpeg = [
            0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x04, 0x00, 0x00, 0xFF, 0xC0, 0x00, 0x11, 0x08, 0x01,
            0xE0, 0x02, 0x80, 0x03,
        ];
        assert_eq!(jpeg_size(&jpeg), Ok((640, 480)));
        assert!(jpeg_size(b"PNG").is_err());
        assert!(jpeg_size(&jpeg[..10]).is_err());
        assert!(jpeg_size(&[0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x01]).is_err());
    }

    #[test]
    fn raw_pixels_become_packed_rgb() {
        // 2x2 bgr8 with 2 bytes of padding per row
        let data = [1, 2, 3, 4, 5, 6, 0, 0, 7, 8, 9, 10, 11, 12, 0, 0];
        let img = Image::Raw {
            encoding: RawEncoding::Bgr8,
            width: 2,
            height: 2,
            step: 8,
            data: &data,
        };
        assert_eq!(img.check(2, 2), Ok(InputKind::Rgb24));
        assert_eq!(img.to_input(), vec![3, 2, 1, 6, 5, 4, 9, 8, 7, 12, 11, 10]);
        let mono = Image::Raw {
            encoding: RawEncoding::Mono8,
            width: 2,
            height: 1,
            step: 2,
            data: &[9, 200],
        };
        assert_eq!(mono.to_input(), vec![9, 9, 9, 200, 200, 200]);
        assert!(img.check(3, 2).unwrap_err().contains("expected 3x2"));
        let short = Image::Raw {
            encoding: RawEncoding::Rgb8,
            width: 2,
            height: 2,
            step: 6,
            data: &data[..11],
        };
        assert!(short.check(2, 2).unwrap_err().contains("12 needed"));
        assert_eq!(RawEncoding::from_ros("bgr8"), Some(RawEncoding::Bgr8));
        assert_eq!(RawEncoding::from_ros("yuv422"), None);
    }
}
