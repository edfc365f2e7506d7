#!/bin/bash
# The chart of an ensemble (run.chart) through the whole `rovib ensemble` command, at equal error
# (BENCHMARKS.md, "The chart of an ensemble"). Writes scenes and outputs under $WORK
# (default target/ensemble_charts); prints one line per run; compare.py reads the outputs.
#   cargo build --release && benches/ensemble_charts/run.sh $PWD/target/release/rovib 2000 3 > m.txt
#   (cd target/ensemble_charts && python3 ../../benches/ensemble_charts/compare.py ../../m.txt)
# run.chart through the real ensemble path: CPU (user+sys of the process, --threads 1) and the
# error of the ensemble means at t = 10^4 a.u. against an internal-chart reference at rtol 1e-12
# (the same seed, hence the same initial states). Usage: run.sh BIN N ROUNDS [MOLECULES]
# (MOLECULES: a quoted list of molecules declared by kind, default "h2o h2o2 nh3").
BIN=$1; N=$2; R=$3; MOLS=${4:-h2o h2o2 nh3}
mkdir -p "${WORK:-target/ensemble_charts}" && cd "${WORK:-target/ensemble_charts}"
mk() { # molecule chart rtol
# A pair's thermal density does not vanish at large separations: bound the distance d.
region="{ energy_cap = 0.1 }"
[ "$1" = n2ar_pair ] && region="{ energy_cap = 0.1, limits = { d = [6.0, 12.0] } }"
cat > s_$1_$2_$3.toml <<EOT
molecule = "$1"
[ensemble]
trajectories = $N
seed = 1
method = "thermal"
temperature = 300.0
region = $region
[integrator]
method = "dop853"
rtol = $3
atol = $3
[run]
end = 10000.0
output_interval = 100.0
chart = "$2"
EOT
echo s_$1_$2_$3.toml
}
for m in $MOLS; do
  ref=$(mk $m internal 1e-12)
  rm -rf out_ref_$m; $BIN ensemble $ref --out out_ref_$m --quiet --threads 1 > /dev/null 2>&1 || echo "ref $m failed"
  for r in $(seq 1 $R); do
    for cfg in "internal 1e-8" "internal 1e-9" "cartesian 1e-9" "cartesian 1e-10" "cartesian 1e-11"; do
      set -- $cfg
      s=$(mk $m $1 $2)
      o=out_${m}_$1_$2
      rm -rf $o; /usr/bin/time -f "%U %S" -o t.txt $BIN ensemble $s --out $o --quiet --threads 1 > /dev/null 2>&1 || echo "$m $cfg failed"
      echo "$m $1 $2 round $r cpu $(awk '{print $1+$2}' t.txt)"
    done
  done
done
