//! The OBJ loader on arbitrary bytes: an error is the right answer to bad input, a panic,
//! abort or runaway allocation is a bug.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = rt2::scene::loaders::parse_obj(data, "fuzz.obj") {
        let n = mesh.positions.len() as u32;
        assert!(mesh.triangles.iter().flatten().all(|&i| i < n));
    }
});
