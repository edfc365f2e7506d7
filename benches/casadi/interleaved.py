#!/usr/bin/env python3
"""One right-hand-side evaluation of water: rovib's production path against CasADi-generated C
(the seed's 3 x 3 G-block formulation, `--linear-solve blocks` of compare.py, and the 6 x 6
`ca.solve`), measured as BENCHMARKS.md asks of a noisy shared machine: thread CPU time, the
contenders run alternately round by round, on 64 varied states, each chained as in an
integrator (every input the previous input plus 1e-3 times the previous output).

    /tmp/casadi-venv/bin/python benches/casadi/interleaved.py [--rounds 9] [--iters 2000]

Before timing, both CasADi models are checked against `rovib eval` at three random states
(H and every right-hand-side component to 1e-11 relative, as compare.py does). The CasADi C is
compiled with `gcc -O3 -march=native` (compare.py's flags) into one C driver per variant
(`chain.c`, separate translation unit, no LTO); rovib's side is `examples/rhs_chain.rs`
(`cargo build --release --example rhs_chain`, the default target: baseline x86-64, unless
RUSTFLAGS say otherwise). Each process converts the same states file to its own variables
(CasADi: q, p, Euler angles, p_e; rovib: q, p, quaternion, body J) and prints ns per
evaluation. Generated files go to benches/casadi/build/interleaved/ (git-ignored).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import compare  # noqa: E402  (the model, the validation helper)

CHAIN_C = r"""
/* Chained evaluations of one CasADi-generated right-hand side over the states of a file,
   timed with this thread's CPU time: prints ns per evaluation and a checksum. */
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "h2o_chain.h"

#define F FUNC
#define CAT(a, b) a##b
#define XCAT(a, b) CAT(a, b)

static double cpu(void) { struct timespec t; clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }

