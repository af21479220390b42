#!/usr/bin/env bash
# One HemoCell oneCellShear run of the IUQ study, as the command of an iuq campaign
# (hemocell-shear.toml). Runs in the run directory, which iuq filled with config.xml and RBC.xml:
#
#   run-hemocell.sh T_START T_MAX
#
# 1. puts the cell in place (RBC.pos from this folder) and the material file under both names
#    oneCellShear versions load (RBC.xml/RBC.pos in HemoCell >= 2, RBC_HO.xml/RBC_HO.pos in
#    older ones and in the IUQ study);
# 2. runs ${HEMOCELL_ONECELLSHEAR:-oneCellShear} config.xml (prefixed by $HEMOCELL_LAUNCHER,
#    e.g. "mpirun -np 4", when set);
# 3. decodes the elongation index of the output iterations in [T_START, T_MAX] with
#    decode-el.py, which writes el.json through `iuq rbc elongation` ($IUQ or iuq on PATH).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
if [ $# -ne 2 ]; then
    echo "usage: run-hemocell.sh T_START T_MAX" >&2
    exit 2
fi
t_start=$1
t_max=$2
for f in config.xml RBC.xml; do
    if [ ! -f "$f" ]; then
        echo "run-hemocell.sh: $f is missing in $(pwd) (iuq writes it from the study's template)" >&2
        exit 2
    fi
done
cp RBC.xml RBC_HO.xml
cp "$here/RBC.pos" RBC.pos
cp "$here/RBC.pos" RBC_HO.pos

simulator="${HEMOCELL_ONECELLSHEAR:-oneCellShear}"
if ! command -v "$simulator" >/dev/null 2>&1; then
    echo "run-hemocell.sh: HemoCell's oneCellShear was not found ('$simulator'); set HEMOCELL_ONECELLSHEAR=/path/to/HemoCell/examples/oneCellShear/oneCellShear" >&2
    exit 127
fi
read -r -a launcher <<< "${HEMOCELL_LAUNCHER:-}"
${launcher[@]+"${launcher[@]}"} "$simulator" config.xml

# HemoCell < 2 writes tmp/hdf5; later versions write <outputDirectory>/hdf5 (tmp, set in
# config.xml), or output/hdf5 when that key is ignored.
hdf5=tmp/hdf5
for candidate in tmp/hdf5 output/hdf5; do
    if [ -d "$candidate" ]; then
        hdf5=$candidate
        break
    fi
done
exec python3 "$here/decode-el.py" "$hdf5" --from "$t_start" --to "$t_max" --frames 10 --out el.json
