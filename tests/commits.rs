//! What `Scene::commit` redoes after each kind of edit: nothing after none; the material and
//! light arrays alone after only those were added (the tree and what was built on it kept);
//! every placement and the tree after objects, transforms, enabled states or build options
//! changed. Before, every commit rebuilt everything: 170 ms on the bunny and 3.8 s on the
//! dragon for a commit with no edit, or for a light added.

use glam::{Affine3A, Vec3};
use rt2::context::{Context, QueryOptions};
use rt2::dispatch::BackendRequest;
use rt2::geometry::{Hit, Ray};
use rt2::kdtree::{BuildOptions, Builder};
use rt2::scene::{Material, PointLight, Scene, Shape};

/// Closest hits of a fan of rays towards the origin.
fn hits(ctx: &Context, s: &Scene) -> Vec<Hit> {
    let rays: Vec<Ray> = (0..64)
        .map(|k| {
            let org = Vec3::new(k as f32 * 0.05 - 1.6, 0.3, 5.0);
            Ray::new(org, -Vec3::Z, 0.0, f32::INFINITY)
        })
        .collect();
    let mut hits = vec![Hit::MISS; rays.len()];
    let c = s.committed().unwrap();
    ctx.intersect(c, &rays, &mut hits, &QueryOptions::default())
        .unwrap();
    hits
}

/// A committed scene of two spheres side by side.
fn two_spheres() -> Scene {
    let mut s = Scene::new();
    for x in [-1.0, 1.0] {
        let center = Vec3::new(x, 0.0, 0.0);
        s.add_object(
            Shape::Sphere {
                center,
                radius: 0.9,
            },
            0,
        )
        .unwrap();
    }
    s.commit().unwrap();
    s
}

#[test]
fn a_commit_redoes_only_what_the_edits_made_stale() {
    let ctx = Context::new(BackendRequest::Cpu, 1).unwrap();
    let mut s = two_spheres();
    s.ensure_ropes().unwrap();
    let first = s.committed().unwrap();
    let (id, nodes, before) = (first.id, first.tree.nodes.as_ptr(), hits(&ctx, &s));
    assert!(before.iter().filter(|h| h.is_hit()).count() > 20);

    // No edit: the same commit.
    s.commit().unwrap();
    let c = s.committed().unwrap();
    assert_eq!((c.id, c.tree.nodes.as_ptr()), (id, nodes));

    // A material and a light: queries wait for a commit, which keeps the tree and its ropes.
    s.add_material(Material::default()).unwrap();
    s.add_light(PointLight {
        position: Vec3::splat(5.0),
        color: Vec3::ONE,
        intensity: 1.0,
    })
    .unwrap();
    assert!(s.committed().is_err(), "stale until committed");
    s.commit().unwrap();
    let c = s.committed().unwrap();
    assert_ne!(c.id, id, "a new commit, for the GPU's copy to check");
    assert_eq!(c.tree.nodes.as_ptr(), nodes, "the tree was kept");
    assert!(c.tree.ropes.is_some(), "and its ropes");
    assert_eq!((c.materials.len(), c.lights.len()), (2, 1));
    assert_eq!(hits(&ctx, &s), before);

    // A transform: everything placed and built again, the sphere where it was moved.
    s.set_transform(1, Affine3A::from_translation(Vec3::new(0.0, 10.0, 0.0)))
        .unwrap();
    s.commit().unwrap();
    let c = s.committed().unwrap();
    assert_eq!(c.bounds.max.y, 10.9, "{:?}", c.bounds);
    assert!(c.tree.ropes.is_none(), "a new tree");
    let moved = hits(&ctx, &s);
    assert!(moved.iter().zip(&before).any(|(m, b)| m != b));

    // Build options: a new tree of the other builder; the hits stay.
    let id = c.id;
    s.set_build_options(BuildOptions {
        builder: Builder::Midpoint,
        ..BuildOptions::default()
    });
    s.commit().unwrap();
    let c = s.committed().unwrap();
    assert_ne!(c.id, id);
    assert_eq!(s.build_options().builder, Builder::Midpoint);
    assert_eq!(hits(&ctx, &s), moved);
}

/// Enabling or disabling an object is a geometry edit: the next commit builds a new tree. Setting
/// the state an object already has is no edit: the scene stays committed and the next commit
/// is the same one (it rebuilt everything before `set_enabled` compared the states).
#[test]
fn enabled_state_rebuilds_only_when_it_changes() {
    let ctx = Context::new(BackendRequest::Cpu, 1).unwrap();
    let mut s = two_spheres();
    let c = s.committed().unwrap();
    let (id, nodes, before) = (c.id, c.tree.nodes.as_ptr(), hits(&ctx, &s));

    s.set_enabled(0, true).unwrap();
    assert!(
        s.committed().is_ok(),
        "enabling an enabled object made the scene stale"
    );
    s.commit().unwrap();
    let c = s.committed().unwrap();
    assert_eq!((c.id, c.tree.nodes.as_ptr()), (id, nodes));

    s.set_enabled(0, false).unwrap();
    assert!(s.committed().is_err(), "stale until committed");
    s.commit().unwrap();
    let c = s.committed().unwrap();
    assert_ne!(c.id, id, "a new commit");
    assert_eq!(c.prims.spheres.len(), 1);
    let (id, disabled) = (c.id, hits(&ctx, &s));
    let on = |h: &Hit| h.is_hit().then(|| c.origins[h.prim as usize].object);
    assert!(
        disabled.iter().all(|h| on(h) != Some(0)),
        "sphere 0 was hit"
    );
    assert!(disabled != before);

    s.set_enabled(0, false).unwrap();
    s.commit().unwrap();
    assert_eq!(
        s.committed().unwrap().id,
        id,
        "disabled again: the same commit"
    );

    s.set_enabled(0, true).unwrap();
    s.commit().unwrap();
    assert_eq!(hits(&ctx, &s), before, "enabled again: the first hits");
    assert!(s.set_enabled(2, false).is_err(), "object 2 does not exist");
}
