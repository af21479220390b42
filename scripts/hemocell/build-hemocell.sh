#!/usr/bin/env bash
# Build HemoCell's oneCellShear with interior viscosity, as the HemoCell IUQ study ran it, for
# the `command` model in examples/hemocell/ (see its README.md).
#
#   scripts/hemocell/build-hemocell.sh [options] HEMOCELL_SRC PALABOS_SRC
#
# HEMOCELL_SRC  an unpacked HemoCell source tree (a git checkout or release archive; the study
#               used v2.1, the last release with oneCellShear's walls on the y planes)
# PALABOS_SRC   an unpacked Palabos source tree, as HemoCell's docs have users download it
#               (HemoCell 2.0/2.1 ask for Palabos 2.0; v2.1r0 is the closest public tag)
#
# Options:
#   --out DIR            build folder (default ./hemocell-build); the sources are copied there,
#                        never modified where they are
#   --jobs N             make -j N (default 2)
#   --stock              build oneCellShear.cpp exactly as released (see "What is changed")
#   --allow-z-walls      build a HemoCell whose oneCellShear has its walls on the z planes
#                        (HemoCell >= 2.2); the adapter refuses such runs, see README.md
#   -h, --help
#
# What is changed in the copy, each step checked and reported:
#   1. Palabos is copied to <copy>/palabos and patched with HemoCell's patch/palabos.patch
#      (what patch/patchPLB.sh does). The patch was written against Palabos 2.0; on 2.1r0 two
#      hunks fail on context only (one more friend class in BlockLattice3D, one more #include
#      in isoThermalDynamics.hh) and one is already in Palabos: these are applied here by hand
#      and the result is checked.
#   2. `#define INTERIOR_VISCOSITY` is enabled in config/constant_defaults.h, as HemoCell's
#      docs (xml_files.rst) prescribe for interior viscosity; without it a material with
#      enableInteriorViscosity 1 makes HemoCell exit 1 at start ("Cannot enable interior
#      viscosity when INTERIOR_VISCOSITY is not defined at compile time", on stdout).
#   3. Unless --stock: oneCellShear.cpp gets the one line the interior-viscosity cases of
#      HemoCell have (cellCollision_interior_viscosity.cpp):
#        hemocell.setInteriorViscosityTimeScaleSeperation(<sim><interiorViscosity>,
#                                                         <sim><interiorViscosityEntireGrid>);
#      so that the study's config.xml values (10 and 1000 steps) are used. Released
#      oneCellShear.cpp does not read them and retags the whole grid every step (timescales 1,
#      with a warning), which is slower and not what the study's configuration says.
#
# Then HemoCell's own build: cmake + make in build/hemocell (libhemocell.a) and in
# examples/oneCellShear/build. Prints the path of the oneCellShear binary on the last line
# of stdout. Needs cmake, an MPI C++ compiler (libopenmpi-dev), parallel HDF5
# (libhdf5-openmpi-dev) and patch.
set -euo pipefail

usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; }
out=./hemocell-build
jobs=2
stock=0
allow_z=0
args=()
while [ $# -gt 0 ]; do
    case "$1" in
        --out) out=$2; shift 2 ;;
        --jobs) jobs=$2; shift 2 ;;
        --stock) stock=1; shift ;;
        --allow-z-walls) allow_z=1; shift ;;
        -h|--help) usage; exit 0 ;;
        -*) echo "build-hemocell.sh: unknown option $1" >&2; exit 2 ;;
        *) args+=("$1"); shift ;;
    esac
