#!/usr/bin/env bash
# One point of a whole-curve HemoCell study: oneCellShear at every shear stress named, one after
# the other, each in a folder of its own, their elongation indices gathered into one array.
# The command of a study whose `[model]` is `kind = "command"` with
# `output = { file = "el.json", format = "json", array = "/el" }` (hemocell27-healthy.toml in this folder).
# Runs in the run directory, which iuq filled with RBC.xml (the membrane parameters):
#
#   run-hemocell-curve.sh STRESS_PA [STRESS_PA ...]
#
# For stress τ (Pa), as hemocell-shear.toml derives it for one run: shear rate γ̇ = τ/(ρν) with
# ρ = 1025 kg/m³, ν = 1.1e-6 m²/s; t_start = floor(7.5/(γ̇ dt)), dt = 5e-8 s (strain 7.5);
# t_max = ceil(1.25 t_start); output every floor((t_max - t_start)/10) steps. This folder's
# config.xml is filled with them in stress-<k>/ beside a copy of RBC.xml, and run-hemocell.sh
# runs and decodes it there (its environment: HEMOCELL_ONECELLSHEAR, HEMOCELL_LAYOUT, IUQ, ...).
# el.json: {"el": [{"value": EL, "std": frame std}, ...]} in the order of the stresses given.
# A stress whose run fails fails the point, with that run's reason as the last line of stderr.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
if [ $# -lt 1 ]; then
    echo "usage: run-hemocell-curve.sh STRESS_PA [STRESS_PA ...]" >&2
    exit 2
fi
if [ ! -f RBC.xml ]; then
    echo "run-hemocell-curve.sh: RBC.xml is missing in $(pwd) (iuq writes it from the study's template)" >&2
    exit 2
fi
k=0
for stress in "$@"; do
    read -r shearrate tstart tmax tmeas < <(python3 - "$stress" <<'EOF'
import math, sys
try:
    tau = float(sys.argv[1])
except ValueError:
    sys.exit(f"run-hemocell-curve.sh: stress {sys.argv[1]!r} is not a number")
if not (tau > 0 and math.isfinite(tau)):
    sys.exit(f"run-hemocell-curve.sh: stress {tau} Pa must be positive")
rate = tau / (1025 * 1.1e-6)
tstart = math.floor(7.5 / (rate * 0.5e-7))
tmax = math.ceil(1.25 * tstart)
print(repr(rate), tstart, tmax, (tmax - tstart) // 10)
EOF
)
    dir="stress-$k"
    rm -rf "$dir"
    mkdir "$dir"
    cp RBC.xml "$dir/RBC.xml"
    sed -e "s/{{ shearrate }}/$shearrate/" -e "s/{{ tmax }}/$tmax/" -e "s/{{ tmeas }}/$tmeas/" \
        "$here/config.xml" > "$dir/config.xml"
    echo "run-hemocell-curve.sh: $stress Pa (shear rate $shearrate 1/s, steps $tstart..$tmax) in $dir" >&2
    if ! (cd "$dir" && "$here/run-hemocell.sh" "$tstart" "$tmax" > run.log 2> run.err); then
        reason=$(tail -n1 "$dir/run.err")
        echo "run-hemocell-curve.sh: at $stress Pa: ${reason:-no reason given}" >&2
        exit 1
    fi
    k=$((k + 1))
done
python3 - "$k" <<'EOF'
import json, sys
n = int(sys.argv[1])
values = []
for k in range(n):
    with open(f"stress-{k}/el.json") as f:
        values.append(json.load(f)["el"])
with open("el.json.partial", "w") as f:
    json.dump({"el": values}, f)
EOF
mv el.json.partial el.json
