#!/bin/bash
# What freezing stiff coordinates saves, which a Cartesian chart cannot do (BENCHMARKS.md, "The
# chart of an ensemble"): the same thermal water ensemble (N trajectories, 300 K, 10^4 a.u., one
# thread) as run.sh, integrated
#   - with the two O-H bonds frozen (run.frozen = ["r1", "r2"]: the bend and the rotation only),
#     internal chart, rtol 1e-8;
#   - flexible in the internal chart at rtol 1e-8 and in the Cartesian chart at rtol 1e-10 (the
#     tolerance at which run.sh finds the two charts' errors equal).
# Prints CPU (user+sys) and the right-hand sides per trajectory of each, ROUNDS rounds interleaved.
# The frozen model is another model (rigid bonds): this measures what it costs, not its error.
#   cargo build --release && benches/ensemble_charts/frozen.sh $PWD/target/release/rovib 2000 3
BIN=$1; N=$2; R=$3
mkdir -p "${WORK:-target/ensemble_charts}" && cd "${WORK:-target/ensemble_charts}"
mk() { # name chart rtol extra
cat > f_$1.toml <<EOT
molecule = "h2o"
[ensemble]
trajectories = $N
seed = 1
method = "thermal"
temperature = 300.0
region = { energy_cap = 0.1 }
[integrator]
method = "dop853"
rtol = $3
atol = $3
[run]
end = 10000.0
output_interval = 100.0
chart = "$2"
$4
EOT
echo f_$1.toml
}
for r in $(seq 1 $R); do
  for cfg in "frozen internal 1e-8 frozen=[\"r1\",\"r2\"]" "flexible internal 1e-8" "flexible_cartesian cartesian 1e-10"; do
    set -- $cfg
    s=$(mk $1 $2 $3 "$4")
    o=out_f_$1
    rm -rf $o; /usr/bin/time -f "%U %S" -o t.txt $BIN ensemble $s --out $o --quiet --threads 1 > /dev/null 2>&1 || echo "$1 failed"
    rhs=$(python3 -c "import json; print(json.load(open('$o/summary.json'))['rhs_evaluations'] // $N)")
    echo "$1 chart $2 rtol $3 round $r cpu $(awk '{print $1+$2}' t.txt) rhs $rhs"
  done
done
