#!/usr/bin/env python3
"""A small stand-in for an expensive simulator: Newton cooling of a cup of coffee.

    T(t) = T_env + (T0 - T_env) * exp(-k * t),   T_env = 20 °C

It reads the run's parameters from `params.json` in the current directory (the run directory
that iuq prepares) and writes `result.json`:

- one run per (parameters, time): `params.json` holds `k`, `T0` and the time `t`, and the
  result is {"T": T(t)};
- one run per parameter vector (`--curve`): the result is {"T": [T(t_1), ..., T(t_n)]} at the
  measurement times given after `--curve` (the times of the data file, in file order);
- many runs per process (`--batch`, for `kind = "batch-command"`): it reads `inputs.csv`
  (`run_id`, `k`, `T0`, `t`, one row per run) and writes `outputs.csv` (`T`, `error`: one row
  per input row, the reason in `error` where the run fails).

Like a real solver with an explicit time step, it refuses to run where the cooling rate makes the
step unstable: for k > 0.5 (or $COOLING_K_UNSTABLE) it prints a reason on stderr and exits with
status 3, so part of the prior gives no answer. For tests and benchmarks: $COOLING_SLEEP (seconds)
makes each run take that long, and $COOLING_RUN_LOG names a file to which every finished run
appends its parameters as a JSON line. $COOLING_CHAOS (°C) adds to each run's result one offset
A·(2h − 1), h a hash of the exact bits of its parameters: like a chaotic simulator's, the same
parameters give the same result, parameters a billionth apart unrelated ones.
"""

import hashlib
import json
import math
import os
import struct
import sys
import time

T_ENV = 20.0
K_UNSTABLE = 0.5


def temperature(k: float, t0: float, t: float) -> float:
    return T_ENV + (t0 - T_ENV) * math.exp(-k * t)


def batch() -> int:
    import csv

    k_unstable = float(os.environ.get("COOLING_K_UNSTABLE", K_UNSTABLE))
    with open("inputs.csv", encoding="utf-8", newline="") as f:
        rows = list(csv.DictReader(f))
    with open("outputs.csv", "w", encoding="utf-8", newline="") as f:
        out = csv.writer(f)
        out.writerow(["T", "error"])
        for row in rows:
            k, t0, t = float(row["k"]), float(row["T0"]), float(row["t"])
            if k > k_unstable:
                out.writerow(["", f"unstable time step: cooling rate k = {k:.4g} > {k_unstable} per minute"])
            else:
                out.writerow([temperature(k, t0, t), ""])
    return 0


def chaotic_offset(params: dict) -> float:
    """$COOLING_CHAOS·(2h − 1), h in [0, 1) a hash of the parameters' exact bits (0 unset)."""
    amplitude = float(os.environ.get("COOLING_CHAOS", "0"))
    if amplitude == 0:
        return 0.0
    bits = b"".join(struct.pack("<d", float(params[key])) for key in sorted(params))
    h = int.from_bytes(hashlib.sha256(bits).digest()[:8], "little") / 2.0**64
    return amplitude * (2.0 * h - 1.0)


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "--batch":
        return batch()
    with open("params.json", encoding="utf-8") as f:
        params = json.load(f)
    k = float(params["k"])
    t0 = float(params["T0"])
    delay = float(os.environ.get("COOLING_SLEEP", "0"))
    if delay > 0:
        time.sleep(delay)
    k_unstable = float(os.environ.get("COOLING_K_UNSTABLE", K_UNSTABLE))
    if k > k_unstable:
        print(
            f"unstable time step: cooling rate k = {k:.4g} > {k_unstable} per minute",
            file=sys.stderr,
        )
        return 3
    offset = chaotic_offset(params)
    if len(sys.argv) > 1 and sys.argv[1] == "--curve":
        times = [float(a) for a in sys.argv[2:]]
        result = {"T": [temperature(k, t0, t) + offset for t in times]}
    else:
        result = {"T": temperature(k, t0, float(params["t"])) + offset}
    with open("result.json", "w", encoding="utf-8") as f:
        json.dump(result, f)
    log = os.environ.get("COOLING_RUN_LOG")
    if log:
        with open(log, "a", encoding="utf-8") as f:
            f.write(json.dumps(params, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
