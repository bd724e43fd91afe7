//! Shared by the integration tests that compile C against `include/rt2.h` or load the built
//! shared library: where the library is, and a `cc` compiler configured outside build.rs.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// `target/<profile>`: the test executable lives in `target/<profile>/deps`, and `cargo test`
/// builds the library's cdylib next to it (the crate's `crate-type` list includes it).
pub fn profile_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test knows its own path");
    let deps = exe
        .parent()
        .expect("the test executable has a parent directory");
    deps.parent()
        .expect("target/<profile>/deps has a parent")
        .to_path_buf()
}

/// The shared library that `cargo test` built for this run: `target/<profile>/deps/librt2.so`,
/// beside the test executable. (`target/<profile>/librt2.so` is only refreshed by `cargo build`,
/// so it can be stale during `cargo test`, or absent on a fresh clone.)
pub fn shared_library() -> PathBuf {
    let name = format!(
        "{}rt2{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    );
    let path = profile_dir().join("deps").join(name);
    assert!(
        path.is_file(),
        "{} is missing: it is built by `cargo test` / `cargo build` as the crate's cdylib",
        path.display()
    );
    path
}

pub fn manifest_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Scratch space for this test binary (Cargo creates `target/tmp` for integration tests).
pub fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::create_dir_all(&dir).expect("create a scratch directory under target/tmp");
    dir
}

/// The triple of the machine running the tests: the C code runs here, so target = host.
fn host_triple() -> String {
    let arch = std::env::consts::ARCH;
    match std::env::consts::OS {
        "linux" if cfg!(target_env = "musl") => format!("{arch}-unknown-linux-musl"),
        "linux" => format!("{arch}-unknown-linux-gnu"),
        "macos" => format!("{arch}-apple-darwin"),
        os => panic!("the C test harness supports Linux and macOS, not {os}"),
    }
}

/// A `cc` build for C (or C++ with `cpp`). Outside build.rs Cargo sets none of TARGET, HOST,
/// OPT_LEVEL or OUT_DIR, so they are given explicitly; no cargo: lines are printed.
pub fn compiler(cpp: bool, out_dir: &Path) -> cc::Tool {
    let triple = host_triple();
    cc::Build::new()
        .cpp(cpp)
        .target(&triple)
        .host(&triple)
        .opt_level(1)
        .debug(true)
        .warnings(false)
        .out_dir(out_dir)
        .cargo_metadata(false)
        .emit_rerun_if_env_changed(false)
        .get_compiler()
}
