//! The ray query API on arbitrary scenes and rays (any f32 bit pattern: NaN, inf, denormals,
//! 1e38): every traversal with every intersector must return without panicking, and
//! `occluded` must agree with `intersect` (a hit exists or not).
#![no_main]
use glam::Vec3;
use libfuzzer_sys::fuzz_target;
use rt2::cpu::traverse::{intersect, occluded, Traversal, TraverseOptions};
use rt2::geometry::{Ray, TraversalStats};
use rt2::precision::Intersector;
use rt2::scene::{Scene, Shape};

fuzz_target!(|data: &[u8]| {
    let Some((&head, body)) = data.split_first() else {
        return;
    };
    let f: Vec<f32> = body
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let v = |i: usize| Vec3::new(f[i], f[i + 1], f[i + 2]);
    // The head byte splits the floats between triangles (9 each), spheres (4) and rays (8).
    let tris = (head as usize & 15).min(f.len() / 9);
    let spheres = ((head as usize >> 4) & 3).min((f.len() - 9 * tris) / 4);
    let mut scene = Scene::new();
    let positions: Vec<Vec3> = (0..3 * tris).map(|k| v(3 * k)).collect();
    let triangles = (0..tris as u32)
        .map(|k| [3 * k, 3 * k + 1, 3 * k + 2])
        .collect();
    // Invalid shapes (non-finite coordinates, bad radii) are refused: that is fine.
    let _ = scene.add_object(
        Shape::Mesh {
            positions,
            triangles,
        },
        0,
    );
    for s in 0..spheres {
        let i = 9 * tris + 4 * s;
        let _ = scene.add_object(
            Shape::Sphere {
                center: v(i),
                radius: f[i + 3],
            },
            0,
        );
    }
    if scene.commit().is_err() || scene.ensure_ropes().is_err() {
        return;
    }
    let _ = scene.ensure_exact_vertices();
    let Ok(c) = scene.committed() else {
        return;
    };
    let start = 9 * tris + 4 * spheres;
    for r in f[start..].chunks_exact(8).take(16) {
        let ray = Ray::new(
            Vec3::new(r[0], r[1], r[2]),
            Vec3::new(r[3], r[4], r[5]),
            r[6],
            r[7],
        );
        for intersector in Intersector::ALL {
            let opts = TraverseOptions {
                intersector,
                short_stack_size: (head as usize >> 6) + 1,
                ..TraverseOptions::default()
            };
            for how in Traversal::ALL {
                let mut st = TraversalStats::default();
                let hit = intersect(&c.tree, &c.prims, &ray, how, &opts, &mut st);
                let occ = occluded(&c.tree, &c.prims, &ray, how, &opts, &mut st);
                assert_eq!(
                    occ,
                    hit.is_hit(),
                    "{how:?} {intersector:?} {ray:?}: {hit:?}"
                );
            }
        }
    }
});
