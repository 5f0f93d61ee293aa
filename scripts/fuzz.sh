#!/usr/bin/env bash
# Fuzz every input decoder for a bounded time, then minimise any crashers into
# tests/fuzz_regressions/<target>/ (replayed by `cargo test --test fuzz_regressions`).
#
#   scripts/fuzz.sh [seconds-per-target] [target...]
#
# Needs the nightly toolchain and cargo-fuzz (`cargo install cargo-fuzz`). Not part
# of CI's default run. Environment:
#   FUZZ_SANITIZER   libFuzzer sanitizer (default: none, for speed; use `address` to
#                    also check unsafe code: the fast renderer's SIMD and the dependencies)
#   FUZZ_TARGET_DIR  cargo target directory (default: fuzz/target)
#   FUZZ_JOBS        parallel fuzzing processes per target (default: 1)
set -euo pipefail

secs="${1:-60}"
shift || true
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(raw_query mosaic_decode dng_decode table_file training_json illuminant_upload)
fi
san="${FUZZ_SANITIZER:-none}"
tdir="${FUZZ_TARGET_DIR:-$root/fuzz/target}"
jobs="${FUZZ_JOBS:-1}"
par=""
if [ "$jobs" -gt 1 ]; then
    # libFuzzer fork mode: that many worker processes
    par="-fork=$jobs"
fi

if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
    echo "cargo-fuzz on the nightly toolchain is needed: cargo install cargo-fuzz" >&2
    exit 2
fi
# seed corpora (committed; regenerate with the ignored test if missing)
if [ ! -d fuzz/seeds ]; then
    cargo test --test fuzz_regressions -- --ignored write_seed_corpus
fi

(cd fuzz && cargo +nightly fuzz build -s "$san" --target-dir "$tdir")

summary=()
crashes=0
for t in "${targets[@]}"; do
    corpus="fuzz/corpus/$t"
    # a fresh artifact directory per run: only this run's crashers are kept
    run="$(date +%Y%m%d-%H%M%S)"
    art="fuzz/artifacts/$t/$run"
    mkdir -p "$corpus" "$art"
    log="fuzz/artifacts/$t/$run.log"
    echo "=== $t: ${secs}s"
    set +e
    (cd fuzz && cargo +nightly fuzz run -s "$san" --target-dir "$tdir" "$t" \
        "corpus/$t" "seeds/$t" -- \
        -max_total_time="$secs" $par \
        -print_final_stats=1 -artifact_prefix="artifacts/$t/$run/" -rss_limit_mb=4096 \
        -timeout=20) 2>&1 | tee "$log" | grep -E "^#[0-9]+.*(DONE|pulse)|ERROR|panicked|SUMMARY" || true
    set -e
    execs="$(grep -E '^stat::number_of_executed_units' "$log" | tail -1 | awk '{print $2}')"
    rate="$(grep -E '^#[0-9]+.*exec/s' "$log" | tail -1 | sed -E 's/.*exec\/s: ([0-9]+).*/\1/')"
    found=0
    for crash in "$art"/crash-* "$art"/oom-* "$art"/timeout-*; do
        [ -e "$crash" ] || continue
        found=$((found + 1))
        dest="tests/fuzz_regressions/$t"
        mkdir -p "$dest"
        name="$(basename "$crash")"
        echo "--- minimising $crash"
        (cd fuzz && cargo +nightly fuzz tmin -s "$san" --target-dir "$tdir" "$t" \
            "../$crash" -- -runs=2000 -exact_artifact_path="../$dest/$name") >/dev/null 2>&1 \
            || cp "$crash" "$dest/$name"
        [ -e "$dest/$name" ] || cp "$crash" "$dest/$name"
        echo "    kept as $dest/$name"
    done
    crashes=$((crashes + found))
    summary+=("$t: ${execs:-?} execs, ${rate:-?} exec/s, $found crashers")
done

echo
echo "=== summary (${secs}s per target, sanitizer $san)"
printf '%s\n' "${summary[@]}"
if [ "$crashes" -gt 0 ]; then
    echo
    echo "$crashes crasher(s) minimised into tests/fuzz_regressions/<target>/."
    echo "Reproduce with: cargo test --test fuzz_regressions"
    exit 1
fi
echo "No crashers. Replay the kept inputs any time with: cargo test --test fuzz_regressions"
