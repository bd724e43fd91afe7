//! Wavefront OBJ parsing, limited to what a triangle mesh needs: `v` positions and `f`
//! polygons. Texture coordinates, normals, groups, smoothing and materials are ignored, and so
//! are points and lines, which have no surface for a ray to hit.
//!
//! Errors name the 1-based line.

use std::borrow::Cow;

use glam::Vec3;

use super::{cr_line_ends, finite_coord, line_error, Mesh, Quoted, UTF8_BOM};
use crate::error::{Error, Result};
use crate::fallible::TryGrow;

/// Parses an OBJ file held in memory; `name` is used in error messages.
///
/// Reads `v x y z`, `v x y z w` (w ignored) or `v x y z r g b` (a vertex colour, as MeshLab
/// and ZBrush write it; ignored) and `f` with vertex references of the forms `i`, `i/t`,
/// `i//n`, `i/t/n`; only `i` is used. Indices are 1-based; negative ones count back from the
/// last vertex defined so far, and a positive one must refer to a vertex already defined
/// (the OBJ rule, which lets every index be checked on its own line). Triangles follow the
/// file's face order, each polygon of n vertices fan-triangulated in place into n-2 triangles
/// `(v0, v(k), v(k+1))`.
///
/// Ignored statements: `vt`, `vn`, `vp`, `g`, `o`, `s`, `mg`, `usemtl`, `mtllib`, the other
/// render attributes (`usemap`, `maplib`, `lod`, `bevel`, `c_interp`, `d_interp`,
/// `shadow_obj`, `trace_obj`: how surfaces are drawn, not surfaces), points `p`
/// and lines `l` (Blender writes loose edges so; they have no surface), comments and blank
/// lines; CRLF line endings and a UTF-8 byte-order mark are accepted, a line ending in `\`
/// outside a comment continues on the next (errors name its first line), and bytes that are
/// not UTF-8 are only an error where a number is expected. Any other statement is an error, so
/// that a file that is not OBJ (or uses features this loader would silently drop, like curved
/// surfaces) is reported rather than half-loaded. A file without faces is an error too.
pub fn parse_obj(text_bytes: &[u8], name: &str) -> Result<Mesh> {
    cr_line_ends(parse(text_bytes, name), text_bytes, name)
}

/// [`parse_obj`] but for naming CR-only line ends.
fn parse(text_bytes: &[u8], name: &str) -> Result<Mesh> {
    let mut mesh = Mesh::default();
    let mut saw_statement = false;
    for line in Lines::new(text_bytes, name) {
        let (line_no, raw) = line?;
        let err = |msg: String| line_error(name, line_no, msg);
        // Lossy: exporters write names and comments in other encodings (Latin-1), which this
        // loader ignores; a byte that is not UTF-8 inside a number fails to parse as one.
        let line = String::from_utf8_lossy(&raw);
        let line = line.split('#').next().unwrap_or_default();
        let mut toks = line.split_whitespace();
        let Some(keyword) = toks.next() else {
            continue;
        };
        saw_statement = true;
        match keyword {
            "v" => {
                let mut values = [0f32; 6];
                let mut count = 0;
                for tok in toks {
                    if count == values.len() {
                        return Err(err(format!("unexpected {} after the vertex", Quoted(tok))));
                    }
                    values[count] = tok
                        .parse::<f32>()
                        .map_err(|_| err(format!("{} is not a number", Quoted(tok))))?;
                    count += 1;
                }
                if !matches!(count, 3 | 4 | 6) {
                    return Err(err(format!(
                        "a vertex is x y z, x y z w or x y z r g b, not {count} numbers"
                    )));
                }
                let mut xyz = [0f32; 3];
                for (axis, c) in xyz.iter_mut().enumerate() {
                    *c = finite_coord(values[axis].into(), axis).map_err(err)?;
                }
                mesh.positions
                    .try_push(Vec3::from_array(xyz))
                    .map_err(|_| no_memory(name))?;
            }
            "f" => {
                let defined = mesh.positions.len();
                let index = |tok: &str| -> Result<u32> {
                    vertex_ref(tok, defined)
                        .map_err(|m| err(format!("face vertex {}: {m}", Quoted(tok))))
                };
                let (Some(a), Some(b)) = (toks.next(), toks.next()) else {
                    return Err(err("face has fewer than 3 vertices".into()));
                };
                let (v0, mut prev) = (index(a)?, index(b)?);
                let mut corners = 2;
                for tok in toks {
                    let v = index(tok)?;
                    mesh.triangles
                        .try_push([v0, prev, v])
                        .map_err(|_| no_memory(name))?;
                    prev = v;
                    corners += 1;
                }
                if corners < 3 {
                    return Err(err("face has fewer than 3 vertices".into()));
                }
            }
            "vt" | "vn" | "vp" | "g" | "o" | "s" | "mg" | "usemtl" | "mtllib" | "p" | "l" => {}
            // Render attributes: how surfaces are drawn, never a surface.
            "usemap" | "maplib" | "lod" | "bevel" | "c_interp" | "d_interp" | "shadow_obj"
            | "trace_obj" => {}
            other => return Err(err(format!("unsupported OBJ statement {}", Quoted(other)))),
        }
    }
    if text_bytes.is_empty() {
        return Err(Error::parse(format!("{name}: empty file")));
    }
    if !saw_statement {
        return Err(Error::parse(format!(
            "{name}: no statements (the file holds only comments and blank lines)"
        )));
    }
    if mesh.triangles.is_empty() {
        return Err(Error::parse(format!(
            "{name}: no faces ('f' lines) in the file"
        )));
    }
    Ok(mesh)
}

