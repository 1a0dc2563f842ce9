//! [`GifWriter`]: an animated GIF of a fit's progress, written into a temporary file and
//! renamed into place when finished.

use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use image::RgbaImage;

use crate::error::{Error, Result};
use crate::io::AtomicFile;

/// An animated GIF of a fit's progress, written frame by frame into a temporary file beside
/// the target and renamed into place by [`GifWriter::finish`]. Dropped unfinished (an error, an
/// interrupted fit), it leaves nothing behind.
///
/// Frames loop forever. A frame with at most 256 colours (a contact sheet has 8) keeps its
/// exact colours; others are quantized to 256 (NeuQuant).
pub struct GifWriter {
    // Declared before `file`, so it is dropped (and lets go of the temporary file) first.
    encoder: gif::Encoder<BufWriter<File>>,
    file: AtomicFile,
    width: u32,
    height: u32,
    delay_cs: u16,
    frames: usize,
}

impl GifWriter {
    /// Starts a GIF of `width × height` frames (each 1 to 65535, GIF's limit), shown
    /// `delay_ms` each: rounded to GIF's unit of 10 ms, and at least 20 ms, since browsers show
    /// shorter delays as 100 ms.
    pub fn create(path: &Path, width: u32, height: u32, delay_ms: u32) -> Result<GifWriter> {
        let dims = (u16::try_from(width), u16::try_from(height));
        let (Ok(w), Ok(h)) = dims else {
            return Err(Error::Input(format!(
                "GIF {}: {width}×{height} frames exceed GIF's 65535 × 65535",
                path.display()
            )));
        };
        if w == 0 || h == 0 {
            return Err(Error::Input(format!(
                "GIF {}: {width}×{height} frames are empty",
                path.display()
            )));
        }
        let mut file = AtomicFile::create(path)?;
        let sink = BufWriter::new(file.take_file());
        let mut encoder = gif::Encoder::new(sink, w, h, &[]).map_err(|e| gif_error(&file, e))?;
        encoder
            .set_repeat(gif::Repeat::Infinite)
            .map_err(|e| gif_error(&file, e))?;
        let delay_cs = (delay_ms.saturating_add(5) / 10).clamp(2, u32::from(u16::MAX)) as u16;
        Ok(GifWriter {
            encoder,
            file,
            width,
            height,
            delay_cs,
            frames: 0,
        })
    }

    /// Appends a frame; it must have the size given to [`GifWriter::create`].
    pub fn push(&mut self, frame: &RgbaImage) -> Result<()> {
        if frame.dimensions() != (self.width, self.height) {
            return Err(Error::Input(format!(
                "GIF {}: a {}×{} frame in a {}×{} animation",
                self.file.target().display(),
                frame.width(),
                frame.height(),
                self.width,
                self.height
            )));
        }
        let mut rgba = frame.as_raw().clone();
        // Speed 10 of 1..=30, gif's default: only used past 256 colours.
        let mut f =
            gif::Frame::from_rgba_speed(self.width as u16, self.height as u16, &mut rgba, 10);
        f.delay = self.delay_cs;
        f.dispose = gif::DisposalMethod::Keep;
        self.encoder
            .write_frame(&f)
            .map_err(|e| gif_error(&self.file, e))?;
        self.frames += 1;
        Ok(())
    }

    /// Frames pushed so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Ends the GIF and moves it into place. With no frame pushed, fails and writes nothing.
    pub fn finish(self) -> Result<()> {
        let GifWriter {
            encoder,
            file,
            frames,
            ..
        } = self;
        if frames == 0 {
            return Err(Error::Input(format!(
                "GIF {}: no frame to write",
                file.target().display()
            )));
        }
        let sink = encoder.into_inner().map_err(|e| gif_error(&file, e))?;
        let inner = sink.into_inner().map_err(|e| file.io(e.into_error()))?;
        file.persist(inner)
    }
}

fn gif_error(file: &AtomicFile, e: gif::EncodingError) -> Error {
    match e {
        gif::EncodingError::Io(e) => file.io(e),
        e => Error::Input(format!("GIF {}: {e}", file.target().display())),
    }
}

impl std::fmt::Debug for GifWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GifWriter")
            .field("target", &self.file.target())
            .field("width", &self.width)
            .field("height", &self.height)
            .field("frames", &self.frames)
            .finish()
    }
}
