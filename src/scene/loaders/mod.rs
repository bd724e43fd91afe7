//! Mesh file loaders (PLY ASCII/binary, OBJ). Errors name the file and the line or byte offset.
//!
//! This module owns turning mesh files into a [`Mesh`]: choosing the format by extension
//! ([`load_mesh`]), parsing in-memory bytes ([`parse_ply`], [`parse_obj`]), and validating
//! everything the scene API would later reject (non-finite coordinates, out-of-range indices),
//! so that a bad file fails here with a message that points at the offending line or byte.
//!
//! Every loader treats its input as untrusted: no panics on any input, no allocation sized by
//! a header count before that count is checked against the bytes actually present.
//!
//! Both read LF or CRLF line endings and an optional UTF-8 byte-order mark; comments may be in
//! any encoding (exporters write Latin-1). Lines that end in a CR alone are refused as such.

use std::path::Path;

use glam::Vec3;

use crate::error::{Error, Result, Rt2Status};
use crate::fallible;

mod obj;
mod ply;

pub use obj::parse_obj;
pub use ply::parse_ply;

/// A triangle mesh as read from a file: positions and triangles (polygons fan-triangulated).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

/// Loads a `.ply` or `.obj` file (extension matched case-insensitively).
///
/// The format is chosen by extension rather than by sniffing so that a mislabelled file fails
/// with a parse error of the format the user asked for, not a confusing guess.
///
/// Triangles follow the file's face order, polygons fan-triangulated in place (see
/// [`parse_ply`] / [`parse_obj`]), because ray sets identify triangles by face index.
///
/// Errors: `Unsupported` for other extensions, `Io` when the file cannot be read or is not a
/// regular file (the message names the path and the OS error or the file's type),
/// `OutOfMemory` when its bytes cannot be allocated, `Parse` for malformed content.
pub fn load_mesh(path: &Path) -> Result<Mesh> {
    let name = path.display().to_string();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let parse: fn(&[u8], &str) -> Result<Mesh> = match ext.as_deref() {
        Some("ply") => parse_ply,
        Some("obj") => parse_obj,
        _ => {
            return Err(Error::unsupported(format!(
                "{name}: unsupported mesh file extension (supported: .ply, .obj)"
            )))
        }
    };
    let bytes = read_regular_file(path, &name)?;
    parse(&bytes, &name)
}

/// Reads a whole regular file, refusing anything else (FIFO, socket, device, directory) with
/// an `Io` error.
///
/// `std::fs::read` would hang forever on a FIFO without a writer (even its `open` blocks) and
/// read `/dev/zero` until memory runs out; a path under the caller's control may be either, or
/// a symlink to one. So the path is checked before opening, opened non-blocking on Unix (a FIFO
/// swapped in after the check then cannot block the open), checked again
/// through the open handle (the file actually read), and read no further than the size that
/// handle reported, so a file growing while it is read cannot make the read unbounded.
/// Failing to allocate that size is `OutOfMemory`, not an abort.
fn read_regular_file(path: &Path, name: &str) -> Result<Vec<u8>> {
    use std::io::Read;
    let io = |e: std::io::Error| Error::io(format!("{name}: cannot read file: {e}"));
    let not_regular = |meta: &std::fs::Metadata| {
        Error::io(format!(
            "{name}: cannot read file: not a regular file (it is a {})",
            file_kind(&meta.file_type())
        ))
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path).map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    let len = usize::try_from(meta.len()).map_err(|_| {
        Error::out_of_memory(format!(
            "{name}: the file ({} bytes) does not fit in memory",
            meta.len()
        ))
    })?;
    let mut bytes = fallible::with_capacity(len).map_err(|_| {
        Error::out_of_memory(format!(
            "{name}: cannot allocate {len} bytes to read the file"
        ))
    })?;
    file.take(meta.len()).read_to_end(&mut bytes).map_err(io)?;
    Ok(bytes)
}

/// Names a file type for the "not a regular file" error.
fn file_kind(t: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "FIFO";
        }
        if t.is_char_device() {
            return "character device";
        }
        if t.is_block_device() {
            return "block device";
        }
        if t.is_socket() {
            return "socket";
        }
    }
    if t.is_dir() {
        "directory"
    } else {
        "special file"
    }
}

/// Shows a token from the file in an error message: quoted, control characters escaped (so
/// binary garbage stays readable) and cut to a sensible length (a garbage "token" can be huge).
struct Quoted<'a>(&'a str);

impl std::fmt::Display for Quoted<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        const MAX_CHARS: usize = 40;
        let mut chars = self.0.chars();
        let head: String = chars.by_ref().take(MAX_CHARS).collect();
        let more = if chars.next().is_some() { "..." } else { "" };
        write!(f, "'{}{more}'", head.escape_debug())
    }
}

/// What some editors write at the start of a UTF-8 file.
const UTF8_BOM: &[u8] = b"\xef\xbb\xbf";

/// `result` of parsing `text`, with a parse error on the first line replaced by one naming
/// the cause when that line holds a CR before its end: lines that end in a CR alone (classic
/// Mac OS), which both loaders, splitting lines at LF, read as one long line whose error named
/// the wrong cause. Only on failure, and only an error on the first line: a file that parses
/// (CR CR LF endings, a CR in a comment) is kept, and so is an error further down a file whose
/// first line merely holds a stray CR (a bad index on line 5 is reported as such).
fn cr_line_ends(result: Result<Mesh>, text: &[u8], name: &str) -> Result<Mesh> {
    result.map_err(|e| {
        let first = text.split(|&b| b == b'\n').next().unwrap_or_default();
        let first = first.strip_suffix(b"\r").unwrap_or(first);
        let on_first_line = e.message.starts_with(&line_error(name, 1, "").message);
        match e.status {
            Rt2Status::Parse if on_first_line && first.contains(&b'\r') => Error::parse(format!(
                "{name}: the lines end in a CR alone (classic Mac OS line endings): convert \
                 the file to LF or CRLF line endings"
            )),
            _ => e,
        }
    })
}

/// A parse error located at a 1-based line of a text file (or of a PLY header).
fn line_error(name: &str, line: usize, msg: impl std::fmt::Display) -> Error {
    Error::parse(format!("{name}: line {line}: {msg}"))
}

/// A parse error located at a byte offset of a binary PLY body (offset from file start).
fn offset_error(name: &str, offset: usize, msg: impl std::fmt::Display) -> Error {
    Error::parse(format!("{name}: byte offset {offset}: {msg}"))
}

/// Converts a coordinate to `f32`, rejecting NaN/inf (also values that overflow `f32`),
/// because the scene API refuses non-finite coordinates and the file is the place to say why.
fn finite_coord(value: f64, axis: usize) -> std::result::Result<f32, String> {
    let v = value as f32;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!(
            "coordinate {} is not a finite f32 ({value})",
            ["x", "y", "z"][axis.min(2)]
        ))
    }
}
