//! PLY (Stanford polygon file format) parsing: the header, then an ASCII or binary
//! (little/big-endian) body from which `vertex` x/y/z and `face` index lists are kept and every
//! other property and element is skipped. A header that would make a column ambiguous (an
//! element or a property declared twice, a face list under both its names) is an error.
//!
//! Errors in the header and in ASCII bodies name the 1-based line; errors in binary bodies name
//! the byte offset from the start of the file, since a binary body has no lines.

use std::collections::HashSet;

use glam::Vec3;

use super::{cr_line_ends, finite_coord, line_error, offset_error, Mesh, Quoted, UTF8_BOM};
use crate::error::{Error, Result};
use crate::fallible::TryGrow;

/// The scalar types of the PLY spec, under either of their two spellings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// The spec's primary spelling, for error messages.
    fn spec_name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }

    /// Size in a binary body.
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The value range of an integer type; `None` for floating-point types.
    fn int_range(self) -> Option<(i64, i64)> {
        match self {
            Scalar::I8 => Some((i8::MIN.into(), i8::MAX.into())),
            Scalar::U8 => Some((0, u8::MAX.into())),
            Scalar::I16 => Some((i16::MIN.into(), i16::MAX.into())),
            Scalar::U16 => Some((0, u16::MAX.into())),
            Scalar::I32 => Some((i32::MIN.into(), i32::MAX.into())),
            Scalar::U32 => Some((0, u32::MAX.into())),
            Scalar::F32 | Scalar::F64 => None,
        }
    }

    /// Parses an ASCII token as this type. Every value becomes an `f64`, which holds all
    /// PLY integer values exactly; `float` tokens are parsed as `f32` first so that a value
    /// written as the shortest `f32` representation reads back bit-identical.
    fn parse_token(self, tok: &str) -> Option<f64> {
        match self {
            Scalar::F32 => tok.parse::<f32>().ok().map(f64::from),
            Scalar::F64 => tok.parse::<f64>().ok(),
            int => {
                let (lo, hi) = int.int_range()?;
                let v = tok.parse::<i64>().ok()?;
                (lo..=hi).contains(&v).then_some(v as f64)
            }
        }
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    /// Header line that declared the element, for errors about its count or properties.
    line: usize,
    props: Vec<Property>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLe,
    BinaryBe,
}

#[derive(Debug)]
struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset of the first body byte.
    body_start: usize,
    /// Line number of `end_header` (ASCII body lines are numbered on from it).
    end_line: usize,
}

/// What the body reader does with each element.
enum Role {
    /// `vertex`: for each property, the axis it feeds (x/y/z) if any.
    Vertex(Vec<Option<usize>>),
    /// `face`: the index of the `vertex_indices`/`vertex_index` list property.
    Face(usize),
    Skip,
}

/// Parses a PLY file held in memory; `name` is used in error messages.
///
/// Formats: `ascii`, `binary_little_endian`, `binary_big_endian`. Keeps `vertex` properties
/// `x`, `y`, `z` (any scalar type, any position among other properties) and the `face` list
/// `vertex_indices` (or `vertex_index`); skips everything else but another element of such
/// lists (`tristrips`), whose surfaces would be lost, which is refused. Triangles follow the file's
/// face order, each polygon of n vertices fan-triangulated in place into n-2 triangles
/// `(v0, v(k), v(k+1))`, so face i maps to a known triangle range (ray sets identify triangles
/// by face index; for all-triangle files triangle i is face i).
///
/// Rejects (with `Parse`) faces of fewer than 3 vertices, out-of-range indices, non-finite
/// coordinates, element counts the file cannot hold, trailing data after the last element
/// (a sign of wrong counts), and a file without faces (as the OBJ loader does).
pub fn parse_ply(bytes: &[u8], name: &str) -> Result<Mesh> {
    cr_line_ends(parse(bytes, name), bytes, name)
}

