// Generates `include/rt2.h` from `src/api` with cbindgen (settings in `cbindgen.toml`).
// The header is committed; `tests/header.rs` fails if the committed header differs from the
// copy this script also leaves in OUT_DIR.

/// cbindgen's settings: `cbindgen.toml` plus the macros that come from Cargo.toml, so the
/// header cannot disagree with the library, and the opaque handle typedefs (the handles are
/// `#[repr(C)]` in Rust so their magic number sits at offset 0, and cbindgen must not print
/// their fields). `version` is major, minor, patch and the full string.
fn header_config(crate_dir: &str, version: [&str; 4]) -> cbindgen::Config {
    let mut config = cbindgen::Config::from_file(format!("{crate_dir}/cbindgen.toml"))
        .expect("cbindgen.toml is valid");
    let [major, minor, patch, full] = version;
    config.after_includes = Some(format!(
        "\n#define RT2_VERSION_MAJOR {major}\n#define RT2_VERSION_MINOR {minor}\n\
         #define RT2_VERSION_PATCH {patch}\n#define RT2_VERSION_STRING \"{full}\"\n\n\
         /** Marks \"no object / no primitive\" in rt2_hit (rt2::api::RT2_INVALID_ID). */\n\
         #define RT2_INVALID_ID {:#X}u\n\n\
         /* Opaque handles. */\n\
         typedef struct rt2_context rt2_context;\n\
         typedef struct rt2_scene rt2_scene;\n\
         typedef struct rt2_camera rt2_camera;\n\
         typedef struct rt2_frame rt2_frame;\n",
        u32::MAX,
    ));
    config
}

fn main() {
    println!("cargo:rerun-if-changed=src/api");
    println!("cargo:rerun-if-changed=src/error.rs");
    println!("cargo:rerun-if-changed=cbindgen.toml");
    let crate_dir = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let v = |k: &str| std::env::var(k).expect("cargo sets the package version");
    let version = [
        v("CARGO_PKG_VERSION_MAJOR"),
        v("CARGO_PKG_VERSION_MINOR"),
        v("CARGO_PKG_VERSION_PATCH"),
        v("CARGO_PKG_VERSION"),
    ];
    let config = header_config(&crate_dir, version.each_ref().map(String::as_str));
    // The generation as this build made it, beside the crate's output: tests/header.rs
    // compares include/rt2.h (in the tree and at HEAD) with it, which catches a hand edit
    // that no rebuild has overwritten yet.
    let fresh =
        std::path::Path::new(&std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("rt2.h");
    match cbindgen::generate_with_config(&crate_dir, config) {
        Ok(bindings) => {
            bindings.write_to_file(&fresh);
            bindings.write_to_file(format!("{crate_dir}/include/rt2.h"));
        }
        // A syntax error in the crate is reported by rustc itself, more clearly. No copy is
        // left in OUT_DIR, so that the header test cannot pass against an older generation.
        Err(e) => {
            let _ = std::fs::remove_file(&fresh);
            println!("cargo:warning=cbindgen could not generate include/rt2.h: {e}");
        }
    }
}
