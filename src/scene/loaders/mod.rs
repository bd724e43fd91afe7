//! Mesh file loaders (PLY ASCII/binary, OBJ). Errors name the file and the line or byte offset.
//!
//! This module owns turning mesh files into a [`Mesh`]: choosing the format by extension
//! ([`load_mesh`]), parsing in-memory bytes ([`parse_ply`], [`parse_obj`]), and validating
//! everything the scene API would later reject (non-finite coordinates, out-of-range indices),
//! so that a bad file fails here with a message that points at the offending line or byte.
//!
//! Every loader treats its input as untrusted: no panics on any input, no allocation sized by
//! a header count before that count is checked against the bytes actually present.

use std::path::Path;

use glam::Vec3;

use crate::error::{Error, Result};

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
/// Errors: `Unsupported` for other extensions, `Io` when the file cannot be read (the message
/// names the path and the OS error), `Parse` for malformed content.
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
    let bytes =
        std::fs::read(path).map_err(|e| Error::io(format!("{name}: cannot read file: {e}")))?;
    parse(&bytes, &name)
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
