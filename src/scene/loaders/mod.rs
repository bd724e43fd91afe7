//! Mesh file loaders (PLY ASCII/binary, OBJ). Errors name the file and the line or byte offset.

use glam::Vec3;

/// A triangle mesh as read from a file: positions and triangles (polygons fan-triangulated).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}
