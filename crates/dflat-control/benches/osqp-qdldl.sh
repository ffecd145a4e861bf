#!/usr/bin/env bash
# The OSQP anchor of the corner bench (feature `osqp-bench`) builds OSQP's C
# through cmake, and OSQP 1.x's cmake fetches its linear solver QDLDL with
# `git clone` from GitHub at configure time. Where only the package
# registries are reachable, this brings QDLDL's C source from PyPI (the
# `qdldl` sdist carries it, 0.1.9: OSQP asks for 0.1.8, 0.1.9 only raises
# cmake's minimum version) and writes a cmake toolchain file that points
# OSQP's FetchContent at it. Usage:
#
#   eval "$(bash crates/dflat-control/benches/osqp-qdldl.sh)"
#   cargo bench -p dflat-control --features osqp-bench --bench corner -- 200
#
# It prints the one export the build needs (CMAKE_TOOLCHAIN_FILE). cmake
# itself: `apt-get install -y cmake`. Files go to $OSQP_QDLDL_DIR
# (default /tmp/dflat-qdldl); nothing is written in the repository.
set -euo pipefail
dir="${OSQP_QDLDL_DIR:-/tmp/dflat-qdldl}"
version=0.1.9.post1
src="$dir/qdldl-$version/c/qdldl"
if [ ! -f "$src/CMakeLists.txt" ]; then
    mkdir -p "$dir"
    # --no-binary for qdldl alone: its build dependencies come as wheels.
    pip download --quiet --no-deps --no-binary qdldl "qdldl==$version" -d "$dir" >&2
    tar -xzf "$dir/qdldl-$version.tar.gz" -C "$dir"
fi
echo "set(FETCHCONTENT_SOURCE_DIR_QDLDL \"$src\")" > "$dir/toolchain.cmake"
echo "export CMAKE_TOOLCHAIN_FILE=$dir/toolchain.cmake"
