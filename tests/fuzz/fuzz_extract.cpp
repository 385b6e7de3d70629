// libFuzzer entry point; see fuzz_extract_core.hpp for the input layout.
//   cmake -S . -B build-fuzz -DCMAKE_CXX_COMPILER=clang++ -DPQDC_FUZZ=ON
//   cmake --build build-fuzz --target pqdc_fuzz_extract
//   UBSAN_OPTIONS=suppressions=tests/fuzz/ubsan.supp \
//     build-fuzz/tests/fuzz/pqdc_fuzz_extract -max_total_time=300 NEW_CORPUS_DIR tests/fuzz/corpus
#include "fuzz_extract_core.hpp"

#include <tbb/global_control.h>

#include <cstdio>
#include <cstdlib>
#include <memory>

// One thread: the grids are tiny, and TBB's start-up per call would dominate.
// Thread-count independence is tested by the unit tests.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
    static const auto one_thread = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, 1);
    openvdb::initialize();
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string problem = pqdc_fuzz::check_one_input(data, size);
    if (!problem.empty()) {
        std::fprintf(stderr, "pqdc_fuzz_extract: %s\n", problem.c_str());
        std::abort();
    }
    return 0;
}