/// [`parse_ply`] but for naming CR-only line ends.
fn parse(bytes: &[u8], name: &str) -> Result<Mesh> {
    let header = parse_header(bytes, name)?;
    let roles = plan(&header, name)?;
    let body = bytes.get(header.body_start..).unwrap_or_default();
    check_counts(&header, body.len(), name)?;

    let mut mesh = Mesh::default();
    // Both counts were just bounded by the body size, so a reservation is at most a few times
    // the file's size. A large file can still exhaust memory: that is reported as
    // `OutOfMemory` rather than aborting the host program.
    for (el, role) in header.elements.iter().zip(&roles) {
        let reserved = match role {
            Role::Vertex(_) => mesh.positions.try_reserve_exact(el.count),
            Role::Face(_) => mesh.triangles.try_reserve(el.count),
            Role::Skip => Ok(()),
        };
        reserved.map_err(|_| {
            Error::out_of_memory(format!(
                "{name}: cannot allocate memory for {} '{}' entries",
                el.count, el.name
            ))
        })?;
    }
    let n_verts = header
        .elements
        .iter()
        .zip(&roles)
        .find(|(_, r)| matches!(r, Role::Vertex(_)))
        .map_or(0, |(el, _)| el.count);

    match header.format {
        Format::Ascii => read_ascii(&header, &roles, body, n_verts, name, &mut mesh)?,
        Format::BinaryLe | Format::BinaryBe => {
            let mut cur = Cursor {
                bytes,
                pos: header.body_start,
                big_endian: header.format == Format::BinaryBe,
                name,
            };
            read_binary(&header, &roles, &mut cur, n_verts, &mut mesh)?;
        }
    }
    // As in OBJ: a mesh file that yields no triangle is refused rather than loaded as an
    // object with nothing to hit. Checked after the body, so that a damaged body is reported
    // as such. Every face gives at least one triangle, so no triangle means no face.
    if mesh.triangles.is_empty() {
        let line = header
            .elements
            .iter()
            .zip(&roles)
            .find(|(_, r)| matches!(r, Role::Face(_)))
            .map_or(header.end_line, |(el, _)| el.line);
        return Err(line_error(
            name,
            line,
            "no faces in the file (element 'face' has 0 entries)",
        ));
    }
    Ok(mesh)
}

fn parse_header(bytes: &[u8], name: &str) -> Result<Header> {
    if bytes.is_empty() {
        return Err(Error::parse(format!("{name}: empty file")));
    }
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut names: HashSet<&str> = HashSet::new();
    // (element, property) names: a property declared twice would be read twice from every
    // row, and only the first used.
    let mut prop_names: HashSet<(usize, &str)> = HashSet::new();
    loop {
        line_no += 1;
        let rest = match bytes.get(pos..) {
            Some(r) if !r.is_empty() => r,
            _ => {
                return Err(line_error(
                    name,
                    line_no,
                    "end of file inside the PLY header (no end_header line)",
                ))
            }
        };
        let (raw, len) = match rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&rest[..i], i + 1),
            None => (rest, rest.len()),
        };
        pos += len;
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        let err = |msg: String| line_error(name, line_no, msg);
        // Comments are skipped before the UTF-8 check: exporters write them in other
        // encodings (Latin-1), as the OBJ loader allows.
        let keyword = raw.trim_ascii_start().split(u8::is_ascii_whitespace).next();
        if line_no > 1 && matches!(keyword, Some(b"comment" | b"obj_info")) {
            continue;
        }
        // A byte-order mark, as some editors write at the start of a UTF-8 file.
        let raw = match line_no {
            1 => raw.strip_prefix(UTF8_BOM).unwrap_or(raw),
            _ => raw,
        };
        let line = std::str::from_utf8(raw)
            .map_err(|_| err("PLY header line is not text (invalid UTF-8)".into()))?;
        if line_no == 1 {
            if line.trim_end() != "ply" {
                return Err(err("not a PLY file (the first line must be 'ply')".into()));
            }
            continue;
        }
        let mut tok = line.split_ascii_whitespace();
        let Some(keyword) = tok.next() else {
            continue;
        };
        match keyword {
            "comment" | "obj_info" => continue,
            "format" => {
                if format.is_some() {
                    return Err(err("second format line".into()));
                }
                format = Some(match tok.next() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::BinaryLe,
                    Some("binary_big_endian") => Format::BinaryBe,
                    Some(other) => {
                        return Err(err(format!(
                            "unknown format {} (expected ascii, \
                             binary_little_endian or binary_big_endian)",
                            Quoted(other)
                        )))
                    }
                    None => return Err(err("format line names no format".into())),
                });
                if tok.next().is_none() {
                    return Err(err("format line lacks a version".into()));
                }
            }
            "element" => {
                let (Some(el_name), Some(count)) = (tok.next(), tok.next()) else {
                    return Err(err("element line needs a name and a count".into()));
                };
                let count = count
                    .parse::<u64>()
                    .ok()
                    .and_then(|c| usize::try_from(c).ok())
                    .ok_or_else(|| {
                        err(format!(
                            "element {} count {} is not a valid count",
                            Quoted(el_name),
                            Quoted(count)
                        ))
                    })?;
                // A set, not a scan of the earlier elements: a header may declare any number
                // of elements, and the scan made such a header take quadratic time.
                if !names.insert(el_name) {
                    return Err(err(format!("element '{el_name}' declared twice")));
                }
                elements.push(Element {
                    name: el_name.to_string(),
                    count,
                    line: line_no,
                    props: Vec::new(),
                });
            }
            "property" => {
                // The element this property belongs to (the last one), counted from 1.
                let element = elements.len();
                let Some(el) = elements.last_mut() else {
                    return Err(err("property line before any element line".into()));
                };
                let scalar = |t: Option<&str>| -> Result<Scalar> {
                    let t = t.ok_or_else(|| err("property line is incomplete".into()))?;
                    Scalar::from_name(t)
                        .ok_or_else(|| err(format!("unknown property type {}", Quoted(t))))
                };
                let kind = match tok.next() {
                    Some("list") => {
                        let count = scalar(tok.next())?;
                        let item = scalar(tok.next())?;
                        if count.int_range().is_none() {
                            return Err(err("a list's count type must be an integer type".into()));
                        }
                        Kind::List { count, item }
                    }
                    t => Kind::Scalar(scalar(t)?),
                };
                let prop_name = tok
                    .next()
                    .ok_or_else(|| err("property line lacks a name".into()))?;
                if !prop_names.insert((element, prop_name)) {
                    return Err(err(format!(
                        "property '{prop_name}' declared twice in element '{}'",
                        el.name
                    )));
                }
                el.props.push(Property {
                    name: prop_name.to_string(),
                    kind,
                });
            }
            "end_header" => {}
            other => return Err(err(format!("unknown PLY header keyword {}", Quoted(other)))),
        }
        if let Some(extra) = tok.next() {
            return Err(err(format!(
                "unexpected {} at the end of the line",
                Quoted(extra)
            )));
        }
        if keyword == "end_header" {
            break;
        }
    }
    let format =
        format.ok_or_else(|| line_error(name, line_no, "PLY header has no format line"))?;
    Ok(Header {
        format,
        elements,
        body_start: pos,
        end_line: line_no,
    })
}

