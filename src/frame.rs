//! Frames: RGBA8 images, row-major from the top-left, with an optional HUD mask of pixels
//! that are not traced at all (their contents are left as they were).

use crate::error::{Error, Result};
use crate::fallible;
use std::path::Path;

#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    width: u32,
    height: u32,
    pixels: Vec<u8>,
    mask: Option<Vec<u8>>,
}

/// Largest accepted side: keeps `width * height * 4` far from overflow and allocations sane.
pub const MAX_SIDE: u32 = 1 << 15;

impl Frame {
    pub fn new(width: u32, height: u32) -> Result<Self> {
        if width == 0 || height == 0 {
            return Err(Error::invalid_argument(format!(
                "frame size {width}x{height} is empty"
            )));
        }
        if width > MAX_SIDE || height > MAX_SIDE {
            return Err(Error::invalid_argument(format!(
                "frame size {width}x{height} exceeds the maximum side of {MAX_SIDE}"
            )));
        }
        let len = (width as usize) * (height as usize) * 4;
        let pixels = fallible::filled(0, len)
            .map_err(|_| Error::out_of_memory(format!("{len} bytes for the frame")))?;
        Ok(Frame {
            width,
            height,
            pixels,
            mask: None,
        })
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    pub fn pixels(&self) -> &[u8] {
        &self.pixels
    }

    pub fn pixels_mut(&mut self) -> &mut [u8] {
        &mut self.pixels
    }

    /// Pixels and mask together, for renderers that skip masked pixels while writing.
    pub fn pixels_and_mask_mut(&mut self) -> (&mut [u8], Option<&[u8]>) {
        (&mut self.pixels, self.mask.as_deref())
    }

    /// `mask` has one byte per pixel; 0 means "do not trace". `None` clears the mask.
    pub fn set_mask(&mut self, mask: Option<&[u8]>) -> Result<()> {
        if let Some(m) = mask {
            if m.len() != self.pixel_count() {
                return Err(Error::invalid_argument(format!(
                    "mask has {} bytes, the frame {} pixels",
                    m.len(),
                    self.pixel_count()
                )));
            }
        }
        // A byte per pixel, up to 1 GiB at the largest frame: refused as OUT_OF_MEMORY, like
        // the frame itself, rather than aborting.
        self.mask = match mask {
            Some(m) => Some(fallible::copied(m).map_err(|_| {
                Error::out_of_memory(format!("{} bytes for the frame's mask", m.len()))
            })?),
            None => None,
        };
        Ok(())
    }

    /// Writes the frame as a PNG at `path`, which [`check_png_path`] must accept.
    pub fn save_png(&self, path: &Path) -> Result<()> {
        use image::ImageEncoder;
        check_png_path(path)?;
        let io =
            |e: &dyn std::fmt::Display| Error::io(format!("cannot write {}: {e}", path.display()));
        let file = create_for_writing(path).map_err(|e| io(&e))?;
        let mut out = std::io::BufWriter::new(file);
        image::codecs::png::PngEncoder::new(&mut out)
            .write_image(
                &self.pixels,
                self.width,
                self.height,
                image::ExtendedColorType::Rgba8,
            )
            .map_err(|e| io(&e))?;
        // `image::save_buffer` let the BufWriter flush on drop, which discards the error: a
        // PNG under 8 KiB written to a full disk returned OK. Flush and check it here.
        out.into_inner().map_err(|e| io(e.error()))?;
        Ok(())
    }
}

/// Opens `path` for writing as `File::create` does, except that a FIFO no process reads is
/// an error rather than an open that blocks until a reader comes, perhaps never. On Unix the
/// open is non-blocking (for a FIFO without a reader it fails with `ENXIO`; a regular file or
/// a device opens as usual), and the handle is made blocking again, so that writes to a
/// FIFO that is read wait for the reader as any writer's do.
fn create_for_writing(path: &Path) -> std::io::Result<std::fs::File> {
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::fd::AsRawFd;
        use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
        options.custom_flags(libc::O_NONBLOCK);
        let file = options.open(path).map_err(|e| {
            // ENXIO also comes from a socket or a device without its hardware: said only of
            // a FIFO.
            let fifo = e.raw_os_error() == Some(libc::ENXIO)
                && std::fs::metadata(path).is_ok_and(|m| m.file_type().is_fifo());
            if fifo {
                std::io::Error::new(e.kind(), "a FIFO that no process reads")
            } else {
                e
            }
        })?;
        let fd = file.as_raw_fd();
        // SAFETY: `fd` is the open file's descriptor, alive as long as `file`; F_GETFL and
        // F_SETFL read and set its status flags only.
        let cleared = unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            flags >= 0 && libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK) == 0
        };
        if !cleared {
            return Err(std::io::Error::last_os_error());
        }
        Ok(file)
    }
    #[cfg(not(unix))]
    options.open(path)
}

/// Whether a PNG can be written at `path`, checked before any work is done (the CLI checks its
/// `-o` before rendering): the name ends in `.png` (any case), it is not a directory, and its
/// folder exists. `Io` errors name the path; the write itself can still fail (permissions).
pub fn check_png_path(path: &Path) -> Result<()> {
    let is_png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png {
        return Err(Error::invalid_argument(format!(
            "{}: the output must be a .png file",
            path.display()
        )));
    }
    if path.is_dir() {
        return Err(Error::io(format!("{}: is a directory", path.display())));
    }
    let folder = path.parent().filter(|p| !p.as_os_str().is_empty());
    if folder.is_some_and(|f| !f.is_dir()) {
        return Err(Error::io(format!(
            "{}: its folder does not exist",
            path.display()
        )));
    }
    Ok(())
}
