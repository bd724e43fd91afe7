#!/usr/bin/env bash
# Runs the C examples under valgrind (memcheck): zero errors and zero leaks, or exit 1.
#   scripts/sanitize.sh            build the library (release) and c_examples, run each
#   RT2_C_EXAMPLES=DIR scripts/sanitize.sh   examples from another directory
# valgrind is used rather than AddressSanitizer because the library is Rust: ASan would need
# the whole crate rebuilt with nightly -Zsanitizer=address, valgrind checks the real build.
# "Definitely", "indirectly" and "possibly" lost count as leaks, and every memcheck error
# fails; "still reachable" (process-lifetime allocations of the Rust runtime) does not.
# scripts/valgrind.supp holds the suppressions, each with its reason.
set -euo pipefail
cd "$(dirname "$0")/.."
examples=${RT2_C_EXAMPLES:-c_examples}
if ! command -v valgrind >/dev/null; then
    echo "sanitize.sh: valgrind is not installed (apt-get install valgrind)" >&2
    exit 2
fi
[ -f "$examples/Makefile" ] || { echo "sanitize.sh: no $examples/Makefile" >&2; exit 2; }
examples=$(cd "$examples" && pwd)
cargo build --release --lib
make -s -C "$examples" RT2_LIB="$PWD/target/release" RT2_INCLUDE="$PWD/include"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
fail=0
root=$PWD
# load_model reads the bunny from the shared data (RT2_SHARED, default ../shared).
bunny="${RT2_SHARED:-$root/../shared}/models/bunny.ply"
for src in "$examples"/*.c; do
    exe=$(basename "$src" .c)
    args=()
    if [ "$exe" = load_model ]; then
        if [ ! -f "$bunny" ]; then
            # As the cargo tests: with RT2_REQUIRE_SHARED=1 (CI) a missing file is a failure.
            if [ "${RT2_REQUIRE_SHARED:-0}" = 1 ]; then
                echo "FAIL $exe: $bunny is absent and RT2_REQUIRE_SHARED=1 (set RT2_SHARED to the shared data folder)"
                fail=1
            else
                echo "skip $exe: $bunny is absent (set RT2_SHARED to the shared data folder)"
            fi
            continue
        fi
        args=("$bunny")
    fi
    # Run where the example may write its images; models come from ../shared when present.
    log="$out/$exe.log"
    if (cd "$out" && RT2_BACKEND=cpu valgrind --error-exitcode=99 --leak-check=full --suppressions="$root/scripts/valgrind.supp" \
            --errors-for-leak-kinds=definite,indirect,possible --show-leak-kinds=definite,indirect,possible \
            "$examples/$exe" "${args[@]}" \
            >"$out/$exe.out" 2>"$log"); then
        summary=$(grep -E "ERROR SUMMARY|definitely lost|indirectly lost|possibly lost" "$log" | sed 's/^==[0-9]*== //' | tr '\n' ';')
        echo "ok   $exe: $summary"
    else
        echo "FAIL $exe (exit $?):"
        grep -E "^==[0-9]+== (Invalid|Conditional|Use of|Mismatched|.*lost|ERROR SUMMARY)" "$log" | head -20
        fail=1
    fi
done
exit $fail
