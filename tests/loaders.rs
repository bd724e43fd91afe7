//! Mesh loader tests: exact content of small hand-written PLY/OBJ files, a malformed-file
//! corpus whose errors must point at the right line or byte offset, a four-format round trip
//! of random meshes, and the shared Stanford models.

use std::path::PathBuf;
use std::time::Instant;

use glam::Vec3;
use rt2::error::{Result, Rt2Status};
use rt2::scene::loaders::{load_mesh, parse_obj, parse_ply, Mesh};

mod support;

// ---------------------------------------------------------------------------------------------
// Helpers

/// Asserts a `Parse` error whose message names `name` and contains every one of `needles`.
#[track_caller]
fn assert_parse_err(result: Result<Mesh>, name: &str, needles: &[&str]) {
    let err = match result {
        Ok(mesh) => panic!(
            "{name}: expected a parse error, got a mesh with {} vertices / {} triangles",
            mesh.positions.len(),
            mesh.triangles.len()
        ),
        Err(e) => e,
    };
    assert_eq!(err.status, Rt2Status::Parse, "{name}: {}", err.message);
    assert!(
        err.message.contains(name),
        "message does not name the file {name:?}: {}",
        err.message
    );
    for needle in needles {
        assert!(
            err.message.contains(needle),
            "message for {name} lacks {needle:?}: {}",
            err.message
        );
    }
}

/// Little helper to write binary PLY bodies in either byte order.
struct Bin {
    big: bool,
    buf: Vec<u8>,
}

impl Bin {
    fn new(header: &str, big: bool) -> Self {
        Bin {
            big,
            buf: header.as_bytes().to_vec(),
        }
    }
    fn put(&mut self, le: &[u8], be: &[u8]) -> &mut Self {
        self.buf.extend_from_slice(if self.big { be } else { le });
        self
    }
    fn u8(&mut self, v: u8) -> &mut Self {
        self.buf.push(v);
        self
    }
    fn i8(&mut self, v: i8) -> &mut Self {
        self.buf.push(v as u8);
        self
    }
    fn i16(&mut self, v: i16) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    fn u16(&mut self, v: u16) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    fn i32(&mut self, v: i32) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    fn u32(&mut self, v: u32) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    fn f32(&mut self, v: f32) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
    fn f64(&mut self, v: f64) -> &mut Self {
        self.put(&v.to_le_bytes(), &v.to_be_bytes())
    }
}

/// A deterministic xorshift generator (no dependency needed for a property test).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    /// Any finite f32, from tiny subnormals to huge values, so text writers are tested on
    /// exact round trips of every magnitude.
    fn finite_f32(&mut self) -> f32 {
        loop {
            let v = f32::from_bits(self.next() as u32);
            if v.is_finite() {
                return v;
            }
        }
    }
}

fn v(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(x, y, z)
}

// ---------------------------------------------------------------------------------------------
// PLY content

#[test]
fn ply_ascii_with_extra_properties_elements_and_quads() {
    let text = "ply\n\
        format ascii 1.0\n\
        comment made by hand\n\
        obj_info nothing to see\n\
        element material 2\n\
        property list uchar float weights\n\
        property uchar id\n\
        element vertex 5\n\
        property float nx\n\
        property float x\n\
        property list int int tags\n\
        property double y\n\
        property uchar red\n\
        property short z\n\
        element face 3\n\
        property uchar flags\n\
        property list uchar uint vertex_indices\n\
        property float quality\n\
        end_header\n\
        2 0.5 0.25 7\n\
        0 1\n\
        9 0 1 5 0.5 255 -3\n\
        9 1.5 0 -2 0 4\n\
        \n\
        9 1 2 1 2 1.25 0 7\n\
        9 0 0 0 0 0\n\
        9 -1e3 3 1 2 3 2.5e-1 1 0\n\
        1 3 0 1 2 0.5\n\
        1 4 0 1 2 3 0.5\n\
        0 5 4 3 2 1 0 1\n";
    let mesh = parse_ply(text.as_bytes(), "hand.ply").unwrap();
    assert_eq!(
        mesh.positions,
        vec![
            v(0.0, 0.5, -3.0),
            v(1.5, -2.0, 4.0),
            v(1.0, 1.25, 7.0),
            v(0.0, 0.0, 0.0),
            v(-1000.0, 0.25, 0.0),
        ]
    );
    // File face order; the quad and the pentagon are fan-triangulated in place.
    assert_eq!(
        mesh.triangles,
        vec![
            [0, 1, 2],
            [0, 1, 2],
            [0, 2, 3],
            [4, 3, 2],
            [4, 2, 1],
            [4, 1, 0],
        ]
    );
}

#[test]
fn ply_ascii_crlf_aliases_and_vertex_index_name() {
    let text = "ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty float32 x\r\n\
        property float64 y\r\nproperty int8 z\r\nelement face 1\r\n\
        property list uint8 int32 vertex_index\r\nend_header\r\n\
        1 2 3\r\n4 5 -6\r\n7 8 9\r\n3 2 1 0\r\n";
    let mesh = parse_ply(text.as_bytes(), "crlf.ply").unwrap();
    assert_eq!(
        mesh.positions,
        vec![v(1.0, 2.0, 3.0), v(4.0, 5.0, -6.0), v(7.0, 8.0, 9.0)]
    );
    assert_eq!(mesh.triangles, vec![[2, 1, 0]]);
}

