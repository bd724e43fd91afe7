//! Primitives renumbered for spatial locality (the kd-tree issue's layout): after the build,
//! the bounded primitives of each kind are numbered in the order the tree's leaf lists first
//! name them, so that the primitives of neighbouring leaves are neighbours in memory and a
//! traversal's leaf tests read fewer cache lines. The tree's lists and the origins follow the
//! new numbers; what callers see of a hit (its object and the primitive's index in the object)
//! does not change.

use super::PrimOrigin;
use crate::fallible::{self, Fallible};
use crate::geometry::PrimitiveSet;
use crate::kdtree::KdTree;

/// Renumbers the bounded primitives of `prims` (planes keep their numbers), with `origins` and
/// the leaf lists of `tree` (each list stays ascending).
///
/// Fails when its tables cannot be allocated, with `prims`, `origins` and `tree` part renumbered:
/// the commit that called it then throws them away.
pub(super) fn renumber(
    prims: &mut PrimitiveSet,
    origins: &mut [PrimOrigin],
    tree: &mut KdTree,
) -> Fallible<()> {
    let counts = [
        prims.triangles.len(),
        prims.spheres.len(),
        prims.ellipsoids.len(),
        prims.boxes.len(),
    ];
    let n = counts.iter().sum::<usize>();
    let starts = [0, counts[0], counts[0] + counts[1], n - counts[3]];
    let kind = |p: usize| starts.iter().rposition(|&s| p >= s).unwrap_or(0);
    // Old numbers in their new order, kind by kind: first as the leaves list them, then those
    // no leaf holds (empty or non-finite bounds) in their old order.
    let mut by_kind: [Vec<u32>; 4] = Default::default();
    for (list, count) in by_kind.iter_mut().zip(counts) {
        *list = fallible::with_capacity(count)?;
    }
    let mut seen = fallible::filled(false, n)?;
    let unlisted = 0..n as u32;
    for p in tree.prim_indices.iter().copied().chain(unlisted) {
        if !std::mem::replace(&mut seen[p as usize], true) {
            by_kind[kind(p as usize)].push(p);
        }
    }
    let mut order = fallible::with_capacity(n)?;
    for list in &by_kind {
        order.extend_from_slice(list);
    }
    let mut new_of = fallible::filled(0u32, n)?;
    for (new, &old) in order.iter().enumerate() {
        new_of[old as usize] = new as u32;
    }

    let [tri, sph, ell, bx] = starts;
    prims.triangles = permuted(&prims.triangles, &order[..sph], tri)?;
    if !prims.vertices.is_empty() {
        prims.vertices = permuted(&prims.vertices, &order[..sph], tri)?;
    }
    prims.spheres = permuted(&prims.spheres, &order[sph..ell], sph)?;
    prims.ellipsoids = permuted(&prims.ellipsoids, &order[ell..bx], ell)?;
    prims.boxes = permuted(&prims.boxes, &order[bx..], bx)?;
    let bounded = permuted(&origins[..n], &order, 0)?;
    origins[..n].copy_from_slice(&bounded);

    for p in &mut tree.prim_indices {
        *p = new_of[*p as usize];
    }
    for n in tree.nodes.iter().filter(|n| n.is_leaf()) {
        tree.prim_indices[n.prim_range()].sort_unstable();
    }
    Ok(())
}

/// `v` in the order `old` gives, each number counted from `base` (the kind's first number).
fn permuted<T: Copy>(v: &[T], old: &[u32], base: usize) -> Fallible<Vec<T>> {
    fallible::collect(old.iter().map(|&o| v[o as usize - base]))
}

#[cfg(test)]
mod tests {
    use super::super::{Scene, Shape};
    use glam::Vec3;

    /// A scrambled grid of triangles with spheres and boxes among them: after the commit the
    /// triangles of the first leaves come first, every kind keeps its own range, each origin
    /// still names the primitive it came from (same geometry), and every leaf list stays
    /// ascending. (That the renamed lists still find every hit is the business of the
    /// traversal, ray-set and precision tests, which all trace committed scenes.)
    #[test]
    fn renumbering_follows_the_leaves_and_keeps_every_primitive() {
        let mut scene = Scene::new();
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        // Cells visited in a scrambled order so that file order is not spatial order.
        for k in 0..400u32 {
            let cell = (k * 173) % 400;
            let (x, y) = ((cell % 20) as f32, (cell / 20) as f32);
            let base = positions.len() as u32;
            positions.extend([
                Vec3::new(x, y, 0.0),
                Vec3::new(x + 0.9, y, 0.0),
                Vec3::new(x, y + 0.9, 0.1),
            ]);
            triangles.push([base, base + 1, base + 2]);
        }
        let mesh = Shape::Mesh {
            positions: positions.clone(),
            triangles: triangles.clone(),
        };
        scene.add_object(mesh, 0).unwrap();
        for k in 0..30 {
            let c = Vec3::new(((k * 7) % 20) as f32, ((k * 11) % 20) as f32, 2.0);
            let sphere = Shape::Sphere {
                center: c,
                radius: 0.3,
            };
            scene.add_object(sphere, 0).unwrap();
            let b = Shape::Box {
                min: c - Vec3::new(0.2, 0.2, 3.0),
                max: c - Vec3::new(-0.2, -0.2, 2.8),
            };
            scene.add_object(b, 0).unwrap();
        }
        scene.commit().unwrap();
        let c = scene.committed().unwrap();
        let (nt, ns) = (c.prims.triangles.len(), c.prims.spheres.len());
        assert_eq!((nt, ns, c.prims.boxes.len()), (400, 30, 30));

        // Same geometry behind every origin.
        for (i, o) in c.origins[..nt].iter().enumerate() {
            assert_eq!(o.object, 0);
            let [a, b, d] = triangles[o.prim as usize].map(|v| positions[v as usize]);
            let t = crate::geometry::Triangle::from_vertices(a, b, d);
            assert_eq!(c.prims.triangles[i], t, "triangle {i}");
        }
        for (k, o) in c.origins[nt..nt + ns].iter().enumerate() {
            assert_eq!(o.object % 2, 1, "spheres are the odd objects");
            assert_eq!(c.prims.spheres[k].radius, 0.3);
        }
        for o in &c.origins[nt + ns..] {
            assert!(
                o.object > 0 && o.object % 2 == 0,
                "boxes are the even objects after 0"
            );
        }

        // Numbered in the order the leaves first list them, kind by kind.
        let mut first_seen = Vec::new();
        for &p in &c.tree.prim_indices {
            if !first_seen.contains(&p) {
                first_seen.push(p);
            }
        }
        let triangles_seen: Vec<u32> = first_seen
            .iter()
            .copied()
            .filter(|&p| (p as usize) < nt)
            .collect();
        assert_eq!(triangles_seen, (0..nt as u32).collect::<Vec<_>>());
        assert_ne!(
            c.origins[..nt].iter().map(|o| o.prim).collect::<Vec<_>>(),
            (0..nt as u32).collect::<Vec<_>>(),
            "the scrambled file order was kept: nothing was renumbered"
        );
        for &leaf in c.tree.nodes.iter().filter(|n| n.is_leaf()) {
            assert!(c.tree.leaf_prims(leaf).windows(2).all(|w| w[0] < w[1]));
        }
    }
}