/// The names of a face's vertex index list (the spec's and a common variant).
fn is_face_list_name(name: &str) -> bool {
    name == "vertex_indices" || name == "vertex_index"
}

/// Decides each element's role and checks that the header declares what a mesh needs.
fn plan(header: &Header, name: &str) -> Result<Vec<Role>> {
    let mut roles = Vec::with_capacity(header.elements.len());
    let (mut have_vertex, mut have_face) = (false, false);
    for el in &header.elements {
        let err = |msg: String| line_error(name, el.line, msg);
        let role = match el.name.as_str() {
            "vertex" => {
                have_vertex = true;
                let mut axes = vec![None; el.props.len()];
                for (axis, axis_name) in ["x", "y", "z"].into_iter().enumerate() {
                    let Some(i) = el.props.iter().position(|p| p.name == axis_name) else {
                        return Err(err(format!(
                            "element 'vertex' has no '{axis_name}' property"
                        )));
                    };
                    if matches!(el.props[i].kind, Kind::List { .. }) {
                        return Err(err(format!("vertex property '{axis_name}' is a list")));
                    }
                    axes[i] = Some(axis);
                }
                if u32::try_from(el.count).is_err() {
                    return Err(err(format!(
                        "{} vertices do not fit 32-bit indices",
                        el.count
                    )));
                }
                Role::Vertex(axes)
            }
            "face" => {
                have_face = true;
                let is_list = |p: &Property| is_face_list_name(&p.name);
                let Some(i) = el.props.iter().position(is_list) else {
                    return Err(err(
                        "element 'face' has no 'vertex_indices' or 'vertex_index' property".into(),
                    ));
                };
                // Both names: one list would be read and the other dropped unseen.
                if el.props.iter().filter(|p| is_list(p)).count() > 1 {
                    return Err(err(
                        "element 'face' has both 'vertex_indices' and 'vertex_index'".into(),
                    ));
                }
                match el.props[i].kind {
                    Kind::List { item, .. } if item.int_range().is_some() => {}
                    _ => {
                        return Err(err(format!(
                            "face property '{}' must be a list of an integer type",
                            el.props[i].name
                        )))
                    }
                }
                Role::Face(i)
            }
            _ => {
                // Another element of index lists (`tristrips`) describes surfaces too, which
                // skipping would drop unseen.
                let list = el
                    .props
                    .iter()
                    .find(|p| is_face_list_name(&p.name) && matches!(p.kind, Kind::List { .. }));
                if let Some(p) = list {
                    return Err(err(format!(
                        "element {} holds vertex index lists ('{}'), which would be dropped: \
                         only 'face' elements are read (triangle strips are not supported)",
                        Quoted(&el.name),
                        p.name
                    )));
                }
                Role::Skip
            }
        };
        roles.push(role);
    }
    if !have_vertex {
        return Err(line_error(
            name,
            header.end_line,
            "PLY header declares no 'vertex' element",
        ));
    }
    if !have_face {
        return Err(line_error(
            name,
            header.end_line,
            "PLY header declares no 'face' element",
        ));
    }
    Ok(roles)
}

