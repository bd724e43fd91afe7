//! The README's thread rules through the C API: one context and one scene used from many
//! threads at once. Renders (each into its own frame) and queries run concurrently with each
//! other and with a thread that edits and commits the scene. The edits leave the scene as it
//! was (the same transform set again), so every call that succeeds must give the single-thread
//! answer; a call that meets the scene between an edit and its commit is refused with
//! `RT2_STATUS_INVALID_OPERATION`, as documented, and nothing else may happen.

use rt2::api::*;
use rt2::error::Rt2Status;
use std::ptr::{null, null_mut};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// Raw handles shared by the scoped threads: the library's handles are made for that.
#[derive(Clone, Copy)]
struct Shared {
    ctx: *mut rt2_context,
    scene: *mut rt2_scene,
    camera: *mut rt2_camera,
}

// SAFETY: the C API documents contexts and scenes as usable from any number of threads; the
// camera is only read by renders.
unsafe impl Send for Shared {}
unsafe impl Sync for Shared {}

const IDENTITY: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
const SIZE: (u32, u32) = (64, 48);

unsafe fn render(h: Shared) -> (Rt2Status, Vec<u8>) {
    let mut frame = null_mut();
    assert_eq!(rt2_frame_create(SIZE.0, SIZE.1, &mut frame), Rt2Status::Ok);
    let st = rt2_render(h.ctx, h.scene, h.camera, null(), frame);
    let n = (4 * SIZE.0 * SIZE.1) as usize;
    let pixels = std::slice::from_raw_parts(rt2_frame_pixels(frame), n).to_vec();
    rt2_frame_destroy(frame);
    (st, pixels)
}

unsafe fn query(h: Shared, rays: &[rt2_ray]) -> (Rt2Status, Vec<(u32, u32, u32)>) {
    let miss = rt2_hit {
        t: 0.0,
        u: 0.0,
        v: 0.0,
        object: 0,
        prim: 0,
    };
    let mut hits = vec![miss; rays.len()];
    let st = rt2_intersect(
        h.ctx,
        h.scene,
        rays.as_ptr(),
        rays.len(),
        hits.as_mut_ptr(),
        null(),
        null_mut(),
    );
    let key = hits
        .iter()
        .map(|h| (h.t.to_bits(), h.object, h.prim))
        .collect();
    (st, key)
}

