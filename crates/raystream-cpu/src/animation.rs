//! Animations: a turntable's, a slice series' or a cine's 8-bit sRGB frames as one animated
//! PNG (APNG: lossless, 24-bit) or GIF (256 colours a frame), written frame by frame as the
//! frames are rendered, so that a long series is never held whole in memory.
//!
//! The containers are the `png` crate's APNG encoder and the `gif` crate's encoder (each frame
//! quantised by NeuQuant to its own palette); this module only sizes the delays, encodes on a
//! thread of its own while the next frame renders, and keeps a half-written file from being
//! left behind.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::pipeline::Pipeline;

/// The animation's container.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AnimationKind {
    /// Animated PNG: every frame's pixels exactly; browsers and most viewers play it, and a
    /// viewer that does not shows the first frame.
    Apng,
    /// GIF: plays everywhere, but each frame is cut to its own 256 colours, and delays are
    /// kept in hundredths of a second.
    Gif,
}

impl AnimationKind {
    /// The file name's extension for this container.
    pub fn extension(self) -> &'static str {
        match self {
            AnimationKind::Apng => "png",
            AnimationKind::Gif => "gif",
        }
    }

    /// The container's name, as `--format` takes it.
    pub fn name(self) -> &'static str {
        match self {
            AnimationKind::Apng => "apng",
            AnimationKind::Gif => "gif",
        }
    }

    /// The frame rate a player shows for `fps` frames a second asked: a GIF's delay is a whole
    /// number of hundredths of a second (the nearest), an APNG's the exact fraction 1/`fps`.
    pub fn played_fps(self, fps: u32) -> f64 {
        match self {
            AnimationKind::Apng => fps as f64,
            AnimationKind::Gif => 100.0 / gif_delay_cs(fps) as f64,
        }
    }
}

/// The most frames a second either container plays faithfully: browsers show a GIF delay under
/// 2/100 s as 1/10 s.
pub const MAX_FPS: u32 = 50;

/// GIF quantisation speed (1 best and slowest, 30 fastest): 10 is the `gif` crate's
/// recommendation, a few ms a megapixel.
const GIF_SPEED: i32 = 10;

fn gif_delay_cs(fps: u32) -> u32 {
    ((100.0 / fps as f64).round() as u32).max(2)
}

enum Encoder {
    Apng(png::Writer<BufWriter<File>>),
    Gif(gif::Encoder<BufWriter<File>>),
}

impl Encoder {
    /// Writes one frame, checked already to hold `width`×`height` RGB pixels.
    fn write(
        &mut self,
        rgb: &[u8],
        (width, height): (u32, u32),
        delay_cs: u32,
    ) -> Result<(), String> {
        match self {
            Encoder::Apng(w) => w
                .write_image_data(rgb)
                .map_err(|e| format!("cannot write APNG frame: {e}")),
            Encoder::Gif(e) => {
                let mut frame =
                    gif::Frame::from_rgb_speed(width as u16, height as u16, rgb, GIF_SPEED);
                frame.delay = delay_cs as u16;
                e.write_frame(&frame)
                    .map_err(|e| format!("cannot write GIF frame: {e}"))
            }
        }
    }

    /// Ends the file.
    fn finish(self) -> Result<(), String> {
        match self {
            Encoder::Apng(w) => w.finish().map_err(|e| format!("cannot write APNG: {e}")),
            Encoder::Gif(e) => e
                .into_inner()
                .map_err(|e| format!("cannot write GIF: {e}"))
                .and_then(|w| {
                    w.into_inner()
                        .map_err(|e| format!("cannot write GIF: {}", e.error()))
                        .map(drop)
                }),
        }
    }
}

/// The zlib level of an APNG's frames: 3, not the `png` crate's default 6, which took 4× the
/// time on 1024² CT slices (147 against 40 ms a frame) and 2× on volume renderings (56 against
/// 24 ms) for files 3–4 % smaller (BENCHMARKS.md, "APNG frames deflated at level 3"); its
/// fastest mode (fdeflate) made slices' frames twice as large.
const APNG_DEFLATE_LEVEL: u8 = 3;

/// The encoder thread's work: frame `i`'s pixels written, the frame named in an error.
fn encode(
    size: (u32, u32),
    delay_cs: u32,
) -> impl FnMut(&mut Encoder, Vec<u8>, usize) -> Result<(), String> + Send + 'static {
    move |encoder, rgb, i| {
        encoder
            .write(&rgb, size, delay_cs)
            .map_err(|e| format!("frame {i}: {e}"))
    }
}