/// The same mesh as a binary file with every scalar type, lists on vertices, and extra
/// elements before, between and after the two that matter.
fn binary_with_extras(big: bool) -> Vec<u8> {
    let format = if big {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let header = format!(
        "ply\nformat {format} 1.0\ncomment all the types\n\
         element camera 2\nproperty list ushort double params\nproperty int16 id\n\
         element vertex 4\nproperty uchar flag\nproperty float x\nproperty list uint int8 junk\n\
         property double y\nproperty uint16 pad\nproperty int z\nproperty char c\n\
         element edge 1\nproperty int a\nproperty uint32 b\n\
         element face 2\nproperty short tag\nproperty list int ushort vertex_indices\n\
         property list uchar float uv\nproperty float64 w\n\
         element tail 3\nproperty list char uint stuff\n\
         end_header\n"
    );
    let mut b = Bin::new(&header, big);
    // camera: 2 entries with lists of doubles.
    b.u16(2).f64(1.0).f64(2.0).i16(-1);
    b.u16(0).i16(5);
    // vertex: flag, x, junk list, y, pad, z, c
    let verts = [
        (1.0f32, 2.0f64, 3i32),
        (-4.5, 0.25, -7),
        (8.0, -1e10, 0),
        (0.0, 0.0, 1),
    ];
    for (i, (x, y, z)) in verts.iter().enumerate() {
        b.u8(i as u8).f32(*x).u32(i as u32);
        for k in 0..i {
            b.i8(-(k as i8));
        }
        b.f64(*y).u16(0xffff).i32(*z).i8(-3);
    }
    // edge
    b.i32(-1).u32(7);
    // face: a quad then a triangle
    b.i16(1)
        .i32(4)
        .u16(0)
        .u16(1)
        .u16(2)
        .u16(3)
        .u8(2)
        .f32(0.5)
        .f32(0.5)
        .f64(9.0);
    b.i16(2).i32(3).u16(3).u16(2).u16(1).u8(0).f64(1.0);
    // tail: lists with char counts
    b.i8(1).u32(99);
    b.i8(0);
    b.i8(2).u32(1).u32(2);
    b.buf
}

#[test]
fn ply_binary_little_and_big_endian_with_extras() {
    for big in [false, true] {
        let name = if big { "be.ply" } else { "le.ply" };
        let mesh = parse_ply(&binary_with_extras(big), name).unwrap();
        assert_eq!(
            mesh.positions,
            vec![
                v(1.0, 2.0, 3.0),
                v(-4.5, 0.25, -7.0),
                v(8.0, -1e10, 0.0),
                v(0.0, 0.0, 1.0)
            ],
            "{name}"
        );
        assert_eq!(
            mesh.triangles,
            vec![[0, 1, 2], [0, 2, 3], [3, 2, 1]],
            "{name}"
        );
    }
}

/// Triangle strips (`tristrips`, a list of vertex indices like a face's) are surfaces: a file
/// holding them is refused, naming the element, rather than loaded without them, beside faces
/// or alone (where "no face element" named the wrong cause).
#[test]
fn ply_triangle_strips_are_refused_not_dropped() {
    let strips = "element tristrips 1\nproperty list int int vertex_indices\n";
    let beside = PLY_HEAD.replace("end_header\n", &format!("{strips}end_header\n"))
        + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n4 0 1 2 0\n";
    assert_parse_err(
        parse_ply(beside.as_bytes(), "strips.ply"),
        "strips.ply",
        &[
            "line 9:",
            "'tristrips'",
            "triangle strips are not supported",
        ],
    );
    let alone = format!(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\n{strips}end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    );
    assert_parse_err(
        parse_ply(alone.as_bytes(), "stripsonly.ply"),
        "stripsonly.ply",
        &["line 7:", "'tristrips'"],
    );
    // Other elements, lists among them, are still skipped.
    let other = PLY_HEAD.replace(
        "end_header\n",
        "element edge 1\nproperty list uchar int corners\nend_header\n",
    ) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n2 0 1\n";
    assert_eq!(
        parse_ply(other.as_bytes(), "edges.ply").unwrap().triangles,
        vec![[0, 1, 2]]
    );
}

#[test]
fn ply_faces_may_come_before_vertices() {
    // Indices are checked against the header's vertex count, not the vertices read so far.
    let text = "ply\nformat ascii 1.0\nelement face 2\nproperty list uchar int vertex_indices\n\
        element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n\
        3 2 1 0\n3 0 1 2\n1 0 0\n0 1 0\n0 0 1\n";
    let mesh = parse_ply(text.as_bytes(), "order.ply").unwrap();
    assert_eq!(mesh.triangles, vec![[2, 1, 0], [0, 1, 2]]);
    assert_eq!(
        mesh.positions,
        vec![v(1.0, 0.0, 0.0), v(0.0, 1.0, 0.0), v(0.0, 0.0, 1.0)]
    );
}

#[test]
fn ply_without_faces_is_an_error_as_in_obj() {
    // The same rule as an OBJ without 'f' lines: a mesh file that yields no triangle is
    // almost surely not what the caller meant to load.
    let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
        property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n\
        1 2 3\n";
    assert_parse_err(
        parse_ply(text.as_bytes(), "nofaces.ply"),
        "nofaces.ply",
        &["line 7:", "no faces"],
    );
    let empty = "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\n\
        property float y\nproperty float z\nelement face 0\n\
        property list uchar int vertex_indices\nend_header\n";
    assert_parse_err(
        parse_ply(empty.as_bytes(), "empty.ply"),
        "empty.ply",
        &["line 7:", "no faces"],
    );
}

#[test]
fn ply_header_with_many_elements_parses_in_linear_time() {
    // 100,000 empty elements: checking each name against every earlier one took ~20 s here.
    let mut text = String::from("ply\nformat ascii 1.0\n");
    for i in 0..100_000 {
        text += &format!("element e{i:07}xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx 0\n");
    }
    text += "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
        element face 1\nproperty list uchar int vertex_indices\nend_header\n\
        0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    let start = Instant::now();
    let mesh = parse_ply(text.as_bytes(), "elements.ply").unwrap();
    let elapsed = start.elapsed();
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    // Linear takes a few ms; generous so that a busy machine does not fail it.
    assert!(
        elapsed.as_secs_f64() < if cfg!(debug_assertions) { 20.0 } else { 5.0 },
        "100,000 elements took {elapsed:?}"
    );
    // A name declared twice among many is still found.
    let twice = text.replacen("e0099999", "e0000000", 1);
    assert_parse_err(
        parse_ply(twice.as_bytes(), "twice.ply"),
        "twice.ply",
        &["line 100002:", "declared twice"],
    );
}

#[test]
fn ply_property_declared_twice_is_refused() {
    // Two `x` columns: every row would be read with the first and the second dropped unseen.
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
        property float z\nproperty float x\nelement face 1\n\
        property list uchar int vertex_indices\nend_header\n\
        0 0 0 5\n1 0 0 5\n0 1 0 5\n3 0 1 2\n";
    assert_parse_err(
        parse_ply(text.as_bytes(), "dupx.ply"),
        "dupx.ply",
        &["line 7:", "property 'x' declared twice in element 'vertex'"],
    );
    // A face's list under both of its names.
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
        property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
        property list uchar int vertex_index\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 3 2 1 0\n";
    assert_parse_err(
        parse_ply(text.as_bytes(), "both.ply"),
        "both.ply",
        &["line 7:", "both 'vertex_indices' and 'vertex_index'"],
    );
    // The same name in two elements is two properties.
    let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
        property float z\nelement face 1\nproperty list uchar int vertex_indices\n\
        property float x\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 7\n";
    assert_eq!(
        parse_ply(text.as_bytes(), "two.ply").unwrap().triangles,
        vec![[0, 1, 2]]
    );
}

// ---------------------------------------------------------------------------------------------
// OBJ content

#[test]
fn obj_all_face_forms_and_ignored_statements() {
    let text = "# a comment\n\
        mtllib scene.mtl\n\
        o thing\n\
        g group\n\
        v 0 0 0\n\
        v 1 0 0 1.0\n\
        v 1 1 0\n\
        v 0 1 0   # trailing comment\n\
        vt 0 0\n\
        vn 0 0 1\n\
        vp 0.5 0.5\n\
        usemtl red\n\
        s off\n\
        \n\
        f 1 2 3\n\
        f 1/1 2/1 3/1\n\
        f 1//1 2//1 3//1\n\
        f 1/1/1 2/1/1 3/1/1 4/1/1\n\
        f 1/99999999999999999999 2/1 3/1\n";
    // Texture and normal indices are not read: one past i64 is still a well-formed face.
    let mesh = parse_obj(text.as_bytes(), "forms.obj").unwrap();
    assert_eq!(
        mesh.positions,
        vec![
            v(0.0, 0.0, 0.0),
            v(1.0, 0.0, 0.0),
            v(1.0, 1.0, 0.0),
            v(0.0, 1.0, 0.0)
        ]
    );
    assert_eq!(
        mesh.triangles,
        vec![
            [0, 1, 2],
            [0, 1, 2],
            [0, 1, 2],
            [0, 1, 2],
            [0, 2, 3],
            [0, 1, 2]
        ]
    );
}

/// Asserts that the OBJ `text` reads as the same mesh as the plain OBJ `plain`.
fn assert_reads_as(text: &[u8], plain: &[u8]) {
    let plain = parse_obj(plain, "plain.obj").unwrap();
    let mesh = parse_obj(text, "text.obj").unwrap();
    assert_eq!(mesh.positions, plain.positions);
    assert_eq!(mesh.triangles, plain.triangles);
}

/// What other exporters write: a byte-order mark, names and comments in Latin-1 (bytes that
/// are not UTF-8), and MeshLab's per-vertex colours. The loader ignores all three, as it does
/// normals and groups, and reads the same mesh as from the plain file.
#[test]
fn obj_from_other_exporters_byte_order_mark_latin1_names_vertex_colours() {
    let mut text = b"\xef\xbb\xbfv 0 0 0 0.5 0.25 1\n".to_vec();
    text.extend(b"# caf\xe9\no caf\xe9\ng t\xeate\nmtllib \xe9t\xe9.mtl\nusemtl rouge\xe9\n");
    text.extend(b"v 1 0 0 1 0 0\nv 0 1 0 0 1 0 # vert \xe0 gauche\nf 1 2 3\n");
    assert_reads_as(&text, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    // A byte-order mark only at the start of the file.
    assert_parse_err(
        parse_obj(b"v 0 0 0\n\xef\xbb\xbfv 1 0 0\n", "bom2.obj"),
        "bom2.obj",
        &["line 2:", "unsupported OBJ statement"],
    );
}

/// Points and lines (Blender writes loose edges as `l`) have no surface: the mesh is the
/// faces' alone, whatever they reference. Curved surfaces would be dropped, so they are refused.
#[test]
fn obj_points_and_lines_are_skipped_curves_refused() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nv 1 1 0\np 4\nf 1 2 3\n\
        l 1/1 2/1 3/1 1/1\nmg 1 0.5\nf 2 4 3\np -1 -2\n";
    let faces = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n";
    assert_reads_as(text.as_bytes(), faces.as_bytes());
    assert_parse_err(
        parse_obj(b"v 0 0 0\ncstype bspline\ncurv 0 1 1 1\n", "curve.obj"),
        "curve.obj",
        &["line 2:", "unsupported OBJ statement 'cstype'"],
    );
}

/// The OBJ spec's render attributes say how surfaces are drawn (texture maps, level of
/// detail, shadow and reflection objects) and carry no surface: skipped, as materials are.
#[test]
fn obj_render_attributes_are_skipped() {
    let text = "maplib a.mpc\nusemap wood\nlod 1\nbevel off\nc_interp on\nd_interp off\n\
        shadow_obj shadow.obj\ntrace_obj trace.obj\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n\
        usemap off\n";
    assert_reads_as(text.as_bytes(), b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
}

/// A line ending in `\` continues on the next (long face lists); a comment does not (a
/// Windows path at its end), and an error on a continued statement names its first line.
#[test]
fn obj_continued_lines_are_one_statement() {
    let text =
        b"v 0 0 \\\n0\nv 1 0 0\r\n# c:\\models\\\nv 0 1 0\nv 1 1 0\nf 1 \\\r\n2\\\n 4 \\\n3\n";
    assert_reads_as(text, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4 3\n");
    // The face starts on line 3 and fails on its third corner, on line 5.
    assert_parse_err(
        parse_obj(b"v 0 0 0\nv 1 0 0\nf 1 \\\n 2 \\\n 7\n", "bad.obj"),
        "bad.obj",
        &["line 3:", "index 7 out of range"],
    );
    // The file's last line may end in `\`.
    let last = parse_obj(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 \\\n3 \\", "last.obj").unwrap();
    assert_eq!(last.triangles, vec![[0, 1, 2]]);
}

#[test]
fn obj_negative_indices_are_relative_to_vertices_so_far() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nf -1 -2/1 -3//2 -4/1/1\n";
    let mesh = parse_obj(text.as_bytes(), "neg.obj").unwrap();
    assert_eq!(mesh.positions.len(), 4);
    assert_eq!(mesh.triangles, vec![[0, 1, 2], [3, 2, 1], [3, 1, 0]]);
}

/// A PLY header's comments may be in another encoding (Latin-1), and the file may start with a
/// UTF-8 byte-order mark, as OBJ files may.
#[test]
fn ply_latin1_comments_and_a_byte_order_mark() {
    let mut bytes = b"\xef\xbb\xbf".to_vec();
    // Indented, as some exporters write their comments.
    let head = PLY_HEAD.replace("format", "  comment caf\u{e9}\nformat");
    bytes.extend_from_slice(head.as_bytes());
    let at = bytes
        .windows(4)
        .position(|w| w == "caf\u{e9}".as_bytes()[..4].as_ref());
    // The comment's e-acute as Latin-1 (one byte 0xE9) instead of UTF-8 (0xC3 0xA9).
    let at = at.expect("the comment") + 3;
    bytes.splice(at..at + 2, [0xe9]);
    bytes.extend_from_slice(b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    let mesh = parse_ply(&bytes, "latin1.ply").unwrap();
    assert_eq!(mesh.positions.len(), 3);
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    // Non-UTF-8 elsewhere in the header is still an error.
    let mut bad = PLY_HEAD
        .replace("vertex_indices", "vertex_ind\u{e9}")
        .into_bytes();
    let at = bad
        .windows(2)
        .position(|w| w == [0xc3, 0xa9])
        .expect("the e-acute");
    bad.splice(at..at + 2, [0xe9]);
    assert_parse_err(
        parse_ply(&bad, "latin1name.ply"),
        "latin1name.ply",
        &["line 8:", "invalid UTF-8"],
    );
}

/// Files that parse keep loading whatever CRs they hold: CR CR LF line ends (a double
/// conversion) and a CR inside a comment on the first line; only a file that fails and whose
/// first line holds a CR is told its lines end in a CR alone.
#[test]
fn stray_carriage_returns_in_files_that_parse() {
    let obj =
        "# made on a Mac\r, then converted\nv 0 0 0\r\r\nv 1 0 0\r\r\nv 0 1 0\r\r\nf 1 2 3\r\r\n";
    let mesh = parse_obj(obj.as_bytes(), "crcrlf.obj").unwrap();
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    let ply = format!("{PLY_HEAD}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").replace('\n', "\r\r\n");
    let mesh = parse_ply(ply.as_bytes(), "crcrlf.ply").unwrap();
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
}

/// A stray CR on the first line of a file that fails further down does not hide the real error
/// behind the CR-alone message: that message is for an error on the first line, where a file
/// with CR-only line ends has all of its text.
#[test]
fn a_stray_carriage_return_does_not_hide_a_later_error() {
    let obj = "# exported\rby tool\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n";
    assert_parse_err(
        parse_obj(obj.as_bytes(), "crbad.obj"),
        "crbad.obj",
        &["line 5:", "out of range"],
    );
    let ply = format!("{PLY_HEAD}0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n").replace('\n', "\r\r\n");
    let err = parse_ply(ply.as_bytes(), "crbad.ply").unwrap_err();
    assert_parse_err(Err(err.clone()), "crbad.ply", &["line 13:", "out of range"]);
    assert!(!err.message.contains("CR alone"), "{}", err.message);
}

#[test]
fn obj_crlf_line_endings() {
    let text = "v 0.5 0 0\r\nv 0 0.5 0\r\nv 0 0 0.5\r\n\r\nf 1 2 3\r\n";
    let mesh = parse_obj(text.as_bytes(), "crlf.obj").unwrap();
    assert_eq!(
        mesh.positions,
        vec![v(0.5, 0.0, 0.0), v(0.0, 0.5, 0.0), v(0.0, 0.0, 0.5)]
    );
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
}

// ---------------------------------------------------------------------------------------------
// Malformed files

const PLY_HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
    property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
    end_header\n";
// Body lines are numbered from 10.

#[test]
fn malformed_ascii_ply_errors_name_file_and_line() {
    let good_verts = "0 0 0\n1 0 0\n0 1 0\n";
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        ("empty.ply", String::new(), vec!["empty file"]),
        (
            "notply.ply",
            "hello\nworld\n".into(),
            vec!["line 1:", "not a PLY file"],
        ),
        (
            "fmt.ply",
            "ply\nformat binary_middle_endian 1.0\nend_header\n".into(),
            vec!["line 2:", "unknown format 'binary_middle_endian'"],
        ),
        (
            "noformat.ply",
            "ply\nelement vertex 0\nend_header\n".into(),
            vec!["line 3:", "no format line"],
        ),
        (
            "type.ply",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n".into(),
            vec!["line 4:", "unknown property type 'float128'"],
        ),
        (
            "listcount.ply",
            "ply\nformat ascii 1.0\nelement face 1\nproperty list float int vertex_indices\n"
                .into(),
            vec!["line 4:", "count type"],
        ),
        (
            "noend.ply",
            "ply\nformat ascii 1.0\nelement vertex 1\n".into(),
            vec!["line 4:", "no end_header"],
        ),
        (
            "endjunk.ply",
            "ply\nformat ascii 1.0\nelement vertex 0\nend_header garbage\n".into(),
            vec!["line 4:", "unexpected 'garbage'"],
        ),
        (
            "keyword.ply",
            "ply\nformat ascii 1.0\nbogus 1\nend_header\n".into(),
            vec!["line 3:", "'bogus'"],
        ),
        (
            "count.ply",
            "ply\nformat ascii 1.0\nelement vertex many\n".into(),
            vec!["line 3:", "'many'"],
        ),
        (
            "novertex.ply",
            "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\n\
             end_header\n"
                .into(),
            vec!["line 5:", "no 'vertex' element"],
        ),
        (
            "noface.ply",
            "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
             property float z\nend_header\n"
                .into(),
            vec!["line 7:", "no 'face' element"],
        ),
        (
            "noy.ply",
            "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float z\n\
             element face 0\nproperty list uchar int vertex_indices\nend_header\n"
                .into(),
            vec!["line 3:", "no 'y' property"],
        ),
        (
            "noindices.ply",
            "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
             property float z\nelement face 0\nproperty list uchar int idx\nend_header\n"
                .into(),
            vec!["line 7:", "vertex_indices"],
        ),
        (
            "huge.ply",
            "ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\n\
             property float y\nproperty float z\nelement face 1\n\
             property list uchar int vertex_indices\nend_header\n0 0 0\n3 0 0 0\n"
                .into(),
            vec!["line 3:", "4000000000"],
        ),
        (
            // Too short for the counts: refused from the header, before reading the body.
            "short.ply",
            format!("{PLY_HEAD}0 0 0\n1 0 0\n"),
            vec!["line 3:", "truncated", "'vertex' declares 3"],
        ),
        (
            // Long enough for the minimum sizes, so found while reading the body.
            "truncated.ply",
            format!("{PLY_HEAD}0.000000 0.000000 0.000000\n1.000000 0.000000 0.000000\n"),
            vec!["line 12:", "truncated", "vertex 2"],
        ),
        (
            "truncface.ply",
            format!("{PLY_HEAD}0.0 0.0 0.0\n1.0 0.0 0.0\n0.0 1.0 0.0\n"),
            vec!["line 13:", "truncated", "face 0"],
        ),
        (
            "shortline.ply",
            format!("{PLY_HEAD}0 0 0\n1 0\n0 1 0\n3 0 1 2\n"),
            vec!["line 11:", "missing value"],
        ),
        (
            "nonnumber.ply",
            format!("{PLY_HEAD}0 0 0\n1 abc 0\n0 1 0\n3 0 1 2\n"),
            vec!["line 11:", "'abc'"],
        ),
        (
            "nan.ply",
            format!("{PLY_HEAD}0 0 0\n1 0 0\n0 NaN 0\n3 0 1 2\n"),
            vec!["line 12:", "not a finite"],
        ),
        (
            "inf.ply",
            format!("{PLY_HEAD}0 0 inf\n1 0 0\n0 1 0\n3 0 1 2\n"),
            vec!["line 10:", "not a finite"],
        ),
        (
            "overflow.ply",
            format!("{PLY_HEAD}0 0 1e39\n1 0 0\n0 1 0\n3 0 1 2\n"),
            vec!["line 10:", "not a finite"],
        ),
        (
            "index.ply",
            format!("{PLY_HEAD}{good_verts}3 0 1 3\n"),
            vec!["line 13:", "index 3 out of range"],
        ),
        (
            "negindex.ply",
            format!("{PLY_HEAD}{good_verts}3 0 -1 2\n"),
            vec!["line 13:", "index -1 out of range"],
        ),
        (
            "twoverts.ply",
            format!("{PLY_HEAD}{good_verts}2 0 1\n"),
            vec!["line 13:", "face 0 has 2 vertices"],
        ),
        (
            "ucharcount.ply",
            format!("{PLY_HEAD}{good_verts}300 0 1 2\n"),
            vec!["line 13:", "'300'"],
        ),
        (
            "extra.ply",
            format!("{PLY_HEAD}{good_verts}3 0 1 2 7\n"),
            vec!["line 13:", "extra value '7'"],
        ),
        (
            "trailing.ply",
            format!("{PLY_HEAD}{good_verts}3 0 1 2\n\n3 0 1 2\n"),
            vec!["line 15:", "after the last element"],
        ),
        (
            "garbage.ply",
            format!("{PLY_HEAD}{good_verts}\u{1}\u{2}\u{3}\n"),
            // Control characters are shown escaped.
            vec!["line 13:", r"'\u{1}\u{2}\u{3}'"],
        ),
        (
            "cr.ply",
            format!("{PLY_HEAD}{good_verts}3 0 1 2\n").replace('\n', "\r"),
            vec!["CR alone"],
        ),
        (
            // Seven vertices declared, three given, and three faces: the vertices' count alone
            // fits the 42 bytes, so both counts are named (the faces' alone was blamed).
            "counts.ply",
            format!(
                "{}{good_verts}{}",
                PLY_HEAD
                    .replace("vertex 3", "vertex 7")
                    .replace("face 1", "face 3"),
                "3 0 1 2\n".repeat(3)
            ),
            vec![
                "line 7:",
                "'vertex' 7, 'face' 3",
                "need more than the 42 bytes",
            ],
        ),
    ];
    for (name, text, needles) in cases {
        assert_parse_err(parse_ply(text.as_bytes(), name), name, &needles);
    }
    // Non-UTF-8 bytes in an ASCII body.
    let mut bytes = format!("{PLY_HEAD}0 0 0\n").into_bytes();
    bytes.extend_from_slice(&[0xff, 0xfe, b'\n']);
    bytes.extend_from_slice(b"0 1 0\n3 0 1 2\n");
    assert_parse_err(parse_ply(&bytes, "latin.ply"), "latin.ply", &["line 11:"]);
}

const BIN_HEAD: &str = "ply\nformat binary_little_endian 1.0\nelement vertex 3\n\
    property float x\nproperty float y\nproperty float z\nelement face 1\n\
    property list uchar int vertex_indices\nend_header\n";

fn bin_verts(y1: f32) -> Bin {
    let mut b = Bin::new(BIN_HEAD, false);
    b.f32(0.0).f32(0.0).f32(0.0);
    b.f32(1.0).f32(y1).f32(0.0);
    b.f32(0.0).f32(1.0).f32(0.0);
    b
}

#[test]
fn malformed_binary_ply_errors_name_file_and_byte_offset() {
    let h = BIN_HEAD.len();
    let faces = h + 36; // first byte of the face element

    let mut good = bin_verts(0.0);
    good.u8(3).i32(0).i32(1).i32(2);
    assert_eq!(
        parse_ply(&good.buf, "good.bin.ply").unwrap().triangles,
        vec![[0, 1, 2]]
    );

    let truncated_verts = &good.buf[..h + 30];
    let truncated_face = &good.buf[..faces + 7];
    let mut nan = bin_verts(f32::NAN);
    nan.u8(3).i32(0).i32(1).i32(2);
    let mut inf = bin_verts(f32::NEG_INFINITY);
    inf.u8(3).i32(0).i32(1).i32(2);
    let mut index = bin_verts(0.0);
    index.u8(3).i32(0).i32(3).i32(2);
    let mut neg = bin_verts(0.0);
    neg.u8(3).i32(0).i32(1).i32(-5);
    let mut two = bin_verts(0.0);
    two.u8(2).i32(0).i32(1);
    let mut trailing = bin_verts(0.0);
    trailing.u8(3).i32(0).i32(1).i32(2).u8(0);
    // A face claiming 255 vertices with garbage after it.
    let mut garbage = bin_verts(0.0);
    garbage.u8(255);
    garbage.buf.extend_from_slice(&[0xAB; 11]);

    let cases: Vec<(&str, &[u8], Vec<String>)> = vec![
        (
            "trunc_verts.ply",
            truncated_verts,
            // Short of the 37 bytes the counts need at least: refused from the header.
            vec!["line 3:".into(), "truncated".into(), "30 bytes".into()],
        ),
        (
            "trunc_face.ply",
            truncated_face,
            vec![
                format!("byte offset {}:", faces + 5),
                "truncated".into(),
                "face 0".into(),
            ],
        ),
        (
            "nan.bin.ply",
            &nan.buf,
            vec![
                format!("byte offset {}:", h + 16),
                "vertex 1".into(),
                "not a finite".into(),
            ],
        ),
        (
            "inf.bin.ply",
            &inf.buf,
            vec![format!("byte offset {}:", h + 16), "not a finite".into()],
        ),
        (
            "index.bin.ply",
            &index.buf,
            vec![
                format!("byte offset {}:", faces + 5),
                "index 3 out of range".into(),
            ],
        ),
        (
            "neg.bin.ply",
            &neg.buf,
            vec![
                format!("byte offset {}:", faces + 9),
                "index -5 out of range".into(),
            ],
        ),
        (
            "two.bin.ply",
            &two.buf,
            vec![
                format!("byte offset {faces}:"),
                "face 0 has 2 vertices".into(),
            ],
        ),
        (
            "trailing.bin.ply",
            &trailing.buf,
            vec![
                format!("byte offset {}:", faces + 13),
                "after the last element".into(),
            ],
        ),
        (
            "garbage.bin.ply",
            &garbage.buf,
            vec![format!("byte offset {}:", faces + 1), "out of range".into()],
        ),
    ];
    for (name, bytes, needles) in cases {
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        assert_parse_err(parse_ply(bytes, name), name, &needles);
    }
}

#[test]
fn huge_counts_fail_fast_without_allocating() {
    // 4 billion vertices and faces claimed by a 200-byte file: must be refused from the header.
    for (format, line) in [("ascii", "line 3:"), ("binary_big_endian", "line 3:")] {
        let text = format!(
            "ply\nformat {format} 1.0\nelement vertex 4294967295\nproperty float x\n\
             property float y\nproperty float z\nelement face 4294967295\n\
             property list uchar int vertex_indices\nend_header\n0 0 0\n"
        );
        let start = Instant::now();
        assert_parse_err(
            parse_ply(text.as_bytes(), "huge.ply"),
            "huge.ply",
            &[line, "4294967295"],
        );
        assert!(start.elapsed().as_secs_f64() < 1.0);
    }
    // Faces alone too many for the bytes left after the vertices.
    let text = "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\n\
        property float y\nproperty float z\nelement face 18446744073709551615\n\
        property list uchar int vertex_indices\nend_header\n";
    assert_parse_err(
        parse_ply(text.as_bytes(), "u64.ply"),
        "u64.ply",
        &["line 7:"],
    );
    // A list length of 4 billion in a binary skipped element: computed size, not a crash.
    let mut b = Bin::new(
        "ply\nformat binary_little_endian 1.0\nelement junk 1\nproperty list uint double d\n\
         element vertex 0\nproperty float x\nproperty float y\nproperty float z\n\
         element face 0\nproperty list uchar int vertex_indices\nend_header\n",
        false,
    );
    let at = b.buf.len();
    b.u32(u32::MAX).f64(1.0);
    assert_parse_err(
        parse_ply(&b.buf, "biglist.ply"),
        "biglist.ply",
        &[&format!("byte offset {}:", at + 4), "truncated"],
    );
}

#[test]
fn random_garbage_is_a_parse_error_never_a_panic() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for round in 0..200 {
        let len = rng.below(300) as usize;
        let garbage: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
        // Raw garbage, and garbage behind a valid binary header.
        let mut behind = BIN_HEAD.as_bytes().to_vec();
        behind.extend_from_slice(&garbage);
        for (name, bytes) in [("g.ply", &garbage), ("gh.ply", &behind)] {
            match parse_ply(bytes, name) {
                Ok(_) => {} // a rare valid mesh is fine
                Err(e) => {
                    assert_eq!(e.status, Rt2Status::Parse, "round {round}: {}", e.message);
                    assert!(e.message.contains(name), "{}", e.message);
                    assert!(
                        e.message.contains("line ")
                            || e.message.contains("byte offset ")
                            || e.message.contains("empty file"),
                        "round {round}: no location in {}",
                        e.message
                    );
                }
            }
        }
        let e = parse_obj(&garbage, "g.obj").err();
        if let Some(e) = e {
            assert_eq!(e.status, Rt2Status::Parse);
            assert!(e.message.contains("g.obj"), "{}", e.message);
        }
    }
}

#[test]
fn malformed_obj_errors_name_file_and_line() {
    let cases: &[(&str, &str, &[&str])] = &[
        ("empty.obj", "", &["empty file"]),
        (
            "blank.obj",
            "\n  \n# only a comment\n",
            &["no statements", "only comments and blank lines"],
        ),
        (
            "cr.obj",
            "v 0 0 0\rv 1 0 0\rv 0 1 0\rf 1 2 3\r",
            &["CR alone"],
        ),
        ("nofaces.obj", "v 0 0 0\n", &["no faces"]),
        (
            "nonnumber.obj",
            "v 0 0 0\nv 1 x 0\n",
            &["line 2:", "'x' is not a number"],
        ),
        ("short.obj", "v 0 0\n", &["line 1:", "not 2 numbers"]),
        (
            "five.obj",
            "v 0 0 0 1 2\n",
            &["line 1:", "x y z r g b, not 5 numbers"],
        ),
        (
            "toolong.obj",
            "v 0 0 0 1 2 3 4\n",
            &["line 1:", "unexpected '4'"],
        ),
        (
            "nan.obj",
            "v 0 0 0\nv 0 0 0\nv nan 0 0\n",
            &["line 3:", "not a finite"],
        ),
        ("inf.obj", "v 0 -inf 0\n", &["line 1:", "not a finite"]),
        (
            "range.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
            &["line 4:", "index 4 out of range"],
        ),
        (
            "forward.obj",
            "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n",
            &["line 3:", "index 3 out of range"],
        ),
        (
            "negrange.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n",
            &["line 4:", "index -4 out of range"],
        ),
        (
            "hugeindex.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n",
            &["line 4:", "index 99999999999999999999 out of range"],
        ),
        (
            "hugeneg.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -99999999999999999999\n",
            &["line 4:", "index -99999999999999999999 out of range"],
        ),
        (
            "zero.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
            &["line 4:", "index 0"],
        ),
        (
            "twoverts.obj",
            "v 0 0 0\nv 1 0 0\nf 1 2\n",
            &["line 3:", "fewer than 3"],
        ),
        (
            "badref.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1/1 2 3\n",
            &["line 4:", "'1/1/1/1'"],
        ),
        (
            "badtex.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/a 2 3\n",
            &["line 4:", "'1/a'"],
        ),
        (
            "emptyn.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1// 2 3\n",
            &["line 4:", "'1//'"],
        ),
        (
            "notint.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2.5 3\n",
            &["line 4:", "'2.5'"],
        ),
        (
            "keyword.obj",
            "v 0 0 0\ncurv 0 1 1 2\n",
            &["line 2:", "'curv'"],
        ),
        (
            "crlf_err.obj",
            "v 0 0 0\r\nv 1 0 0\r\nv 0 q 0\r\n",
            &["line 3:", "'q'"],
        ),
    ];
    for (name, text, needles) in cases {
        assert_parse_err(parse_obj(text.as_bytes(), name), name, needles);
    }
    let bytes = b"v 0 0 0\nv 1 0 0\n\xff\xfe\n";
    assert_parse_err(parse_obj(bytes, "bin.obj"), "bin.obj", &["line 3:"]);
    // A byte that is not UTF-8 (Latin-1 'é') where a number belongs.
    let bytes = b"v 0 0 0\nv 1 \xe9 0\n";
    assert_parse_err(
        parse_obj(bytes, "latin1.obj"),
        "latin1.obj",
        &["line 2:", "is not a number"],
    );
    // A huge garbage token is cut short in the message.
    let long = format!("v 0 0 0\nv 0 {} 0\n", "z".repeat(10_000));
    let err = parse_obj(long.as_bytes(), "long.obj").unwrap_err();
    assert!(err.message.contains("line 2:"), "{}", err.message);
    assert!(err.message.contains("zzz...'"), "{}", err.message);
    assert!(err.message.len() < 200, "{}", err.message);
}

// ---------------------------------------------------------------------------------------------
// Files, extensions, I/O errors

/// A path named `file_name` in this test binary's scratch folder (`support::scratch`, under
/// `target/tmp`), nothing at it yet (a FIFO or link left by an earlier run is removed).
fn scratch_path(file_name: &str) -> PathBuf {
    let path = support::scratch("loaders").join(file_name);
    let _ = std::fs::remove_file(&path);
    path
}

/// A file named `file_name` in the scratch folder, holding `content`.
fn scratch_file(file_name: &str, content: &[u8]) -> PathBuf {
    let path = scratch_path(file_name);
    std::fs::write(&path, content).unwrap();
    path
}

/// A file whose geometry `rt2_scene_add_mesh` would refuse (a triangle whose edges overflow
/// f32) is INVALID_ARGUMENT through `rt2_scene_load_file`, naming the file and the triangle,
/// and adds nothing to the scene.
#[test]
fn a_file_with_a_triangle_beyond_f32_is_refused_naming_file_and_triangle() {
    use rt2::api::*;
    let path = scratch_file(
        "huge.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 3e38 0 0\nv -3e38 1 0\nf 1 2 3\nf 4 5 3\n",
    );
    let c_path = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
    let (mut ctx, mut scene) = (std::ptr::null_mut(), std::ptr::null_mut());
    // SAFETY: handles made and destroyed here; `c_path` is a C string.
    unsafe {
        assert_eq!(
            rt2_context_create(std::ptr::null(), &mut ctx),
            Rt2Status::Ok
        );
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        let mut id = 7;
        let status = rt2_scene_load_file(scene, c_path.as_ptr(), 0, &mut id);
        let message = support::last_error();
        assert_eq!(status, Rt2Status::InvalidArgument, "{message}");
        assert!(message.contains(&path.display().to_string()), "{message}");
        assert!(message.contains("triangle 1"), "{message}");
        assert_eq!(id, 7, "no id written");
        let mut stats = rt2_scene_statistics {
            struct_size: std::mem::size_of::<rt2_scene_statistics>() as u32,
            ..Default::default()
        };
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        assert_eq!(rt2_scene_stats(scene, &mut stats), Rt2Status::Ok);
        assert_eq!(stats.object_count, 0, "nothing added");
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

#[test]
fn load_mesh_picks_format_by_extension_case_insensitively() {
    let ply = scratch_file("Upper.PLY", &binary_with_extras(true));
    let obj = scratch_file("mixed.Obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    assert_eq!(load_mesh(&ply).unwrap().triangles.len(), 3);
    assert_eq!(load_mesh(&obj).unwrap().triangles, vec![[0, 1, 2]]);
    // The path is the name in parse errors.
    let bad = scratch_file("bad.obj", b"v 0 0\n");
    let err = load_mesh(&bad).unwrap_err();
    assert_eq!(err.status, Rt2Status::Parse);
    assert!(
        err.message.contains(&bad.display().to_string()),
        "{}",
        err.message
    );
    assert!(err.message.contains("line 1:"), "{}", err.message);
}

#[test]
fn load_mesh_rejects_other_extensions_as_unsupported() {
    for file in ["mesh.stl", "mesh", "mesh.ply.gz"] {
        let err = load_mesh(std::path::Path::new(file)).unwrap_err();
        assert_eq!(err.status, Rt2Status::Unsupported, "{}", err.message);
        assert!(err.message.contains(file), "{}", err.message);
        assert!(
            err.message.contains(".ply") && err.message.contains(".obj"),
            "{}",
            err.message
        );
    }
}

#[test]
fn missing_file_is_an_io_error_naming_the_path() {
    let path = std::env::temp_dir().join("rt2-definitely-missing-dir/nothing.ply");
    let err = load_mesh(&path).unwrap_err();
    assert_eq!(err.status, Rt2Status::Io, "{}", err.message);
    assert!(
        err.message.contains(&path.display().to_string()),
        "{}",
        err.message
    );
    let os = std::io::Error::from(std::io::ErrorKind::NotFound).to_string();
    assert!(
        err.message.contains("No such file") || err.message.contains(&os),
        "no OS error in {}",
        err.message
    );
}

/// Loads `path` on a thread and waits at most `limit` for it, so that a load that blocks (a
/// FIFO open) or reads without end (`/dev/zero`) fails the test instead of hanging it. A
/// load still running is left behind; it ends with the test process.
#[cfg(unix)]
fn load_within(path: &std::path::Path, limit: std::time::Duration) -> Result<Mesh> {
    let (tx, rx) = std::sync::mpsc::channel();
    let owned = path.to_path_buf();
    std::thread::spawn(move || {
        let _ = tx.send(load_mesh(&owned));
    });
    rx.recv_timeout(limit)
        .unwrap_or_else(|_| panic!("loading {} did not return within {limit:?}", path.display()))
}

/// Asserts an `Io` error that names `path` and says it is not a regular file.
#[cfg(unix)]
#[track_caller]
fn assert_not_regular(result: Result<Mesh>, path: &std::path::Path, kind: &str) {
    let err = result.expect_err("a special file must not load");
    assert_eq!(err.status, Rt2Status::Io, "{}", err.message);
    assert!(
        err.message.contains(&path.display().to_string()),
        "{}",
        err.message
    );
    assert!(
        err.message.contains("not a regular file"),
        "{}",
        err.message
    );
    assert!(err.message.contains(kind), "{}", err.message);
}

#[cfg(unix)]
#[test]
fn fifo_is_refused_promptly_not_waited_on() {
    let path = scratch_path("fifo.ply");
    let c_path = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
    // SAFETY: `c_path` is a C string.
    let made = unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) };
    assert_eq!(
        made,
        0,
        "mkfifo {}: {}",
        path.display(),
        std::io::Error::last_os_error()
    );
    // Nobody ever opens the FIFO for writing: a plain open would block forever.
    let result = load_within(&path, std::time::Duration::from_secs(5));
    assert_not_regular(result, &path, "FIFO");
}

#[cfg(unix)]
#[test]
fn symlink_to_dev_zero_is_refused_promptly_not_read() {
    let path = scratch_path("zero.ply");
    std::os::unix::fs::symlink("/dev/zero", &path).unwrap();
    // Read to the end, /dev/zero would fill memory; it must be refused without reading.
    let result = load_within(&path, std::time::Duration::from_secs(5));
    assert_not_regular(result, &path, "character device");
}

#[test]
fn directory_is_an_io_error() {
    let dir = scratch_path("dir.obj");
    std::fs::create_dir_all(&dir).unwrap();
    let err = load_mesh(&dir).unwrap_err();
    assert_eq!(err.status, Rt2Status::Io, "{}", err.message);
    assert!(
        err.message.contains(&dir.display().to_string()),
        "{}",
        err.message
    );
}

// ---------------------------------------------------------------------------------------------
// Round trip: one random mesh, four writers, identical results

struct RandomMesh {
    positions: Vec<Vec3>,
    polygons: Vec<Vec<u32>>,
}

impl RandomMesh {
    fn new(rng: &mut Rng) -> Self {
        let n = 1 + rng.below(40) as u32;
        let positions = (0..n)
            .map(|_| {
                let mut c = || {
                    if rng.below(2) == 0 {
                        rng.finite_f32()
                    } else {
                        (rng.below(2001) as f32 - 1000.0) / 64.0
                    }
                };
                Vec3::new(c(), c(), c())
            })
            .collect();
        let polygons = (0..rng.below(30))
            .map(|_| {
                (0..3 + rng.below(4))
                    .map(|_| rng.below(n.into()) as u32)
                    .collect()
            })
            .collect();
        RandomMesh {
            positions,
            polygons,
        }
    }

    fn expected(&self) -> Mesh {
        let mut triangles = Vec::new();
        for p in &self.polygons {
            for k in 1..p.len() - 1 {
                triangles.push([p[0], p[k], p[k + 1]]);
            }
        }
        Mesh {
            positions: self.positions.clone(),
            triangles,
        }
    }

    fn header(&self, format: &str) -> String {
        format!(
            "ply\nformat {format} 1.0\nelement vertex {}\nproperty float x\nproperty float y\n\
             property float z\nelement face {}\nproperty list uchar int vertex_indices\n\
             end_header\n",
            self.positions.len(),
            self.polygons.len()
        )
    }

    fn ascii_ply(&self) -> Vec<u8> {
        let mut s = self.header("ascii");
        for p in &self.positions {
            s += &format!("{} {} {}\n", p.x, p.y, p.z);
        }
        for f in &self.polygons {
            s += &f.len().to_string();
            for i in f {
                s += &format!(" {i}");
            }
            s += "\n";
        }
        s.into_bytes()
    }

    fn binary_ply(&self, big: bool) -> Vec<u8> {
        let format = if big {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        };
        let mut b = Bin::new(&self.header(format), big);
        for p in &self.positions {
            b.f32(p.x).f32(p.y).f32(p.z);
        }
        for f in &self.polygons {
            b.u8(f.len() as u8);
            for &i in f {
                b.i32(i as i32);
            }
        }
        b.buf
    }

    /// OBJ with a random mix of reference forms and of absolute/relative indices.
    fn obj(&self, rng: &mut Rng) -> Vec<u8> {
        let mut s = String::from("o random\r\n");
        for p in &self.positions {
            s += &format!("v {} {} {}\n", p.x, p.y, p.z);
        }
        s += "vt 0 0\nvn 0 0 1\n";
        let n = self.positions.len() as i64;
        for f in &self.polygons {
            s += "f";
            for &i in f {
                let idx = if rng.below(2) == 0 {
                    i as i64 + 1
                } else {
                    i as i64 - n
                };
                s += &match rng.below(4) {
                    0 => format!(" {idx}"),
                    1 => format!(" {idx}/1"),
                    2 => format!(" {idx}//-1"),
                    _ => format!(" {idx}/1/1"),
                };
            }
            s += if rng.below(2) == 0 { "\n" } else { "\r\n" };
        }
        s.into_bytes()
    }
}

#[test]
fn random_meshes_round_trip_identically_through_all_four_formats() {
    let mut rng = Rng(0x1234_5678_9abc_def1);
    for round in 0..100 {
        let mesh = RandomMesh::new(&mut rng);
        let expected = mesh.expected();
        if expected.triangles.is_empty() {
            // A file without faces is an error by design, in every format.
            assert!(
                parse_ply(&mesh.ascii_ply(), "r.ply").is_err(),
                "round {round}"
            );
            assert!(parse_ply(&mesh.binary_ply(false), "le.ply").is_err());
            assert!(parse_ply(&mesh.binary_ply(true), "be.ply").is_err());
            assert!(parse_obj(&mesh.obj(&mut rng), "r.obj").is_err());
            continue;
        }
        let ascii = parse_ply(&mesh.ascii_ply(), "r.ply").unwrap();
        let le = parse_ply(&mesh.binary_ply(false), "le.ply").unwrap();
        let be = parse_ply(&mesh.binary_ply(true), "be.ply").unwrap();
        let obj = parse_obj(&mesh.obj(&mut rng), "r.obj").unwrap();
        let bits = |m: &Mesh| -> Vec<[u32; 3]> {
            m.positions
                .iter()
                .map(|p| p.to_array().map(f32::to_bits))
                .collect()
        };
        for (got, format) in [
            (ascii, "ascii PLY"),
            (le, "binary LE PLY"),
            (be, "binary BE PLY"),
            (obj, "OBJ"),
        ] {
            assert_eq!(got, expected, "{format}, round {round}");
            // Bit-exact positions (PartialEq would accept -0 == 0).
            assert_eq!(bits(&got), bits(&expected), "{format}, round {round}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Shared Stanford models

fn shared_model(file: &str) -> Option<PathBuf> {
    support::shared_path(&format!("models/{file}"))
}

fn check_model(file: &str, vertices: usize, triangles: usize) -> Option<Mesh> {
    let path = shared_model(file)?;
    let start = Instant::now();
    let mesh = load_mesh(&path).unwrap();
    eprintln!(
        "{file}: {} vertices, {} triangles, loaded in {:.1} ms",
        mesh.positions.len(),
        mesh.triangles.len(),
        start.elapsed().as_secs_f64() * 1e3
    );
    assert_eq!(mesh.positions.len(), vertices, "{file}");
    assert_eq!(mesh.triangles.len(), triangles, "{file}");
    Some(mesh)
}

#[test]
fn shared_bunny_loads_with_69451_triangles_and_its_bbox() {
    let Some(mesh) = check_model("bunny.ply", 35_947, 69_451) else {
        return;
    };
    let lo = mesh.positions.iter().fold(Vec3::INFINITY, |a, &p| a.min(p));
    let hi = mesh
        .positions
        .iter()
        .fold(Vec3::NEG_INFINITY, |a, &p| a.max(p));
    // Bounding box as listed in shared/models/README.md.
    assert!(
        lo.abs_diff_eq(v(-0.09469, 0.032987, -0.061874), 1e-5),
        "{lo}"
    );
    assert!(hi.abs_diff_eq(v(0.061009, 0.187321, 0.0588), 1e-5), "{hi}");
}

#[test]
fn shared_dragon_loads_with_871414_triangles() {
    let Some(mesh) = check_model("dragon.ply", 437_645, 871_414) else {
        return;
    };
    let lo = mesh.positions.iter().fold(Vec3::INFINITY, |a, &p| a.min(p));
    let hi = mesh
        .positions
        .iter()
        .fold(Vec3::NEG_INFINITY, |a, &p| a.max(p));
    assert!(
        lo.abs_diff_eq(v(-0.108324, 0.0527295, -0.0504143), 1e-5),
        "{lo}"
    );
    assert!(
        hi.abs_diff_eq(v(0.0965662, 0.197173, 0.0412075), 1e-5),
        "{hi}"
    );
}

#[test]
fn shared_snowden_loads_with_37629_triangles() {
    check_model("snowden.ply", 18_743, 37_629);
}
