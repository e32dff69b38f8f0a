#!/usr/bin/env bash
# Fuzzing campaign: runs every cargo-fuzz target (fuzz/fuzz_targets/) for
# SECONDS each (default 60), one at a time, in a single libFuzzer process,
# then prints a table: executions, exec/s, coverage, corpus size, findings.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]
#
# Needs the nightly toolchain and cargo-fuzz (`cargo install cargo-fuzz`).
# Each target's working corpus lives in fuzz/corpus/<target>/ (gitignored),
# seeded from tests/data/fuzz/<target>/ and its minimised corpus/ (both
# replayed by tests/it/fuzz_replay.rs) and, for the mesh readers, from
# tests/data/broken/*.<ext>. Crash, timeout and OOM reproducers land in
# fuzz/artifacts/<target>/; full logs in fuzz/logs/.
set -euo pipefail
cd "$(dirname "$0")/.."

secs=${1:-60}
shift || true
if [ $# -gt 0 ]; then
    targets=("$@")
else
    mapfile -t targets < <(cargo +nightly fuzz list)
fi
export CARGO_BUILD_JOBS=${CARGO_BUILD_JOBS:-1}
cargo +nightly fuzz build >&2

mkdir -p fuzz/logs
rows=()
for t in "${targets[@]}"; do
    corpus=fuzz/corpus/$t
    mkdir -p "$corpus" "fuzz/artifacts/$t"
    find "tests/data/fuzz/$t" -type f -exec cp -n -t "$corpus" {} + 2>/dev/null || true
    case $t in
    parse_obj | parse_off | parse_ply | parse_stl)
        cp -n tests/data/broken/*."${t#parse_}" "$corpus"/ 2>/dev/null || true
        ;;
    esac
    before=$(find "fuzz/artifacts/$t" -type f | wc -l)
    log=fuzz/logs/$t.log
    echo "fuzzing $t for ${secs}s (log: $log)" >&2
    status=0
    cargo +nightly fuzz run "$t" "$corpus" -- \
        -max_total_time="$secs" -rss_limit_mb=2048 -timeout=10 \
        -print_final_stats=1 >"$log" 2>&1 || status=$?
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    # a run stopped by a finding has no final stats: use its last status line
    [ -z "$execs" ] && execs=$(grep -o '^#[0-9]*' "$log" | tail -1 | tr -d '#' || true)
    [ -z "$rate" ] && rate=$(grep -o 'exec/s: [0-9]*' "$log" | tail -1 | awk '{print $2}' || true)
    cov=$(grep -o 'cov: [0-9]* ft: [0-9]*' "$log" | tail -1 | awk '{print $2 "/" $4}' || true)
    entries=$(find "$corpus" -type f | wc -l)
    found=$(($(find "fuzz/artifacts/$t" -type f | wc -l) - before))
    [ "$status" -ne 0 ] && [ "$found" -eq 0 ] && found="exit $status"
    rows+=("$(printf '| %-16s | %7s | %11s | %7s | %9s | %7s | %s |' \
        "$t" "$secs" "${execs:-?}" "${rate:-?}" "${cov:-?}" "$entries" "$found")")
done

printf '| %-16s | %7s | %11s | %7s | %9s | %7s | %s |\n' \
    target seconds execs exec/s cov/ft corpus findings
echo '|------------------|---------|-------------|---------|-----------|---------|----------|'
printf '%s\n' "${rows[@]}"