/// Rejects element counts the body cannot hold, before anything is allocated from them.
///
/// Per entry a binary body needs at least its scalar sizes plus each list's count field; an
/// ASCII body needs at least one character and one separator per property.
fn check_counts(header: &Header, body_len: usize, name: &str) -> Result<()> {
    let ascii = header.format == Format::Ascii;
    // The last ASCII line may lack its newline.
    let limit = body_len as u64 + u64::from(ascii);
    let mut need = 0u64;
    for (i, el) in header.elements.iter().enumerate() {
        let per_entry: u64 = if ascii {
            2 * el.props.len() as u64
        } else {
            el.props
                .iter()
                .map(|p| match p.kind {
                    Kind::Scalar(s) => s.size() as u64,
                    Kind::List { count, .. } => count.size() as u64,
                })
                .sum()
        };
        match (el.count as u64)
            .checked_mul(per_entry)
            .and_then(|n| n.checked_add(need))
        {
            Some(n) if n <= limit => need = n,
            // Alone, this element fits: which count is wrong is not known, so all are named.
            _ if (el.count as u64).saturating_mul(per_entry) <= limit => {
                let counts: Vec<String> = header.elements[..=i]
                    .iter()
                    .map(|e| format!("'{}' {}", e.name, e.count))
                    .collect();
                return Err(line_error(
                    name,
                    el.line,
                    format!(
                        "file truncated or an element count wrong: the elements' declared \
                         entries ({}) need more than the {body_len} bytes after the header",
                        counts.join(", ")
                    ),
                ));
            }
            _ => {
                return Err(line_error(
                    name,
                    el.line,
                    format!(
                        "file truncated or an element count wrong: element '{}' declares {} \
                         entries, more than the {body_len} bytes after the header can hold",
                        el.name, el.count
                    ),
                ))
            }
        }
    }
    Ok(())
}

/// Appends the fan triangulation `(v0, v(k), v(k+1))` of a face of `n` vertices (n ≥ 3) whose
/// indices `index` reads in order. The triangles were reserved one per face: a polygon's
/// others grow the array fallibly, since a file of a few bytes per index can hold a polygon
/// of more triangles than memory does.
fn fan(
    n: usize,
    mut index: impl FnMut() -> Result<u32>,
    triangles: &mut Vec<[u32; 3]>,
    name: &str,
) -> Result<()> {
    let v0 = index()?;
    let mut prev = index()?;
    for _ in 2..n {
        let v = index()?;
        triangles.try_push([v0, prev, v]).map_err(|_| {
            Error::out_of_memory(format!("{name}: cannot allocate memory for the triangles"))
        })?;
        prev = v;
    }
    Ok(())
}

/// Converts a face's vertex index, checked against the vertex count.
fn vertex_index(v: f64, n_verts: usize) -> std::result::Result<u32, String> {
    if v >= 0.0 && v < n_verts as f64 {
        Ok(v as u32)
    } else {
        Err(format!(
            "vertex index {v} out of range (the file has {n_verts} vertices)"
        ))
    }
}

fn face_size_error(face: usize, n: f64) -> String {
    format!("face {face} has {n} vertices (a face needs at least 3)")
}

/// A read position in a binary PLY body. Offsets are from the start of the file.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    big_endian: bool,
    name: &'a str,
}

