#!/usr/bin/env bash
# Runs every cargo-fuzz target (fuzz/fuzz_targets/) for SECONDS seconds each (default 10),
# one after the other, from its seed corpus (fuzz/corpus/<target>/, left untouched: inputs a
# run finds go to fuzz/target/corpus/<target>/). libFuzzer with AddressSanitizer, on the
# stable toolchain (RUSTC_BOOTSTRAP=1 lets it take the -Z flags cargo-fuzz passes).
# Installs the pinned cargo-fuzz first if it is missing. Exits non-zero on any finding; the
# input that found it is in fuzz/artifacts/<target>/ (docs/design/fuzzing.md says how to replay it).
#
#   scripts/fuzz.sh          # 10 s per target (CI runs 5 s: .ci/run, `make fuzz FUZZ_SECONDS=5`)
#   scripts/fuzz.sh 120      # a longer run
#   FUZZ_TARGETS="frames wire_request" scripts/fuzz.sh 30
set -euo pipefail

CARGO_FUZZ_VERSION=0.13.2
seconds=${1:-10}
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
export RUSTC_BOOTSTRAP=1
# envhub's own build flags (path remapping) would only rebuild the fuzz crate's dependencies.
unset RUSTFLAGS
# Nor clippy-driver, which the Makefile compiles the workspace with (the lints are for `make lint`).
unset RUSTC_WORKSPACE_WRAPPER CLIPPY_ARGS

if ! cargo fuzz --version 2>/dev/null | grep -q " $CARGO_FUZZ_VERSION"; then
    echo "fuzz: installing cargo-fuzz $CARGO_FUZZ_VERSION"
    cargo install --locked "cargo-fuzz@$CARGO_FUZZ_VERSION"
fi

targets=${FUZZ_TARGETS:-$(cargo fuzz list)}
echo "fuzz: building the targets (AddressSanitizer, debug assertions)"
cargo fuzz build --sanitizer address

logs=fuzz/target/logs
mkdir -p "$logs"
failed=()
for t in $targets; do
    mkdir -p "fuzz/target/corpus/$t"
    # Limits: no input over 64 KiB, no allocation over 512 MiB (a length taken on trust
    # shows up as an out-of-memory finding), 10 s per input. The open request is read up to
    # 256 KiB (`MAX_OPEN_REQUEST_BYTES`): its target gets inputs one byte past that.
    max_len=65536
    if [ "$t" = open_request ]; then max_len=$((256 * 1024 + 1)); fi
    if cargo fuzz run --sanitizer address "$t" "fuzz/target/corpus/$t" "fuzz/corpus/$t" -- \
        -max_total_time="$seconds" -max_len="$max_len" -malloc_limit_mb=512 -rss_limit_mb=2048 \
        -timeout=10 -print_final_stats=1 >"$logs/$t.log" 2>&1; then
        status=ok
    else
        status=FAILED
        failed+=("$t")
    fi
    runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$logs/$t.log" | tail -1)
    cov=$(grep -o 'cov: [0-9]* ft: [0-9]*' "$logs/$t.log" | tail -1)
    printf 'fuzz %-16s %-6s %10s runs  %s\n' "$t" "$status" "${runs:-?}" "${cov:-}"
done
if [ ${#failed[@]} -gt 0 ]; then
    for t in "${failed[@]}"; do
        echo "---- $t (fuzz/target/logs/$t.log) ----"
        tail -40 "$logs/$t.log"
    done
    echo "fuzz: findings in: ${failed[*]}; inputs in fuzz/artifacts/<target>/" >&2
    exit 1
fi
echo "fuzz: no findings"
