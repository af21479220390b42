#!/usr/bin/env bash
# Build HemoCell's oneCellShear with interior viscosity, as the HemoCell IUQ study ran it, for
# the `command` model in examples/hemocell/ (see its README.md).
#
#   scripts/hemocell/build-hemocell.sh [options] HEMOCELL_SRC PALABOS_SRC
#
# HEMOCELL_SRC  an unpacked HemoCell source tree (a git checkout or release archive): v2.1, the
#               study's version and the last with oneCellShear's walls on the y planes, or any
#               later release up to 2.7 (walls on the z planes; the adapter handles both)
# PALABOS_SRC   an unpacked Palabos source tree, the version that HemoCell release asks for:
#               2.0 for HemoCell 2.0/2.1 (not retrievable any more; v2.1r0 is the closest public
#               tag), v2.3.0 for HemoCell 2.7 (its setup.sh)
#
# Options:
#   --out DIR            build folder (default ./hemocell-build); the sources are copied there,
#                        never modified where they are
#   --jobs N             make -j N (default 2)
#   --stock              build oneCellShear.cpp exactly as released (see "What is changed")
#   -h, --help
#
# Two build systems are recognised:
#   legacy (HemoCell <= 2.1): build/hemocell/CMakeLists.txt builds libhemocell.a, then
#     examples/oneCellShear/CMakeLists.txt the case;
#   top-level (HemoCell >= 2.2 with a top-level CMakeLists.txt defining the library variants,
#     e.g. 2.7): one CMake tree in <copy>/build, `make oneCellShear`.
#
# What is changed in the copy, each step checked and reported:
#   1. Palabos is copied to <copy>/palabos and patched with HemoCell's patch/palabos.patch
#      (what patch/patchPLB.sh does). HemoCell 2.7's patch applies to Palabos v2.3.0 as is.
#      HemoCell 2.1's was written against Palabos 2.0; on 2.1r0 two hunks fail on context only
#      (one more friend class in BlockLattice3D, one more #include in isoThermalDynamics.hh) and
#      one is already in Palabos: these are applied here by hand and the result is checked.
#   2. Interior viscosity at compile time, as HemoCell's docs (xml_files.rst) prescribe; without
#      it a material with enableInteriorViscosity 1 makes HemoCell exit 1 at start ("Cannot
#      enable interior viscosity when INTERIOR_VISCOSITY is not defined at compile time", on
#      stdout). Legacy: `#define INTERIOR_VISCOSITY` in config/constant_defaults.h. Top-level:
#      oneCellShear is linked with the library variant hemocell_interior_viscosity (built with
#      that definition), as HemoCell's own cellCollision_interior_viscosity example is.
#   3. Unless --stock: oneCellShear.cpp gets the one line the interior-viscosity cases of
#      HemoCell have (cellCollision_interior_viscosity.cpp):
#        hemocell.setInteriorViscosityTimeScaleSeperation(<sim><interiorViscosity>,
#                                                         <sim><interiorViscosityEntireGrid>);
#      so that the study's config.xml values (10 and 1000 steps) are used. Released
#      oneCellShear.cpp does not read them and retags the whole grid every step (timescales 1,
#      with a warning), which is slower and not what the study's configuration says.
#
# The wall layout of the built oneCellShear (helper/hemocellInit.hh) is reported: y planes
# 19.5 um apart (<= 2.1) or z planes 9.5 um apart (>= 2.2); examples/hemocell handles both
# (its README.md says how they differ).
#
# Then HemoCell's own build. Prints the path of the oneCellShear binary on the last line of
# stdout. Needs cmake, an MPI C++ compiler (libopenmpi-dev), parallel HDF5
# (libhdf5-openmpi-dev) and patch.
set -euo pipefail

usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; }
out=./hemocell-build
jobs=2
stock=0
args=()
while [ $# -gt 0 ]; do
    case "$1" in
        --out) out=$2; shift 2 ;;
        --jobs) jobs=$2; shift 2 ;;
        --stock) stock=1; shift ;;
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
    say "wall layout: velocity walls on the y planes 0 and ny-1, 19.5 um apart (HemoCell <= 2.1), as the study and iuq's native model"
