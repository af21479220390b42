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
#    HemoCell's stdout and stderr go to hemocell.log (and on to this script's stdout);
# 3. when oneCellShear exits non-zero, prints its reason as the last line of stderr (HemoCell
#    reports errors on stdout only: its last error-like line, else its last line), which the
#    campaign records as the run's failure reason; a cell HemoCell deleted is named there too;
# 4. decodes the elongation index of the output iterations in [T_START, T_MAX] with
#    decode-el.py, which writes el.json through `iuq rbc elongation` ($IUQ or iuq on PATH), and
#    fails the run when HemoCell deleted the cell or the fluid is sheared along z (HemoCell >= 2.2).
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
# A rerun in the same folder starts afresh: HemoCell would write tmp_0/, tmp_1/, ... next to
# an existing tmp/ and the decoder would read the old output.
rm -rf tmp tmp_[0-9]* output hemocell.log
read -r -a launcher <<< "${HEMOCELL_LAUNCHER:-}"
set +e
${launcher[@]+"${launcher[@]}"} "$simulator" config.xml 2>&1 | tee hemocell.log
status=${PIPESTATUS[0]}
set -e
if [ "$status" -ne 0 ]; then
    deleted=$(grep -m1 -A2 'Particle deleted\|(Delete Cells)' hemocell.log | tr -s ' \t\n' ' ' | sed 's/^ //; s/ $//' | cut -c1-300 || true)
    # HemoCell's last error-like line, leaving out its start-up force-cap warning and the
    # backtrace Open MPI's signal handler prints ("[host:pid] *** Process received signal ***").
    reason=$(grep -v -e 'Force limit active' -e '^\[[^]]*:[0-9]*\] ' hemocell.log \
        | grep -i 'error\|cannot\|exiting\|abort\|segmentation\|terminate\|what()\|not found\|does not exist\|failed' \
        | tail -n1 | tr -s ' \t' ' ' | sed 's/^ //' | cut -c1-300 || true)
    [ -n "$reason" ] || reason=$(grep -v '^[[:space:]]*$' hemocell.log | tail -n1 | tr -s ' \t' ' ' | sed 's/^ //' | cut -c1-300 || true)
    if [ "$status" -gt 128 ]; then
        what="was killed by signal $((status - 128))"
    else
        what="exited with status $status"
    fi
    # The campaign records the last line of stderr as the run's failure reason.
    if [ -n "$deleted" ]; then
        echo "run-hemocell.sh: oneCellShear $what; HemoCell deleted the cell: $deleted" >&2
    else
        echo "run-hemocell.sh: oneCellShear $what: ${reason:-no output}" >&2
    fi
    exit 1
fi

# HemoCell < 2 writes tmp/hdf5; later versions write <outputDirectory>/hdf5 (tmp, set in
# config.xml), or output/hdf5 when that key is ignored.
hdf5=tmp/hdf5
for candidate in tmp/hdf5 output/hdf5; do
    if [ -d "$candidate" ]; then
        hdf5=$candidate
        break
    fi
done
exec python3 "$here/decode-el.py" "$hdf5" --from "$t_start" --to "$t_max" --frames 10 --log hemocell.log --out el.json
