#!/usr/bin/env python3
"""What one adaptive round costs at 50, 100 and 500 model runs (a benchmark, not a test).

    python3 scripts/bench/round_cost.py [--iuq-bin target/release/iuq] [--runs 50,100,500]
                                        [--delayed-acceptance on|off|both]

The problem is engine_vs_peers.py's `twoexp` (4 parameters with log-normal priors, 20 outputs,
a posterior about 10⁻⁶ of the prior's volume), run by `iuq pipeline` with the engine's
defaults except the initial design: a maximin LHS of n runs, then two rounds (`max_rounds = 2`)
— the first anneals from the prior, the second carries the first's population — and
`log_likelihood_tolerance = 1e-9`, so that a candidate is always worth a run (otherwise the
second round at 500 runs is the engine's wider search after a round without one). Printed per n
and round: wall seconds, the surrogate evaluations of the round's samplers, and the seconds the
pipeline's stages took (GP fits, BASIS), from `rounds.json` and `pipeline.json`.
`--delayed-acceptance both` (the default) runs every n with the moves screened on the
surrogate's means (`[sampler] delayed_acceptance = true`, the default) and without, side by side.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from engine_vs_peers import PROBLEMS, write_study  # noqa: E402


def study(problem, n, workdir, delayed_acceptance):
    return write_study(problem, workdir, "round-cost",
                       [f'design = {{ kind = "lhs", n = {n}, seed = 1 }}',
                        # A score of any size is worth a run (`log_likelihood_tolerance` tiny): at
                        # 500 runs the surrogate is already exact, and a round without a candidate
                        # worth a run would make the next one search 4 times the candidates from
                        # twice the samples instead of the plain carried round measured here.
                        f"adaptive = {{ max_rounds = 2, max_runs = {n + 100}, log_likelihood_tolerance = 1e-9 }}"],
                       ["seed = 1", "samples = 1000",
                        f"delayed_acceptance = {str(delayed_acceptance).lower()}"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iuq-bin", default="target/release/iuq")
    parser.add_argument("--runs", default="50,100,500")
    parser.add_argument("--delayed-acceptance", choices=["on", "off", "both"], default="both")
    args = parser.parse_args()
    problem = PROBLEMS["twoexp"]()
    modes = {"on": [True], "off": [False], "both": [True, False]}[args.delayed_acceptance]
    print("delayed  runs  round  seconds  surrogate evaluations  screenings  carried replicates")
    for n, delayed in ((int(v), d) for v in args.runs.split(",") for d in modes):
        with tempfile.TemporaryDirectory(prefix=f"iuq-round-cost-{n}-") as workdir:
            path = study(problem, n, workdir, delayed)
            out = os.path.join(workdir, "out")
            started = time.time()
            done = subprocess.run([args.iuq_bin, "pipeline", path, "--out", out, "--json"],
                                  capture_output=True, text=True)
            wall = time.time() - started
            if done.returncode != 0:
                print(f"{n}: failed: {done.stderr.strip().splitlines()[-1:]}")
                continue
            with open(os.path.join(out, "adaptive", "rounds.json")) as f:
                rounds = json.load(f)
            rounds = rounds if isinstance(rounds, list) else rounds["rounds"]
            for r in rounds:
                print(f"{'on' if delayed else 'off':>7}  {r['runs']:4d}  {r['round']:5d}  "
                      f"{r['seconds']:7.2f}  {r['surrogate_evaluations']:21d}  "
                      f"{r.get('surrogate_screenings', 0):10d}  {r['carried_replicates']:18d}")
            print(f"      pipeline in all {wall:.1f} s")


if __name__ == "__main__":
    main()