/// Sets object `k`'s transform to the identity it already has, then commits.
unsafe fn edit_and_commit(h: Shared, k: u32) -> [(&'static str, Rt2Status, bool); 2] {
    let set = rt2_scene_set_transform(h.scene, k, IDENTITY.as_ptr());
    let commit = rt2_scene_commit(h.scene);
    [("edit", set, true), ("commit", commit, true)]
}

#[test]
fn renders_queries_and_commits_share_a_context_and_a_scene() {
    unsafe {
        let mut ctx = null_mut();
        assert_eq!(rt2_context_create(null(), &mut ctx), Rt2Status::Ok);
        let mut scene = null_mut();
        assert_eq!(rt2_scene_create(ctx, &mut scene), Rt2Status::Ok);
        for k in 0..30 {
            let c = [(k % 6) as f32 - 2.5, (k / 6) as f32 - 2.0, -(k % 3) as f32];
            let mut id = 0;
            assert_eq!(
                rt2_scene_add_sphere(scene, c.as_ptr(), 0.45, 0, &mut id),
                Rt2Status::Ok
            );
        }
        assert_eq!(rt2_scene_commit(scene), Rt2Status::Ok);
        let mut camera = null_mut();
        assert_eq!(rt2_camera_create(&mut camera), Rt2Status::Ok);
        let (eye, at, up) = ([0.0f32, 0.0, 8.0], [0.0f32, 0.0, 0.0], [0.0f32, 1.0, 0.0]);
        assert_eq!(
            rt2_camera_look_at(camera, eye.as_ptr(), at.as_ptr(), up.as_ptr()),
            Rt2Status::Ok
        );
        let h = Shared { ctx, scene, camera };
        let rays: Vec<rt2_ray> = (0..2000)
            .map(|i| {
                let a = i as f32 * 0.61;
                rt2_ray {
                    org: [0.0, 0.0, 10.0],
                    tmin: 0.0,
                    dir: [0.3 * a.sin(), 0.25 * a.cos(), -1.0],
                    tmax: f32::INFINITY,
                }
            })
            .collect();
        let (st, want_image) = render(h);
        assert_eq!(st, Rt2Status::Ok);
        let (st, want_hits) = query(h, &rays);
        assert_eq!(st, Rt2Status::Ok);
        assert!(want_hits.iter().any(|k| k.1 != RT2_INVALID_ID));

        let (rays, want_image, want_hits) = (&rays, &want_image, &want_hits);
        // Renders (0) and queries (1) that succeeded so far. The editor waits, after each
        // commit, for one of each to succeed before its next edit (up to a few seconds), and
        // the workers go on until it is done: calls then succeed between the edits on a busy
        // machine too, where a fixed number of fast calls could all meet the scene between an
        // edit and its commit.
        let ok = [AtomicUsize::new(0), AtomicUsize::new(0)];
        let editing = AtomicBool::new(true);
        let (ok, editing) = (&ok, &editing);
        let worker = move |kind: usize, at_least: usize, call: &dyn Fn() -> (Rt2Status, bool)| {
            let mut out = Vec::new();
            while out.len() < at_least || editing.load(Ordering::Acquire) {
                let (st, same) = call();
                if st == Rt2Status::Ok {
                    ok[kind].fetch_add(1, Ordering::Release);
                }
                out.push((["render", "query"][kind], st, same));
            }
            out
        };
        let results: Vec<(&str, Rt2Status, bool)> = std::thread::scope(|s| {
            let mut workers = Vec::new();
            for _ in 0..3 {
                workers.push(s.spawn(move || {
                    worker(0, 6, &|| {
                        let (st, img) = render(h);
                        (st, &img == want_image)
                    })
                }));
            }
            for _ in 0..2 {
                workers.push(s.spawn(move || {
                    worker(1, 10, &|| {
                        let (st, hits) = query(h, rays);
                        (st, &hits == want_hits)
                    })
                }));
            }
            workers.push(s.spawn(move || {
                let mut out = Vec::new();
                for k in 0..8u32 {
                    out.extend(edit_and_commit(h, k));
                    // Counted from the commit on: a call that succeeded before the edit says
                    // nothing about the committed scene.
                    let before = ok.each_ref().map(|n| n.load(Ordering::Acquire));
                    let start = Instant::now();
                    while (0..2).any(|i| ok[i].load(Ordering::Acquire) == before[i])
                        && start.elapsed() < Duration::from_secs(5)
                    {
                        std::thread::yield_now();
                    }
                }
                editing.store(false, Ordering::Release);
                out
            }));
            workers
                .into_iter()
                .flat_map(|w| w.join().expect("no thread panics"))
                .collect()
        });
        let mut succeeded = [0, 0];
        for (what, st, same) in &results {
            match (*what, st) {
                ("edit" | "commit", st) => assert_eq!(*st, Rt2Status::Ok, "{what}"),
                (_, Rt2Status::Ok) => {
                    assert!(same, "a concurrent {what} gave another answer");
                    succeeded[(*what == "query") as usize] += 1;
                }
                // The scene was between an edit and its commit.
                (_, st) => assert_eq!(*st, Rt2Status::InvalidOperation, "{what}"),
            }
        }
        assert!(
            succeeded[0] > 0 && succeeded[1] > 0,
            "renders and queries that succeeded: {succeeded:?}"
        );
        // After the last commit every call succeeds again, with the same answers.
        assert_eq!(render(h), (Rt2Status::Ok, want_image.clone()));
        assert_eq!(query(h, rays), (Rt2Status::Ok, want_hits.clone()));
        rt2_camera_destroy(camera);
        rt2_scene_destroy(scene);
        rt2_context_destroy(ctx);
    }
}

/// Set in the child process of [`default_thread_count_follows_rayon_num_threads_up_to_the_cap`]:
/// the worker count that context must report.
const CHILD_EXPECTS: &str = "RT2_TEST_THREADS_EXPECTED";

/// `threads = 0` takes `RAYON_NUM_THREADS` when it is set (the C examples' harness keeps
/// parallel test runs from oversubscribing the machine with it), and never more than the
/// documented 1024: handed 0, rayon started as many workers as the variable said (2000 took
/// 2 s and the context reported 2000 threads). Each count runs in a child process of this test
/// binary, whose environment no other test shares.
#[test]
fn default_thread_count_follows_rayon_num_threads_up_to_the_cap() {
    if let Ok(want) = std::env::var(CHILD_EXPECTS) {
        let mut d = rt2_context_desc_default();
        d.backend = Rt2Backend::Cpu as u32;
        assert_eq!(d.threads, 0);
        let mut ctx = null_mut();
        unsafe {
            assert_eq!(rt2_context_create(&d, &mut ctx), Rt2Status::Ok);
            let mut p: rt2_context_properties = std::mem::zeroed();
            p.struct_size = std::mem::size_of::<rt2_context_properties>() as u32;
            assert_eq!(rt2_context_info(ctx, &mut p), Rt2Status::Ok);
            rt2_context_destroy(ctx);
            assert_eq!(
                p.threads.to_string(),
                want,
                "threads of a context asked for 0"
            );
        }
        return;
    }
    let exe = std::env::current_exe().expect("the test knows its own path");
    for (rayon, want) in [("3", 3), ("1500", 1024)] {
        let out = std::process::Command::new(&exe)
            .args([
                "--exact",
                "default_thread_count_follows_rayon_num_threads_up_to_the_cap",
                "--test-threads",
                "1",
            ])
            .env("RAYON_NUM_THREADS", rayon)
            .env("RT2_BACKEND", "cpu")
            .env(CHILD_EXPECTS, want.to_string())
            .output()
            .expect("the test binary runs");
        assert!(
            out.status.success(),
            "RAYON_NUM_THREADS={rayon}, expected {want} threads:\n{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
