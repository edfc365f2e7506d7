#!/usr/bin/env bash
# Builds a release binary that times one generated molecule's production right-hand side the
# way examples/rhs_cost.rs does (8 varied states, thread CPU time per evaluation, median of
# ROUNDS), without building the whole rovib crate for it:
#
#   cargo build --release -p rovib-runtime
#   benches/size/rhs_alone.sh /tmp/gen/hexane.rs /tmp/hexane_rhs && /tmp/hexane_rhs 3 4000
set -eu
src=$(realpath "$1"); out=$2
root=$(cd "$(dirname "$0")/../.." && pwd)
ty=$(grep -m1 -oP '^pub struct \K[A-Za-z0-9_]+(?=;)' "$src")
dir=$(mktemp -d /tmp/rhs-alone.XXXX)
{ sed -e "s|@SRC@|$src|; s|@TY@|$ty|" "$root/benches/size/molecule_alone.rs.in"; cat "$root/benches/size/rhs_alone_main.rs.in"; } > "$dir/main.rs"
deps=$root/target/release/deps
rt=$(ls -t "$deps"/librovib_runtime-*.rlib | head -1)
rustc --edition 2024 --crate-name rhs_alone -C opt-level=3 -C codegen-units=16 -L "dependency=$deps" \
    --extern "rovib_runtime=$rt" "$dir/main.rs" -o "$out"
rm -rf "$dir"
