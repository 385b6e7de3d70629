#!/usr/bin/env bash
# Builds pqdc_tests and the pqdc CLI (the CLI tests run the real binary) with
# AddressSanitizer + UndefinedBehaviorSanitizer (cmake -DPQDC_SANITIZE=ON: the
# library and the apps are instrumented, the test drivers only linked) and
# runs the Catch2 suite through ctest. Any sanitizer report fails the run:
# UBSan halts on the first error, ASan aborts on memory errors and leaks.
#
#   .ci/sanitize.sh                 # build dir: build-asan next to the sources
#   PQDC_ASAN_BUILD_DIR=/tmp/b PQDC_JOBS=4 .ci/sanitize.sh [extra ctest args]
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=${PQDC_ASAN_BUILD_DIR:-$root/build-asan}
jobs=${PQDC_JOBS:-2}

# -O1 -g1: line tables for the reports' stack traces at about half the compile
# time of -O2 -g (CI has 90 minutes for both builds and both suites).
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" \
      -DPQDC_SANITIZE=ON \
      -DPQDC_BUILD_TESTS=ON -DPQDC_BUILD_APPS=ON -DPQDC_BUILD_BENCH=OFF >/dev/null
cmake --build "$build" --target pqdc_tests pqdc_cli -j "$jobs"

# Narrow leak suppressions (see the file) instead of detect_leaks=0.
export ASAN_OPTIONS="abort_on_error=1:detect_stack_use_after_return=1:strict_string_checks=1:check_initialization_order=1${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export LSAN_OPTIONS="suppressions=$root/.ci/lsan.supp:print_suppressions=0${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"

# Only the Catch2 tests: other ctest entries need tools this script does not build.
ctest --test-dir "$build" -L '^pqdc_tests$' -j "$jobs" --output-on-failure --timeout 900 "$@"
