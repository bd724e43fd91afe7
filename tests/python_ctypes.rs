//! Runs `tests/python/test_ctypes.py` with python3 against the cdylib that `cargo test` built
//! (passed in `RT2_LIBRARY`). Skipped, loudly, only when python3 is not installed.

mod support;

use std::process::Command;

#[test]
fn python_ctypes_drives_the_library() {
    let script = support::manifest_dir().join("tests/python/test_ctypes.py");
    let lib = support::shared_library();
    let out = match Command::new("python3")
        .arg(&script)
        .env("RT2_LIBRARY", &lib)
        .output()
    {
        Ok(out) => out,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            eprintln!(
                "\n*** SKIPPED python_ctypes_drives_the_library: python3 is not installed ***\n"
            );
            return;
        }
        Err(e) => panic!("cannot run python3: {e}"),
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stdout}{stderr}");
    assert!(
        out.status.success(),
        "test_ctypes.py failed ({}):\n{stdout}\n{stderr}",
        out.status
    );
    assert!(
        stdout.contains("test_ctypes: OK"),
        "test_ctypes.py did not finish:\n{stdout}"
    );
}