/// An animation being written: [`AnimationWriter::push`] each frame in order, then
/// [`AnimationWriter::finish`]. Frames are encoded on a thread of their own (a
/// [`Pipeline`]: a GIF frame's quantisation takes ≈ 80 ms a megapixel, more than a GPU's
/// frame). Dropped unfinished (an error while rendering), it removes its file.
pub struct AnimationWriter {
    path: PathBuf,
    kind: AnimationKind,
    width: u32,
    height: u32,
    frames: u32,
    written: u32,
    encoder: Option<Pipeline<Vec<u8>, Encoder>>,
}

impl AnimationWriter {
    /// Creates `path` for `frames` frames of `width`×`height` at `fps` frames a second (1 to
    /// [`MAX_FPS`]), looping forever.
    pub fn create(
        path: &Path,
        kind: AnimationKind,
        (width, height): (u32, u32),
        frames: u32,
        fps: u32,
    ) -> Result<Self, String> {
        let name = path.display();
        if !(1..=MAX_FPS).contains(&fps) {
            return Err(format!(
                "{name}: {fps} frames a second; an animation plays 1 to {MAX_FPS}"
            ));
        }
        if frames == 0 || width == 0 || height == 0 {
            return Err(format!(
                "{name}: an animation of {frames} frames of {width}x{height}"
            ));
        }
        // GIF's logical screen is 16-bit.
        if kind == AnimationKind::Gif && (width > 65535 || height > 65535) {
            return Err(format!(
                "{name}: a GIF is at most 65535 pixels a side, not {width}x{height}"
            ));
        }
        let file = File::create(path).map_err(|e| format!("{name}: cannot create: {e}"))?;
        let w = BufWriter::new(file);
        let mut writer = AnimationWriter {
            path: path.to_path_buf(),
            kind,
            width,
            height,
            frames,
            written: 0,
            encoder: None,
        };
        let encoder = match kind {
            AnimationKind::Apng => {
                let mut e = png::Encoder::new(w, width, height);
                e.set_color(png::ColorType::Rgb);
                e.set_depth(png::BitDepth::Eight);
                e.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
                e.set_deflate_compression(png::DeflateCompression::Level(APNG_DEFLATE_LEVEL));
                let fps = u16::try_from(fps).expect("at most MAX_FPS");
                e.set_animated(frames, 0)
                    .and_then(|_| e.set_frame_delay(1, fps))
                    .map_err(|e| format!("{name}: cannot write APNG: {e}"))?;
                Encoder::Apng(
                    e.write_header()
                        .map_err(|e| format!("{name}: cannot write APNG: {e}"))?,
                )
            }
            AnimationKind::Gif => {
                let side = |v: u32| u16::try_from(v).expect("checked above");
                let mut e = gif::Encoder::new(w, side(width), side(height), &[])
                    .map_err(|e| format!("{name}: cannot write GIF: {e}"))?;
                e.set_repeat(gif::Repeat::Infinite)
                    .map_err(|e| format!("{name}: cannot write GIF: {e}"))?;
                Encoder::Gif(e)
            }
        };
        writer.encoder = Some(Pipeline::spawn(
            encoder,
            encode((width, height), gif_delay_cs(fps)),
        ));
        Ok(writer)
    }

    /// Appends the next frame: 8-bit sRGB, 3 bytes a pixel, rows from the top (moved to the
    /// encoder's thread, copied only if borrowed). It is encoded while the caller goes on; an
    /// error of an earlier frame's encoding is returned here or by
    /// [`AnimationWriter::finish`].
    pub fn push(&mut self, rgb: impl Into<Vec<u8>>) -> Result<(), String> {
        let rgb = rgb.into();
        let name = self.path.display();
        let want = self.width as usize * self.height as usize * 3;
        if rgb.len() != want {
            return Err(format!(
                "{name}: frame {} holds {} bytes, not the {want} of {}x{} RGB",
                self.written,
                rgb.len(),
                self.width,
                self.height
            ));
        }
        if self.written == self.frames {
            return Err(format!("{name}: more than the {} frames", self.frames));
        }
        self.encoder
            .as_mut()
            .expect("open until finished")
            .send(rgb)
            .map_err(|e| format!("{name}: {e}"))?;
        self.written += 1;
        Ok(())
    }

