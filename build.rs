//! Generates `include/rt2.h` from `src/api` with cbindgen (settings in `cbindgen.toml`).
//! The header is committed; `tests/header.rs` fails if it differs from a fresh generation.

fn main() {
    println!("cargo:rerun-if-changed=src/api");
    println!("cargo:rerun-if-changed=src/error.rs");
    println!("cargo:rerun-if-changed=cbindgen.toml");
    let crate_dir = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let mut config = cbindgen::Config::from_file(format!("{crate_dir}/cbindgen.toml"))
        .expect("cbindgen.toml is valid");
    // Version macros come from Cargo.toml so the header cannot disagree with the library.
    let v = |k: &str| std::env::var(k).expect("cargo sets the package version");
    config.after_includes = Some(format!(
        "\n#define RT2_VERSION_MAJOR {}\n#define RT2_VERSION_MINOR {}\n#define RT2_VERSION_PATCH {}\n#define RT2_VERSION_STRING \"{}\"\n\n/** Marks \"no object / no primitive\" in rt2_hit (rt2::api::RT2_INVALID_ID). */\n#define RT2_INVALID_ID {:#X}u\n",
        v("CARGO_PKG_VERSION_MAJOR"),
        v("CARGO_PKG_VERSION_MINOR"),
        v("CARGO_PKG_VERSION_PATCH"),
        v("CARGO_PKG_VERSION"),
        u32::MAX,
    ));
    match cbindgen::generate_with_config(&crate_dir, config) {
        Ok(bindings) => {
            bindings.write_to_file(format!("{crate_dir}/include/rt2.h"));
        }
        // A syntax error in the crate is reported by rustc itself, more clearly.
        Err(e) => println!("cargo:warning=cbindgen could not generate include/rt2.h: {e}"),
    }
}