int main(int argc, char **argv) {
    if (argc != 3) { fprintf(stderr, "usage: chain STATES ITERS\n"); return 2; }
    FILE *f = fopen(argv[1], "r");
    if (!f) { perror(argv[1]); return 2; }
    long iters = atol(argv[2]);
    static double states[4096][12];
    int n = 0;
    while (n < 4096) {
        int got = 0;
        for (int i = 0; i < 12; i++) got += fscanf(f, "%lf", &states[n][i]);
        if (got != 12) break;
        n++;
    }
    fclose(f);
    casadi_int sz_arg, sz_res, sz_iw, sz_w;
    XCAT(F, _work)(&sz_arg, &sz_res, &sz_iw, &sz_w);
    const double **arg = calloc(sz_arg + 1, sizeof *arg);
    double **res = calloc(sz_res + 1, sizeof *res);
    casadi_int *iw = calloc(sz_iw + 1, sizeof *iw);
    double *w = calloc(sz_w + 1, sizeof *w);
    double x[12], d[12], checksum = 0.0;
    arg[0] = x; res[0] = d;
    double t0 = cpu();
    for (int s = 0; s < n; s++) {
        for (int i = 0; i < 12; i++) x[i] = states[s][i];
        for (long k = 0; k < iters; k++) {
            F(arg, res, iw, w, 0);
            for (int i = 0; i < 12; i++) x[i] += 1e-3 * d[i];
        }
        checksum += x[0];
    }
    double t1 = cpu();
    printf("%.2f %.17e\n", (t1 - t0) * 1e9 / ((double)n * iters), checksum);
    return 0;
}
"""


def states(count: int, seed: int) -> np.ndarray:
    """Water about its reference: stretches +-3 %, bend +-0.08 rad, thermal-sized momenta,
    Euler angles away from gimbal lock, p_e of a few hbar."""
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(count):
        q = compare.REFERENCE_Q * np.array([rng.uniform(0.97, 1.03), rng.uniform(0.97, 1.03), 1.0])
        q[2] += rng.uniform(-0.08, 0.08)
        p = [rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-1, 1)]
        euler = [rng.uniform(-math.pi, math.pi), rng.uniform(0.5, 2.6), rng.uniform(-math.pi, math.pi)]
        pe = rng.uniform(-5, 5, 3)
        rows.append(np.concatenate([q, p, euler, pe]))
    return np.array(rows)


def run(cmd) -> tuple[float, float]:
    r = subprocess.run([str(c) for c in cmd], text=True, capture_output=True, check=True)
    ns, checksum = r.stdout.split()
    if not math.isfinite(float(checksum)):
        sys.exit(f"{cmd}: non-finite checksum {checksum}")
    return float(ns), float(checksum)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--iters", type=int, default=2000, help="chained evaluations per state (64 states)")
    ap.add_argument("--rovib-binary", type=Path, default=None,
                    help="an already built rhs_chain (default: build it with cargo, release)")
    args = ap.parse_args()
    build = compare.HERE / "build" / "interleaved"
    build.mkdir(parents=True, exist_ok=True)

    if args.rovib_binary is None:
        compare.sh(["cargo", "build", "--release", "-q", "--example", "rhs_chain"])
        rovib = compare.ROOT / "target" / "release" / "examples" / "rhs_chain"
    else:
        rovib = args.rovib_binary.resolve()

    variants = {"blocks": "h2o_rhs_blocks", "solve": "h2o_rhs_solve"}
    functions = {}
    for variant, name in variants.items():
        x, H, rhs, _ = compare.build_model(variant)
        functions[variant] = (ca.Function(name, [x], [rhs], {"cse": True}), ca.Function(name + "_H", [x], [H]))
        print(f"{variant}: {compare.op_counts(functions[variant][0])['arithmetic']} arithmetic operations after CSE")

    # Validation against `rovib eval` before any timing.
    rng = np.random.default_rng(2024)
    worst = 0.0
    for k in range(3):
        q = compare.REFERENCE_Q * np.array([1 + rng.uniform(-0.05, 0.1), 1 + rng.uniform(-0.05, 0.1), 1.0])
        q[2] += rng.uniform(-0.25, 0.25)
        st = dict(q=q.tolist(), p=rng.uniform(-3, 3, 3).tolist(),
                  euler=[rng.uniform(-math.pi, math.pi), rng.uniform(0.4, 2.7), rng.uniform(-math.pi, math.pi)],
                  pe=rng.uniform(-6, 6, 3).tolist())
        ref = compare.rovib_eval(st, build / f"state{k}.json")
        xv = np.concatenate([st["q"], st["p"], st["euler"], st["pe"]])
        theirs = np.concatenate([ref["rhs"][b] for b in ("q", "p", "euler", "pe")])
        scale = np.where(theirs != 0, np.abs(theirs), np.max(np.abs(theirs)))
        for variant, (f, h) in functions.items():
            mine = f(xv).full().ravel()
            rel = max(float(np.max(np.abs(mine - theirs) / scale)), abs(float(h(xv)) - ref["H"]) / abs(ref["H"]))
            worst = max(worst, rel)
            print(f"  state {k}, {variant}: worst relative difference to rovib eval {rel:.1e}")
    if worst > 1e-11:
        sys.exit(f"VALIDATION FAILED: {worst:.2e} > 1e-11; not timing a wrong model")

    cwd = os.getcwd()
    os.chdir(build)
    try:
        cg = ca.CodeGenerator("h2o_chain.c", {"with_header": True})
        for f, _ in functions.values():
            cg.add(f)
        cg.generate()
    finally:
        os.chdir(cwd)
    (build / "chain.c").write_text(CHAIN_C)
    cflags = ["-O3", "-march=native"]
    binaries = {}
    for variant, name in variants.items():
        binaries[variant] = build / f"chain_{variant}"
        compare.sh(["gcc", *cflags, f"-DFUNC={name}", "chain.c", "h2o_chain.c", "-o", binaries[variant], "-lm"],
                   cwd=build)
    path = build / "states.txt"
    np.savetxt(path, states(64, 7), fmt="%.17g")

    order = [("rovib production", [rovib, path, args.iters]),
             ("CasADi 3x3 G blocks", [binaries["blocks"], path, args.iters]),
             ("CasADi 6x6 solve", [binaries["solve"], path, args.iters])]
    times: dict[str, list[float]] = {name: [] for name, _ in order}
    print(f"\nload average {os.getloadavg()}; {args.rounds} rounds, 64 states x {args.iters} chained evaluations")
    for r in range(args.rounds):
        line = []
        for name, cmd in (order if r % 2 == 0 else order[::-1]):
            ns, _ = run(cmd)
            times[name].append(ns)
            line.append(f"{name} {ns:.1f}")
        print(f"round {r}: " + ", ".join(line) + " ns/eval")
    base = times["rovib production"]
    print("\nmedians (thread CPU time, ns per evaluation) and median per-round ratio to rovib production:")
    summary = {}
    for name, _ in order:
        ratios = [t / b for t, b in zip(times[name], base)]
        summary[name] = dict(median_ns=statistics.median(times[name]), ratio=statistics.median(ratios),
                             ratio_range=[min(ratios), max(ratios)])
        print(f"  {name:22s} {statistics.median(times[name]):7.1f} ns   x{statistics.median(ratios):.2f} "
              f"(rounds {min(ratios):.2f}-{max(ratios):.2f})")
    (build / "results.json").write_text(json.dumps(dict(times=times, summary=summary, cflags=cflags,
                                                         casadi=ca.__version__, loadavg=os.getloadavg()), indent=1))


if __name__ == "__main__":
    main()