done
if [ ${#args[@]} -ne 2 ]; then
    usage >&2
    exit 2
fi
hemocell_src=$(cd "${args[0]}" && pwd)
palabos_src=$(cd "${args[1]}" && pwd)
say() { echo "build-hemocell.sh: $*" >&2; }
die() { say "$*"; exit 1; }

[ -f "$hemocell_src/hemocell.h" ] && [ -f "$hemocell_src/examples/oneCellShear/oneCellShear.cpp" ] \
    || die "$hemocell_src is not a HemoCell source tree (no hemocell.h or examples/oneCellShear/oneCellShear.cpp)"
[ -d "$palabos_src/src" ] && [ -f "$palabos_src/src/palabos3D.h" ] \
    || die "$palabos_src is not a Palabos source tree (no src/palabos3D.h)"
[ -f "$hemocell_src/patch/palabos.patch" ] || die "$hemocell_src/patch/palabos.patch is missing"
for tool in cmake make patch mpicxx; do
    command -v "$tool" >/dev/null || die "$tool not found (install cmake, make, patch and an MPI compiler, e.g. libopenmpi-dev)"
done

# The wall layout of oneCellShear (helper/hemocellInit.hh, iniLatticeSquareCouette).
init="$hemocell_src/helper/hemocellInit.hh"
if grep -q 'Box3D(0, nx-1, 0, *0, *0, nz-1)' "$init"; then
    say "wall layout: velocity walls on the y planes 0 and ny-1 (HemoCell <= 2.1), as the study and iuq's native model"
elif grep -q 'Box3D(0, nx-1, 0, ny-1, nz-1, nz-1)' "$init"; then
    if [ $allow_z -eq 0 ]; then
        die "this HemoCell's oneCellShear has its walls on the z planes 0 and nz-1 (HemoCell >= 2.2, Lees-Edwards commit 267a21d): a 9.5 µm gap, a different experiment from the study's (walls 19.5 µm apart on the y planes). Build HemoCell v2.1 (or pass --allow-z-walls; the adapter then refuses the runs)"
    fi
    say "WARNING: walls on the z planes (HemoCell >= 2.2); examples/hemocell refuses such runs"
else
    say "WARNING: cannot tell the wall layout from $init"
fi

mkdir -p "$out"
out=$(cd "$out" && pwd)
copy="$out/hemocell"
start=$(date +%s)
if [ -e "$copy" ]; then
    say "reusing $copy (delete it for a clean build)"
else
    say "copying HemoCell to $copy and Palabos to $copy/palabos"
    mkdir -p "$copy"
    (cd "$hemocell_src" && tar -c --exclude=./palabos --exclude=./.git .) | tar -x -C "$copy"
    mkdir -p "$copy/palabos"
    (cd "$palabos_src" && tar -c --exclude=./.git .) | tar -x -C "$copy/palabos"

    # 1. Palabos patch (patch/patchPLB.sh is `patch -d ../palabos -p1 < ./palabos.patch`).
    say "patching Palabos with patch/palabos.patch"
    set +e
    (cd "$copy/palabos" && patch -p1 --forward --batch --no-backup-if-mismatch -r - < "$copy/patch/palabos.patch") > "$out/palabos-patch.log" 2>&1
    set -e
    failed=$(grep -c 'hunks\? FAILED' "$out/palabos-patch.log" || true)
    say "patch: $(grep -c '^patching file\|^checking file' "$out/palabos-patch.log" || true) files, $failed with failed hunks (log: $out/palabos-patch.log)"
    lattice_h="$copy/palabos/src/atomicBlock/blockLattice3D.h"
    if ! grep -q 'struct ImplicitGrid3D {' "$lattice_h"; then
        say "applying the blockLattice3D.h hunk by hand (ImplicitGrid3D after the class's last friend)"
        python3 - "$lattice_h" <<'EOF'
import re, sys
path = sys.argv[1]
text = open(path).read()
# The end of class BlockLattice3D: its last friend declaration followed by "};".
m = list(re.finditer(r"(    friend class \w+CollideAndStream3D;\n)(\};\n)", text))
if not m:
    sys.exit("build-hemocell.sh: cannot find the end of class BlockLattice3D in " + path)
last = m[0]
insert = ("    template<typename T_, template<typename U_> class Descriptor_>\n"
          "    friend class ImplicitGrid3D;\n"
          "};\n\n"
          "template<typename T, template<typename U> class Descriptor>\n"
          "struct ImplicitGrid3D {\n"
          "        BlockLattice3D<T,Descriptor>& parent;\n"
          "        ImplicitGrid3D(BlockLattice3D<T,Descriptor>& parent_);\n"
          "        const Cell<T,Descriptor> & operator () (int x,int y,int z) const;\n"
          "        Cell<T,Descriptor> & operator () (int x,int y,int z);\n"
          "};\n")
text = text[:last.start(2)] + insert + text[last.end(2):]
open(path, "w").write(text)
EOF
    fi
    iso_hh="$copy/palabos/src/basicDynamics/isoThermalDynamics.hh"
    if ! grep -q '#include "atomicBlock/blockLattice3D.h"' "$iso_hh"; then
        say "applying the isoThermalDynamics.hh hunk by hand (#include \"atomicBlock/blockLattice3D.h\")"
        sed -i 's|^#include <limits>$|#include <limits>\n#include "atomicBlock/blockLattice3D.h"|' "$iso_hh"
        grep -q '#include "atomicBlock/blockLattice3D.h"' "$iso_hh" || die "could not add the include to $iso_hh"
    fi
    # Every file the patch touches must now carry its added lines: check a marker per file.
    grep -q 'ImplicitGrid3D<T,Descriptor> grid;' "$lattice_h" || die "Palabos patch incomplete: $lattice_h has no ImplicitGrid3D grid"
    [ -f "$copy/palabos/src/core/implicitGrid3D.h" ] || die "Palabos patch incomplete: src/core/implicitGrid3D.h missing"
    rej=$(grep 'FAILED' "$out/palabos-patch.log" | grep -v -e 'blockLattice3D.h' -e 'isoThermalDynamics.hh' || true)
    files_failed=$(awk '/^patching file|^checking file/{f=$3} /FAILED/{print f}' "$out/palabos-patch.log" | sort -u | grep -v -e 'atomicBlock/blockLattice3D.h$' -e 'basicDynamics/isoThermalDynamics.hh$' || true)
    if [ -n "$files_failed" ]; then
        die "Palabos patch failed in files not handled here: $files_failed (see $out/palabos-patch.log); use the Palabos version HemoCell asks for"
    fi

    # 1b. Palabos >= 2.1 returns std::unique_ptr where 2.0 returned std::auto_ptr; HemoCell
    # made the same replacement when it moved to Palabos 2.2.1 (commit 3dd2148).
    if ! grep -rq 'auto_ptr' "$copy/palabos/src"; then
        for f in $(grep -rl 'std::auto_ptr' "$copy/IO" "$copy/helper" "$copy/core" "$copy/examples/oneCellShear" 2>/dev/null || true); do
            sed -i 's/std::auto_ptr/std::unique_ptr/g' "$f"
            say "std::auto_ptr -> std::unique_ptr in ${f#$copy/} (Palabos returns unique_ptr)"
        done
    fi

    # 2. interior viscosity at compile time.
    defaults="$copy/config/constant_defaults.h"
    sed -i 's|^//#define INTERIOR_VISCOSITY|#define INTERIOR_VISCOSITY|' "$defaults"
    grep -q '^#define INTERIOR_VISCOSITY' "$defaults" || die "could not enable INTERIOR_VISCOSITY in $defaults"
    say "INTERIOR_VISCOSITY enabled in config/constant_defaults.h"

    # 3. the interior-viscosity time scales from config.xml.
    case_cpp="$copy/examples/oneCellShear/oneCellShear.cpp"
    if [ $stock -eq 0 ] && ! grep -q 'setInteriorViscosityTimeScaleSeperation' "$case_cpp"; then
        python3 - "$case_cpp" <<'EOF'
import sys
path = sys.argv[1]
text = open(path).read()
anchor = "hemocell.setFluidOutputs(outputs);\n"
if anchor not in text:
    sys.exit("build-hemocell.sh: cannot find `hemocell.setFluidOutputs(outputs);` in " + path)
line = ("\n  // added by iuq's build-hemocell.sh, as in cellCollision_interior_viscosity.cpp\n"
        "  hemocell.setInteriorViscosityTimeScaleSeperation((*cfg)[\"sim\"][\"interiorViscosity\"].read<int>(),"
        "(*cfg)[\"sim\"][\"interiorViscosityEntireGrid\"].read<int>());\n")
open(path, "w").write(text.replace(anchor, anchor + line, 1))
EOF
        grep -q 'setInteriorViscosityTimeScaleSeperation' "$case_cpp" || die "could not add the time scales to $case_cpp"
        say "oneCellShear.cpp reads <sim><interiorViscosity> and <interiorViscosityEntireGrid>"
    fi
fi

# HemoCell's build: the library first (build/hemocell), then the case (its CMakeLists.txt
# builds the library again through scripts/safe_libhemocell_compilation.sh, which then has
# nothing to do).
say "building libhemocell.a (make -j$jobs; the whole of Palabos is compiled in)"
(cd "$copy/build/hemocell" && cmake . -DBUILD_TESTING=OFF > "$out/cmake-lib.log" 2>&1 \
    && make -j"$jobs" > "$out/make-lib.log" 2>&1) || die "library build failed: see $out/cmake-lib.log and $out/make-lib.log"
# One job: the case's build runs cmake twice in build/hemocell (hemocell_pre and the
# ExternalProject's configure step), which collide under make -j ("Cmake might sometimes fail
# while using the -j flag with make", HemoCell's QuickStart); the case is one source file.
say "building oneCellShear (make -j1)"
mkdir -p "$copy/examples/oneCellShear/build"
(cd "$copy/examples/oneCellShear/build" && cmake .. -DBUILD_TESTING=OFF > "$out/cmake-case.log" 2>&1 \
    && make -j1 > "$out/make-case.log" 2>&1) || die "oneCellShear build failed: see $out/cmake-case.log and $out/make-case.log"
binary="$copy/examples/oneCellShear/oneCellShear"
[ -x "$binary" ] || die "no binary at $binary after the build (see $out/make-case.log)"
say "built in $(( $(date +%s) - start )) s"
echo "$binary"
