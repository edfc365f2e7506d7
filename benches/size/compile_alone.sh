#!/usr/bin/env bash
# Compiles one generated molecule file alone, with its production right-hand side
# (ReducedSystem::rhs) instantiated, as an rlib against this checkout's rovib-runtime, and
# prints rustc's CPU time (user + sys) and peak memory (BENCHMARKS.md, "Large molecules,
# third step"). Needs the runtime built first in the matching profile:
#
#   cargo run --release -p rovib-codegen --features examples --example cost -- --write /tmp/gen molecules/h2o.toml ...
#   cargo build --release -p rovib-runtime     # for `release`
#   cargo build -p rovib-runtime               # for `test` (opt-level 1, full debug information)
#   benches/size/compile_alone.sh /tmp/gen/h2o.rs release|test
set -u
src=$(realpath "$1"); prof=$2
root=$(cd "$(dirname "$0")/../.." && pwd)
ty=$(grep -m1 -oP '^pub struct \K[A-Za-z0-9_]+(?=;)' "$src")
dir=$(mktemp -d /tmp/compile-alone.XXXX)
sed -e "s|@SRC@|$src|; s|@TY@|$ty|" "$root/benches/size/molecule_alone.rs.in" > "$dir/lib.rs"
if [ "$prof" = release ]; then
    deps=$root/target/release/deps; flags="-C opt-level=3 -C codegen-units=16"
else
    deps=$root/target/debug/deps; flags="-C opt-level=1 -C debuginfo=2 -C codegen-units=256"
fi
rt=$(ls -t "$deps"/librovib_runtime-*.rlib | head -1)
/usr/bin/time -f "%U %S %M" -o "$dir/time" rustc --edition 2024 --crate-type lib --crate-name alone $flags \
    -L "dependency=$deps" --extern "rovib_runtime=$rt" "$dir/lib.rs" -o "$dir/libalone.rlib" 2> "$dir/stderr"
status=$?
t=$(tail -1 "$dir/time")
echo "$(basename "$src") $prof cpu=$(echo "$t" | awk '{printf "%.1f", $1 + $2}')s peak=$(echo "$t" | awk '{printf "%.0f", $3 / 1024}')MB exit=$status $(grep -m1 -o 'SIGSEGV' "$dir/stderr")"
rm -rf "$dir"
exit $status