    /// Ends the file once every frame is written.
    pub fn finish(mut self) -> Result<(), String> {
        let name = self.path.display().to_string();
        if self.written != self.frames {
            return Err(format!(
                "{name}: {} of the {} frames written",
                self.written, self.frames
            ));
        }
        let mut encoder = self.encoder.take().expect("open until finished");
        let result = encoder
            .finish()
            .and_then(Encoder::finish)
            .map_err(|e| format!("{name}: {e}"));
        if result.is_err() {
            let _ = std::fs::remove_file(&self.path);
        }
        result
    }

    /// The container being written.
    pub fn kind(&self) -> AnimationKind {
        self.kind
    }
}

impl Drop for AnimationWriter {
    fn drop(&mut self) {
        // Unfinished: what was written is not a whole animation. The encoder lets go of the
        // file before it is removed.
        if let Some(mut encoder) = self.encoder.take() {
            let _ = encoder.finish();
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::AnimationDecoder;
    use std::io::BufReader;

    /// Three frames that no palette of a few colours could mistake for each other: a
    /// gradient, its negative, and a gradient across the other way.
    fn frames(w: u32, h: u32) -> Vec<Vec<u8>> {
        (0..3)
            .map(|k| {
                let mut v = Vec::new();
                for y in 0..h {
                    for x in 0..w {
                        let a = (x * 255 / (w - 1)) as u8;
                        let b = (y * 255 / (h - 1)) as u8;
                        v.extend_from_slice(&match k {
                            0 => [a, b, 40],
                            1 => [255 - a, 255 - b, 200],
                            _ => [b, 90, a],
                        });
                    }
                }
                v
            })
            .collect()
    }

    /// `name` in a scratch folder of its own, removed with the folder when the test ends.
    fn tmp(name: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::Builder::new()
            .prefix("raystream-anim-")
            .tempdir()
            .unwrap();
        let path = dir.path().join(name);
        (dir, path)
    }

    /// A GIF's frames as RGB and their delays (1/100 s), checking that it loops forever.
    fn read_gif(path: &Path) -> Vec<(Vec<u8>, u16)> {
        let mut o = gif::DecodeOptions::new();
        o.set_color_output(gif::ColorOutput::RGBA);
        let mut d = o.read_info(File::open(path).unwrap()).unwrap();
        assert_eq!(d.repeat(), gif::Repeat::Infinite);
        let mut out = Vec::new();
        while let Some(f) = d.read_next_frame().unwrap() {
            let rgb = f
                .buffer
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            out.push((rgb, f.delay));
        }
        out
    }

    /// `frames` (each `size`) written to `path` as a `kind` animation at `fps`.
    fn write(path: &Path, kind: AnimationKind, size: (u32, u32), frames: &[Vec<u8>], fps: u32) {
        let n = frames.len() as u32;
        let mut a = AnimationWriter::create(path, kind, size, n, fps).unwrap();
        for f in frames {
            a.push(f.as_slice()).unwrap();
        }
        a.finish().unwrap();
    }

    fn rgb_of(f: &image::Frame) -> Vec<u8> {
        f.buffer()
            .pixels()
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect()
    }

    #[test]
    fn apng_keeps_every_frame_exactly_and_loops_at_the_asked_rate() {
        let (w, h) = (37, 23);
        let (_dir, path) = tmp("spin.png");
        let want = frames(w, h);
        write(&path, AnimationKind::Apng, (w, h), &want, 12);

        // The png crate's own reading of the container: three frames, endless loop.
        let mut d = png::Decoder::new(BufReader::new(File::open(&path).unwrap()))
            .read_info()
            .unwrap();
        let actl = d.info().animation_control.expect("an APNG");
        assert_eq!((actl.num_frames, actl.num_plays), (3, 0));
        let mut buf = vec![0; d.output_buffer_size().unwrap()];
        for f in &want {
            let info = d.next_frame(&mut buf).unwrap();
            assert_eq!(&buf[..info.buffer_size()], &f[..]);
            let fc = d.info().frame_control.unwrap();
            assert_eq!((fc.delay_num, fc.delay_den), (1, 12));
        }

        // And image's, which browsers' reading resembles: the same pixels, 1/12 s apart.
        let dec = image::codecs::png::PngDecoder::new(BufReader::new(File::open(&path).unwrap()))
            .unwrap()
            .apng()
            .unwrap();
        let got: Vec<_> = dec.into_frames().collect_frames().unwrap();
        assert_eq!(got.len(), 3);
        for (g, f) in got.iter().zip(&want) {
            assert_eq!(&rgb_of(g), f);
            let (n, d) = g.delay().numer_denom_ms();
            assert_eq!(n as f64 / d as f64, 1000.0 / 12.0);
        }
    }

    #[test]
    fn gif_frames_keep_their_colours_within_a_palette_and_their_delay() {
        let (w, h) = (256, 192);
        let (_dir, path) = tmp("spin.gif");
        let want = frames(w, h);
        write(&path, AnimationKind::Gif, (w, h), &want, 15);
        let got = read_gif(&path);
        assert_eq!(got.len(), 3);
        for ((g, _), f) in got.iter().zip(&want) {
            // 49,152 colours cut to 256: closer than a fixed palette of 6 levels a
            // channel (216 colours, the web's) would come.
            let mean = |g: &[u8]| {
                g.iter()
                    .zip(f)
                    .map(|(&x, &y)| x.abs_diff(y) as f64)
                    .sum::<f64>()
                    / g.len() as f64
            };
            let fixed: Vec<u8> = f
                .iter()
                .map(|&v| (v as f64 / 51.0).round() as u8 * 51)
                .collect();
            // (Measured: 4.9–5.2 against 9.8–12.5.)
            assert!(
                mean(g) < 0.6 * mean(&fixed),
                "{} vs {}",
                mean(g),
                mean(&fixed)
            );
        }
        // 1/15 s is kept as 7/100 s, as played_fps says.
        assert!(got.iter().all(|(_, delay)| *delay == 7));
        assert!((AnimationKind::Gif.played_fps(15) - 100.0 / 7.0).abs() < 1e-12);
        // The frames differ as the inputs do: no frame is a copy of another.
        assert_ne!(got[0].0, got[1].0);
    }

    #[test]
    fn a_gif_of_few_colours_keeps_them_exactly() {
        // A shaded ramp of one hue on black, as a surface under one light: 200 colours.
        let (w, h) = (200, 16);
        let f: Vec<u8> = (0..w * h)
            .flat_map(|i| {
                let k = (i % w) as f32 / (w - 1) as f32;
                [k * 241.0, k * 214.0, k * 180.0].map(|v| v as u8)
            })
            .collect();
        let (_dir, path) = tmp("ramp.gif");
        write(
            &path,
            AnimationKind::Gif,
            (w, h),
            std::slice::from_ref(&f),
            10,
        );
        let got = read_gif(&path);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, f);
        assert_eq!(got[0].1, 10);
    }

    #[test]
    fn an_unfinished_animation_leaves_no_file_and_bad_frames_are_refused() {
        let (_dir, path) = tmp("partial.png");
        let f = frames(8, 8);
        let mut a = AnimationWriter::create(&path, AnimationKind::Apng, (8, 8), 3, 10).unwrap();
        a.push(f[0].as_slice()).unwrap();
        let e = a.push(&f[1][..10]).unwrap_err();
        assert!(e.contains("partial.png") && e.contains("10 bytes"), "{e}");
        let e = a.finish().unwrap_err();
        assert!(e.contains("1 of the 3 frames"), "{e}");
        assert!(!path.exists(), "a half-written animation was left behind");

        let mut a = AnimationWriter::create(&path, AnimationKind::Gif, (8, 8), 1, 10).unwrap();
        a.push(f[0].as_slice()).unwrap();
        drop(a);
        assert!(!path.exists());

        // An encoder's error (here a file opened for reading) reaches the frames after it,
        // and the frame it happened on is named.
        let (_ro_dir, ro) = tmp("read-only.gif");
        std::fs::write(&ro, b"").unwrap();
        let e = gif::Encoder::new(BufWriter::new(File::open(&ro).unwrap()), 64, 64, &[]).unwrap();
        let mut encoder = Pipeline::spawn(Encoder::Gif(e), encode((64, 64), 10));
        let noise: Vec<u8> = (0..64 * 64 * 3u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8)
            .collect();
        let e = (0..50)
            .find_map(|_| encoder.send(noise.clone()).err())
            .expect("writes to a read-only file fail");
        assert!(
            e.starts_with("frame ") && e.contains("cannot write GIF frame"),
            "{e}"
        );
        assert_eq!(encoder.send(noise).unwrap_err(), crate::pipeline::STOPPED);

        for fps in [0, MAX_FPS + 1] {
            let e = AnimationWriter::create(&path, AnimationKind::Gif, (8, 8), 1, fps)
                .err()
                .unwrap();
            assert!(e.contains("frames a second"), "{e}");
        }
        assert!(!path.exists());
    }
}