impl<'a> Cursor<'a> {
    /// Takes `n` bytes; on truncation the error says what was being read (`what` is only
    /// formatted on the error path, so the hot loop does not allocate).
    fn take(&mut self, n: usize, what: impl FnOnce() -> String) -> Result<&'a [u8]> {
        let slice = self
            .pos
            .checked_add(n)
            .and_then(|end| self.bytes.get(self.pos..end));
        match slice {
            Some(s) => {
                self.pos += n;
                Ok(s)
            }
            None => Err(offset_error(
                self.name,
                self.pos,
                format!(
                    "file truncated: {} needs {n} bytes, only {} left",
                    what(),
                    self.bytes.len().saturating_sub(self.pos)
                ),
            )),
        }
    }

    fn read(&mut self, ty: Scalar, what: impl FnOnce() -> String) -> Result<f64> {
        let b = self.take(ty.size(), what)?;
        let be = self.big_endian;
        macro_rules! num {
            ($t:ty) => {{
                let mut a = [0u8; std::mem::size_of::<$t>()];
                a.copy_from_slice(b);
                if be {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        Ok(match ty {
            Scalar::I8 => num!(i8).into(),
            Scalar::U8 => num!(u8).into(),
            Scalar::I16 => num!(i16).into(),
            Scalar::U16 => num!(u16).into(),
            Scalar::I32 => num!(i32).into(),
            Scalar::U32 => num!(u32).into(),
            Scalar::F32 => num!(f32).into(),
            Scalar::F64 => num!(f64),
        })
    }

    fn error(&self, offset: usize, msg: impl std::fmt::Display) -> Error {
        offset_error(self.name, offset, msg)
    }

    /// Skips one property value, computing a list's size from its count field.
    fn skip(&mut self, prop: &Property, what: impl Fn() -> String) -> Result<()> {
        match prop.kind {
            Kind::Scalar(s) => {
                self.take(s.size(), what)?;
            }
            Kind::List { count, item } => {
                let n = self.read(count, &what)?;
                // Integer count types only (checked in the header), so `n` is integral.
                if n < 0.0 {
                    return Err(self.error(
                        self.pos - count.size(),
                        format!("{}: negative list length {n}", what()),
                    ));
                }
                let len = (n as usize).saturating_mul(item.size());
                self.take(len, what)?;
            }
        }
        Ok(())
    }
}

/// Describes a value for truncation errors; a closure so it is only formatted on failure.
fn what<'a>(el: &'a Element, i: usize, p: &'a Property) -> impl Fn() -> String + 'a {
    move || format!("{} {i} property '{}'", el.name, p.name)
}

fn read_binary(
    header: &Header,
    roles: &[Role],
    cur: &mut Cursor,
    n_verts: usize,
    mesh: &mut Mesh,
) -> Result<()> {
    for (el, role) in header.elements.iter().zip(roles) {
        match role {
            Role::Skip => {
                let fixed: Option<usize> = el
                    .props
                    .iter()
                    .map(|p| match p.kind {
                        Kind::Scalar(s) => Some(s.size()),
                        Kind::List { .. } => None,
                    })
                    .sum();
                if let Some(stride) = fixed {
                    // All-scalar elements are skipped in one step.
                    let len = el.count.saturating_mul(stride);
                    cur.take(len, || {
                        format!("element '{}' ({} entries)", el.name, el.count)
                    })?;
                } else {
                    for i in 0..el.count {
                        for p in &el.props {
                            cur.skip(p, what(el, i, p))?;
                        }
                    }
                }
            }
            Role::Vertex(axes) => {
                for i in 0..el.count {
                    let mut xyz = [0f32; 3];
                    for (p, axis) in el.props.iter().zip(axes) {
                        match (axis, p.kind) {
                            (Some(axis), Kind::Scalar(s)) => {
                                let at = cur.pos;
                                let v = cur.read(s, what(el, i, p))?;
                                xyz[*axis] = finite_coord(v, *axis)
                                    .map_err(|m| cur.error(at, format!("vertex {i}: {m}")))?;
                            }
                            _ => cur.skip(p, what(el, i, p))?,
                        }
                    }
                    mesh.positions.push(Vec3::from_array(xyz));
                }
            }
            Role::Face(index_prop) => {
                for i in 0..el.count {
                    for (pi, p) in el.props.iter().enumerate() {
                        match p.kind {
                            Kind::List { count, item } if pi == *index_prop => {
                                let at = cur.pos;
                                let n = cur.read(count, what(el, i, p))?;
                                if n < 3.0 {
                                    return Err(cur.error(at, face_size_error(i, n)));
                                }
                                let name = cur.name;
                                let index = || -> Result<u32> {
                                    let at = cur.pos;
                                    let v = cur.read(item, what(el, i, p))?;
                                    vertex_index(v, n_verts)
                                        .map_err(|m| cur.error(at, format!("face {i}: {m}")))
                                };
                                fan(n as usize, index, &mut mesh.triangles, name)?;
                            }
                            _ => cur.skip(p, what(el, i, p))?,
                        }
                    }
                }
            }
        }
    }
    let left = cur.bytes.len() - cur.pos.min(cur.bytes.len());
    if left > 0 {
        return Err(cur.error(
            cur.pos,
            format!(
                "{left} bytes of unexpected data after the last element \
                 (element counts in the header too small?)"
            ),
        ));
    }
    Ok(())
}

/// Non-blank lines of an ASCII body with their 1-based line numbers.
struct Lines<'a> {
    rest: &'a [u8],
    line: usize,
    name: &'a str,
}

impl<'a> Lines<'a> {
    fn next_nonblank(&mut self) -> Result<Option<(usize, &'a str)>> {
        while !self.rest.is_empty() {
            self.line += 1;
            let (raw, tail) = match self.rest.iter().position(|&b| b == b'\n') {
                Some(i) => (&self.rest[..i], &self.rest[i + 1..]),
                None => (self.rest, &self.rest[self.rest.len()..]),
            };
            self.rest = tail;
            let text = std::str::from_utf8(raw).map_err(|_| {
                line_error(self.name, self.line, "line is not text (invalid UTF-8)")
            })?;
            if !text.trim().is_empty() {
                return Ok(Some((self.line, text)));
            }
        }
        Ok(None)
    }
}

fn read_ascii(
    header: &Header,
    roles: &[Role],
    body: &[u8],
    n_verts: usize,
    name: &str,
    mesh: &mut Mesh,
) -> Result<()> {
    let mut lines = Lines {
        rest: body,
        line: header.end_line,
        name,
    };
    for (el, role) in header.elements.iter().zip(roles) {
        if el.props.is_empty() {
            continue;
        }
        for i in 0..el.count {
            let Some((line, text)) = lines.next_nonblank()? else {
                return Err(line_error(
                    name,
                    lines.line + 1,
                    format!(
                        "file truncated: expected {} {i} of {} declared",
                        el.name, el.count
                    ),
                ));
            };
            let err = |msg: String| line_error(name, line, msg);
            let mut toks = text.split_ascii_whitespace();
            let mut value = |ty: Scalar, what: &str| -> Result<f64> {
                let tok = toks
                    .next()
                    .ok_or_else(|| err(format!("{} {i}: missing value for {what}", el.name)))?;
                ty.parse_token(tok).ok_or_else(|| {
                    err(format!(
                        "{} {i}: {} is not a valid {} value for {what}",
                        el.name,
                        Quoted(tok),
                        ty.spec_name()
                    ))
                })
            };
            let mut xyz = [0f32; 3];
            for (pi, p) in el.props.iter().enumerate() {
                match p.kind {
                    Kind::Scalar(s) => {
                        let v = value(s, &p.name)?;
                        if let Role::Vertex(axes) = role {
                            if let Some(Some(axis)) = axes.get(pi) {
                                xyz[*axis] = finite_coord(v, *axis)
                                    .map_err(|m| err(format!("vertex {i}: {m}")))?;
                            }
                        }
                    }
                    Kind::List { count, item } => {
                        let n = value(count, &format!("the length of '{}'", p.name))?;
                        if !matches!(role, Role::Face(ip) if *ip == pi) {
                            if n < 0.0 {
                                return Err(err(format!("{} {i}: negative list length", el.name)));
                            }
                            for _ in 0..n as usize {
                                value(item, &p.name)?;
                            }
                            continue;
                        }
                        if n < 3.0 {
                            return Err(err(face_size_error(i, n)));
                        }
                        let index = || -> Result<u32> {
                            let v = value(item, &p.name)?;
                            vertex_index(v, n_verts).map_err(|m| err(format!("face {i}: {m}")))
                        };
                        fan(n as usize, index, &mut mesh.triangles, name)?;
                    }
                }
            }
            if let Some(extra) = toks.next() {
                return Err(err(format!(
                    "{} {i}: unexpected extra value {}",
                    el.name,
                    Quoted(extra)
                )));
            }
            if matches!(role, Role::Vertex(_)) {
                mesh.positions.push(Vec3::from_array(xyz));
            }
        }
    }
    if let Some((line, _)) = lines.next_nonblank()? {
        return Err(line_error(
            name,
            line,
            "unexpected data after the last element (element counts in the header too small?)",
        ));
    }
    Ok(())
}
