#!/usr/bin/env bash
# Fuzzes the PLY and OBJ loaders and the ray query API for a bounded time (not in CI).
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]     default: 60 s, targets ply obj query
# Needs a nightly toolchain (libFuzzer instrumentation). Uses cargo-fuzz when installed
# (cargo install cargo-fuzz); otherwise builds the targets with the same flags itself.
# Seeds: a small valid file of each format (written here) and the models of ../shared under
# 2 MB. Crashes land in fuzz/artifacts/TARGET/; turn each into a regression test beside the
# malformed-file corpus of tests/loaders.rs (loaders) or in tests/precision.rs (queries).
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-60}
shift || true
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(ply obj query)
toolchain=${RT2_FUZZ_TOOLCHAIN:-nightly}
if ! cargo "+$toolchain" --version >/dev/null 2>&1; then
    echo "fuzz.sh: the $toolchain toolchain is missing (rustup toolchain install nightly)" >&2
    exit 2
fi
status=0
for t in "${targets[@]}"; do
    corpus=fuzz/corpus/$t
    mkdir -p "$corpus" "fuzz/artifacts/$t"
    case $t in
        ply)
            printf 'ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n' > "$corpus/seed.ply"
            find ../shared/models -maxdepth 1 -name '*.ply' -size -2M -exec cp -n {} "$corpus/" \; 2>/dev/null || true ;;
        obj) printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf -1 -2 -3\nf 1/1/1 2//2 4\n' > "$corpus/seed.obj" ;;
    esac
    echo "== $t: $secs s"
    if cargo "+$toolchain" fuzz --help >/dev/null 2>&1; then
        cargo "+$toolchain" fuzz run "$t" "$corpus" -- -max_total_time="$secs" -rss_limit_mb=2048 || status=1
    else
        # What cargo-fuzz does: SanitizerCoverage for libFuzzer, AddressSanitizer, debug
        # assertions on, release optimisation.
        RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing -Zsanitizer=address -Cdebug-assertions" \
            cargo "+$toolchain" build --release --manifest-path fuzz/Cargo.toml --bin "$t" \
            --target x86_64-unknown-linux-gnu --target-dir fuzz/target
        "fuzz/target/x86_64-unknown-linux-gnu/release/$t" "$corpus" \
            -artifact_prefix="fuzz/artifacts/$t/" -max_total_time="$secs" -rss_limit_mb=2048 || status=1
    fi
done
exit $status