elif grep -q 'Box3D(0, nx-1, 0, ny-1, nz-1, nz-1)' "$init"; then
    say "wall layout: velocity walls on the z planes 0 and nz-1, 9.5 um apart (HemoCell >= 2.2, Lees-Edwards commit 267a21d); examples/hemocell places and measures the cell for it"
else
    say "WARNING: cannot tell the wall layout from $init"
fi
if grep -q '_interior_viscosity' "$hemocell_src/CMakeLists.txt" 2>/dev/null; then
    build_system=top-level
elif [ -f "$hemocell_src/build/hemocell/CMakeLists.txt" ]; then
    build_system=legacy
else
    die "$hemocell_src: neither a top-level CMakeLists.txt with the hemocell_interior_viscosity library (HemoCell >= 2.2) nor build/hemocell/CMakeLists.txt (HemoCell <= 2.1)"
fi
say "build system: $build_system"

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
    if [ "$build_system" = legacy ]; then
    # HemoCell 2.1's patch on Palabos 2.1r0: the hunks that fail on context only.
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

    else
        if [ "$failed" != 0 ]; then
            die "Palabos patch failed ($failed files with failed hunks, see $out/palabos-patch.log); use the Palabos version this HemoCell asks for (its setup.sh)"
        fi
    fi

    # 1b. Palabos >= 2.1 returns std::unique_ptr where 2.0 returned std::auto_ptr; HemoCell
    # made the same replacement when it moved to Palabos 2.2.1 (commit 3dd2148).
    if [ "$build_system" = legacy ] && ! grep -rq 'auto_ptr' "$copy/palabos/src"; then
        for f in $(grep -rl 'std::auto_ptr' "$copy/IO" "$copy/helper" "$copy/core" "$copy/examples/oneCellShear" 2>/dev/null || true); do
            sed -i 's/std::auto_ptr/std::unique_ptr/g' "$f"
            say "std::auto_ptr -> std::unique_ptr in ${f#$copy/} (Palabos returns unique_ptr)"
        done
    fi

    # 2. interior viscosity at compile time.
    if [ "$build_system" = legacy ]; then
        defaults="$copy/config/constant_defaults.h"
        sed -i 's|^//#define INTERIOR_VISCOSITY|#define INTERIOR_VISCOSITY|' "$defaults"
        grep -q '^#define INTERIOR_VISCOSITY' "$defaults" || die "could not enable INTERIOR_VISCOSITY in $defaults"
        say "INTERIOR_VISCOSITY enabled in config/constant_defaults.h"
    else
        case_cmake="$copy/examples/oneCellShear/CMakeLists.txt"
        sed -i 's|target_link_libraries(${EXEC_NAME} ${PROJECT_NAME})|target_link_libraries(${EXEC_NAME} "${PROJECT_NAME}_interior_viscosity")|' "$case_cmake"
        grep -q '_interior_viscosity' "$case_cmake" || die "could not link oneCellShear with hemocell_interior_viscosity in $case_cmake"
        say "oneCellShear linked with the library variant hemocell_interior_viscosity (INTERIOR_VISCOSITY defined)"
    fi

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

if [ "$build_system" = top-level ]; then
    # One CMake tree; the oneCellShear target pulls in only the library variant it links.
    say "building oneCellShear and hemocell_interior_viscosity (make -j$jobs; the whole of Palabos is compiled in)"
    mkdir -p "$copy/build"
    (cd "$copy/build" && cmake .. -DBUILD_TESTING=OFF > "$out/cmake.log" 2>&1 \
        && make -j"$jobs" oneCellShear > "$out/make.log" 2>&1) || die "build failed: see $out/cmake.log and $out/make.log"
else
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
fi
binary="$copy/examples/oneCellShear/oneCellShear"
[ -x "$binary" ] || die "no binary at $binary after the build (see $out/make-case.log)"
say "built in $(( $(date +%s) - start )) s"
echo "$binary"
