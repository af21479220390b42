#!/usr/bin/env bash
# One HemoCell oneCellShear run of the IUQ study, as the command of an iuq campaign
# (hemocell-shear.toml). Runs in the run directory, which iuq filled with config.xml and RBC.xml:
#
#   run-hemocell.sh T_START T_MAX
#
# 1. puts the cell in place for oneCellShear's wall layout and the material file under both
#    names oneCellShear versions load (RBC.xml/RBC.pos in HemoCell >= 2, RBC_HO.xml/RBC_HO.pos
#    in older ones and in the IUQ study). The layout is $HEMOCELL_LAYOUT: y-walls (HemoCell
#    <= 2.1: RBC.pos of this folder, the study's placement), z-walls (HemoCell >= 2.2:
#    RBC-z-walls.pos, the angles of HemoCell's own tank-treading placement RBC_tt.pos, the disk
#    in the shear plane as in the study, at the centre of the box; see README.md), or auto (the
#    default): read from helper/hemocellInit.hh of the HemoCell tree the oneCellShear binary
#    lies in (examples/oneCellShear/), else y-walls, which the decoder then checks against
#    HemoCell's fluid output. $HEMOCELL_POS, when set, is the placement file instead;
# 2. runs ${HEMOCELL_ONECELLSHEAR:-oneCellShear} config.xml (prefixed by $HEMOCELL_LAUNCHER,
#    e.g. "mpirun -np 4", when set);
#    HemoCell's stdout and stderr go to hemocell.log (and on to this script's stdout);
# 3. when oneCellShear exits non-zero, prints its reason as the last line of stderr (HemoCell
#    reports errors on stdout only: its last error-like line, else its last line), which the
#    campaign records as the run's failure reason; a cell HemoCell deleted is named there too;
# 4. decodes the elongation index of the output iterations in [T_START, T_MAX] in the shear plane
#    with decode-el.py --layout <the layout>, which writes el.json through `iuq rbc elongation`
#    ($IUQ or iuq on PATH), and fails the run when HemoCell deleted the cell, the cell left the
#    box, or the fluid's shear contradicts the layout.
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
simulator="${HEMOCELL_ONECELLSHEAR:-oneCellShear}"
if ! command -v "$simulator" >/dev/null 2>&1; then
    echo "run-hemocell.sh: HemoCell's oneCellShear was not found ('$simulator'); set HEMOCELL_ONECELLSHEAR=/path/to/HemoCell/examples/oneCellShear/oneCellShear" >&2
    exit 127
fi

layout="${HEMOCELL_LAYOUT:-auto}"
case "$layout" in
    auto|y-walls|z-walls) ;;
    *) echo "run-hemocell.sh: HEMOCELL_LAYOUT=$layout: expected auto, y-walls (HemoCell <= 2.1) or z-walls (HemoCell >= 2.2)" >&2
       exit 2 ;;
esac
if [ "$layout" = auto ]; then
    binary=$(readlink -f "$(command -v "$simulator")")
    init="$(dirname "$binary")/../../helper/hemocellInit.hh"
    if [ -f "$init" ] && grep -q 'Box3D(0, nx-1, 0, ny-1, nz-1, nz-1)' "$init"; then
        layout=z-walls
    elif [ -f "$init" ] && grep -q 'Box3D(0, nx-1, 0, *0, *0, nz-1)' "$init"; then
        layout=y-walls
    else
        layout=y-walls
        echo "run-hemocell.sh: cannot tell oneCellShear's wall layout (no HemoCell helper/hemocellInit.hh beside $binary): y-walls assumed, checked against HemoCell's fluid output afterwards; set HEMOCELL_LAYOUT to say" >&2
    fi
fi
position="$here/RBC.pos"
[ "$layout" = z-walls ] && position="$here/RBC-z-walls.pos"
if [ -n "${HEMOCELL_POS:-}" ]; then
    position=$HEMOCELL_POS
    if [ ! -f "$position" ]; then
        echo "run-hemocell.sh: HEMOCELL_POS=$position: no such file" >&2
        exit 2
    fi
fi
echo "run-hemocell.sh: wall layout $layout, cell placed by ${position##*/}" >&2
cp RBC.xml RBC_HO.xml
cp "$position" RBC.pos
cp "$position" RBC_HO.pos
# A rerun in the same folder starts afresh: HemoCell would write tmp_0/, tmp_1/, ... next to
# an existing tmp/ and the decoder would read the old output.
rm -rf tmp tmp_[0-9]* output hemocell.log
read -r -a launcher <<< "${HEMOCELL_LAUNCHER:-}"
# An MPI start-up failure (MPI_Init, before HemoCell reads anything: a clash of two Open MPI
# singletons starting at once) is not the model's answer: tried again, up to twice.
for attempt in 1 2 3; do
    set +e
    ${launcher[@]+"${launcher[@]}"} "$simulator" config.xml 2>&1 | tee hemocell.log
    status=${PIPESTATUS[0]}
    set -e
    if [ "$status" -eq 0 ] || ! grep -q 'An error occurred in MPI_Init' hemocell.log || [ "$attempt" -eq 3 ]; then
        break
    fi
    echo "run-hemocell.sh: MPI_Init failed (attempt $attempt); starting oneCellShear again" >&2
    sleep $((5 * attempt))
    rm -rf tmp tmp_[0-9]* output
done
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
exec python3 "$here/decode-el.py" "$hdf5" --from "$t_start" --to "$t_max" --frames 10 --layout "$layout" --log hemocell.log --out el.json