/// The file's lines as they are, numbered from 0.
type RawLines<'a> = std::iter::Enumerate<std::slice::Split<'a, u8, fn(&u8) -> bool>>;

/// The file's logical lines, each with the 1-based number of its first line: without the CR
/// of a CRLF ending or the byte-order mark at the start of the file, and a line that ends in
/// `\` (outside a comment) joined with the next by a space (the OBJ rule for long face lists).
struct Lines<'a> {
    lines: RawLines<'a>,
    name: &'a str,
}

impl<'a> Lines<'a> {
    fn new(text: &'a [u8], name: &'a str) -> Self {
        let newline: fn(&u8) -> bool = |&b| b == b'\n';
        Lines {
            lines: text.split(newline).enumerate(),
            name,
        }
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = Result<(usize, Cow<'a, [u8]>)>;

    fn next(&mut self) -> Option<Self::Item> {
        // The continued lines so far, and the number of the first.
        let mut joined: Option<(usize, Vec<u8>)> = None;
        for (i, raw) in self.lines.by_ref() {
            let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
            let raw = if i == 0 {
                raw.strip_prefix(UTF8_BOM).unwrap_or(raw)
            } else {
                raw
            };
            // A comment is never continued: a Windows path at its end would swallow a line.
            let (part, continued) = match raw.strip_suffix(b"\\") {
                Some(head) if !head.contains(&b'#') => (head, true),
                _ => (raw, false),
            };
            if !continued && joined.is_none() {
                return Some(Ok((i + 1, Cow::Borrowed(raw))));
            }
            let (_, text) = joined.get_or_insert((i + 1, Vec::new()));
            // Fallibly: a file of continued lines is one line as long as the file.
            if text.try_reserve(part.len() + 1).is_err() {
                return Some(Err(no_memory(self.name)));
            }
            text.extend_from_slice(part);
            text.push(b' ');
            if !continued {
                break;
            }
        }
        // The last line of the file may end in `\` too.
        joined.map(|(first, text)| Ok((first, Cow::Owned(text))))
    }
}

/// The error of a mesh that outgrew the memory: OBJ gives no counts up front, so the arrays
/// grow (fallibly: an error, not an abort of the host program) as lines are read.
fn no_memory(name: &str) -> Error {
    Error::out_of_memory(format!("{name}: cannot allocate memory for the mesh"))
}

/// Resolves one face vertex reference (`i`, `i/t`, `i//n`, `i/t/n`) to a 0-based index into
/// the `defined` vertices seen so far. The texture and normal parts are checked for syntax only.
fn vertex_ref(tok: &str, defined: usize) -> std::result::Result<u32, String> {
    let mut parts = tok.split('/');
    let v = parts.next().unwrap_or_default();
    let t = parts.next();
    let n = parts.next();
    if parts.next().is_some() {
        return Err("too many '/' parts".into());
    }
    use std::num::IntErrorKind::{NegOverflow, PosOverflow};
    let overflows = |e: &std::num::ParseIntError| matches!(e.kind(), PosOverflow | NegOverflow);
    // Texture and normal indices are checked for form only (they are not read), however large.
    let integer = |s: &str| s.parse::<i64>().map_or_else(|e| overflows(&e), |_| true);
    // `i/t`, `i/t/n` need an integer t; only `i//n` may leave it empty, and then n is required.
    match (t, n) {
        (None, _) => {}
        (Some(t), None) if integer(t) => {}
        (Some(t), Some(n)) if (t.is_empty() || integer(t)) && integer(n) => {}
        _ => return Err("malformed texture/normal index".into()),
    }
    let out_of_range = || format!("index {v} out of range ({defined} vertices defined so far)");
    let i: i64 = v.parse().map_err(|e| {
        if overflows(&e) {
            out_of_range()
        } else {
            format!("{} is not an integer", Quoted(v))
        }
    })?;
    let resolved = match i {
        0 => return Err("index 0 is invalid (OBJ indices start at 1)".into()),
        i if i > 0 => i - 1,
        i => defined as i64 + i,
    };
    if resolved < 0 || resolved >= defined as i64 {
        return Err(out_of_range());
    }
    u32::try_from(resolved).map_err(|_| "index does not fit 32 bits".into())
}
