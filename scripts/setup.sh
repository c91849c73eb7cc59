#!/usr/bin/env bash
# scripts/setup.sh — installs, with apt-get, the Debian 12 packages trellis needs to build, test,
# benchmark and plot. Checks each package with dpkg-query first: when everything is present it
# prints so and runs no apt command at all. Run as root (no sudo is assumed); safe to run twice.
set -euo pipefail

packages=(
  # toolchain (a minimal Debian 12 has none of it)
  g++ make cmake pkg-config
  # libraries
  libeigen3-dev          # Eigen 3.4: all of trellis's linear algebra
  nlohmann-json3-dev     # scene files (JSON)
  libtinyxml2-dev        # URDF import (XML with line numbers)
  libsundials-dev        # CVODES: Riccati / trajectory integration (control, planned)
  # LAPACK: the Schur forms and inverses of the algebraic Riccati solvers (control/src/lapack.cpp),
  # linked as the generic liblapack.so / libblas.so (Debian's alternatives)
  liblapack-dev libblas-dev
  # OpenBLAS, single-threaded: through Debian's alternatives it becomes libblas.so.3 and
  # liblapack.so.3 for every program (MUMPS inside Ipopt included; `update-alternatives --config
  # libblas.so.3-x86_64-linux-gnu` switches back). The main job's Ipopt/MUMPS 8.7 → 4.6 s, the
  # whole job 26.9 → 22.1 s, a CARE at n = 400 ~3x faster; the suite passes on either BLAS
  # (docs/performance.md). Serial: trellis runs its own threads beside it.
  libopenblas0-serial
  openmpi-bin libopenmpi-dev  # trellis-mpi: `mpirun trellis-mpi funnel` (docs/funnels.md)
  coinor-libipopt-dev    # Ipopt: trajectory optimization (optimization, planned)
  catch2                 # Catch2 2.13: the test suite
  libbenchmark-dev       # Google Benchmark: bench/
  # clang with its sanitizer runtimes and libFuzzer: the presets asan-clang and fuzz
  clang-14 libclang-rt-14-dev libfuzzer-14-dev
  # plots of the benchmark results
  python3 python3-matplotlib
  # the Python module trellis_mech (python/) and its tests
  pybind11-dev python3-dev python3-numpy python3-pytest
  # `pip install .` of trellis_mech (pyproject.toml), and its test
  python3-pip
  # the C++ API reference (docs/Doxyfile) and its test
  doxygen
  # the 3D viewer (viewer/, `trellis view`): three.js, included in every page it writes, and the
  # headless browser its tests open the pages in (tests/viewer/)
  libjs-three chromium
)

missing=()
for p in "${packages[@]}"; do
  if [[ $(dpkg-query -W -f='${db:Status-Status}' "$p" 2>/dev/null || true) != installed ]]; then
    missing+=("$p")
  fi
done

if [[ ${#missing[@]} -eq 0 ]]; then
  echo "setup.sh: all ${#packages[@]} packages already installed; nothing to do."
  exit 0
fi

if [[ $(id -u) -ne 0 ]]; then
  echo "setup.sh: missing packages: ${missing[*]}" >&2
  echo "setup.sh: run this script as root to install them (apt-get needs it)." >&2
  exit 1
fi

echo "setup.sh: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -q
# No recommends: none of these packages needs its recommended extras for building or plotting
# (matplotlib draws with its bundled fonts and the Agg backend).
apt-get install -y -q --no-install-recommends "${missing[@]}"
echo "setup.sh: done."
