//! Closed triangle meshes of analytic shapes: the stress cases of the watertight test (a ray
//! from inside must always hit) and the "tessellated equivalent" the memory report compares
//! analytic primitives with. RT2 never tessellates what it can trace analytically; these are
//! for measurement.

use glam::Vec3;
use std::f32::consts::{PI, TAU};

/// An indexed triangle mesh, counter-clockwise seen from outside.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Closed and consistently oriented: every directed edge is used once and its reverse once.
    pub fn is_closed(&self) -> bool {
        let mut directed = std::collections::HashMap::new();
        for t in &self.triangles {
            for k in 0..3 {
                *directed.entry((t[k], t[(k + 1) % 3])).or_insert(0u32) += 1;
            }
        }
        directed
            .iter()
            .all(|(&(a, b), &n)| n == 1 && directed.get(&(b, a)) == Some(&1))
    }

    /// The mesh under `p -> p * scale + offset`.
    pub fn placed(&self, scale: f32, offset: Vec3) -> Mesh {
        Mesh {
            positions: self.positions.iter().map(|&p| p * scale + offset).collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// Midpoints of every edge (each shared edge twice): targets for rays along edges.
    pub fn edge_midpoints(&self) -> Vec<Vec3> {
        self.triangles
            .iter()
            .flat_map(|t| (0..3).map(move |k| (t[k] as usize, t[(k + 1) % 3] as usize)))
            .map(|(a, b)| 0.5 * (self.positions[a] + self.positions[b]))
            .collect()
    }
}

/// The unit sphere as `rings` bands of `segments` quads, with single vertices at the poles
/// (where fans of thin triangles meet: the worst vertices for a non-watertight test).
pub fn uv_sphere(rings: u32, segments: u32) -> Mesh {
    let (rings, segments) = (rings.max(2), segments.max(3));
    let mut positions = vec![Vec3::Y];
    for i in 1..rings {
        let th = PI * i as f32 / rings as f32;
        for j in 0..segments {
            let ph = TAU * j as f32 / segments as f32;
            positions.push(Vec3::new(
                th.sin() * ph.cos(),
                th.cos(),
                th.sin() * ph.sin(),
            ));
        }
    }
    positions.push(-Vec3::Y);
    let south = positions.len() as u32 - 1;
    let at = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let mut triangles = Vec::new();
    for j in 0..segments {
        triangles.push([0, at(1, j + 1), at(1, j)]);
        triangles.push([south, at(rings - 1, j), at(rings - 1, j + 1)]);
        for i in 1..rings - 1 {
            triangles.push([at(i, j), at(i, j + 1), at(i + 1, j)]);
            triangles.push([at(i, j + 1), at(i + 1, j + 1), at(i + 1, j)]);
        }
    }
    Mesh {
        positions,
        triangles,
    }
}

/// A torus around the y axis (major radius 1, minor `minor`), `n × m` quads.
pub fn torus(n: u32, m: u32, minor: f32) -> Mesh {
    let (n, m) = (n.max(3), m.max(3));
    let mut positions = Vec::new();
    for i in 0..n {
        let u = TAU * i as f32 / n as f32;
        for j in 0..m {
            let v = TAU * j as f32 / m as f32;
            let r = 1.0 + minor * v.cos();
            positions.push(Vec3::new(r * u.cos(), minor * v.sin(), r * u.sin()));
        }
    }
    let at = |i: u32, j: u32| (i % n) * m + j % m;
    let mut triangles = Vec::new();
    for i in 0..n {
        for j in 0..m {
            triangles.push([at(i, j), at(i, j + 1), at(i + 1, j)]);
            triangles.push([at(i, j + 1), at(i + 1, j + 1), at(i + 1, j)]);
        }
    }
    Mesh {
        positions,
        triangles,
    }
}

/// The unit cube `[0, 1]³` as 12 triangles: its faces lie in the planes of its own bounding box,
/// where the kd-tree's scene box and leaf faces are.
pub fn cube() -> Mesh {
    let positions = (0..8)
        .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
        .collect();
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let triangles = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Mesh {
        positions,
        triangles,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_meshes_are_closed_and_an_open_one_is_not() {
        for m in [
            uv_sphere(12, 24),
            uv_sphere(2, 3),
            torus(24, 12, 0.35),
            cube(),
        ] {
            assert!(m.is_closed(), "{} triangles", m.triangles.len());
        }
        let mut open = cube();
        open.triangles.pop();
        assert!(!open.is_closed());
        let mut flipped = cube();
        flipped.triangles[0].swap(0, 1);
        assert!(!flipped.is_closed());
    }
}
