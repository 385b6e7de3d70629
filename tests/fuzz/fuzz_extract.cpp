// libFuzzer entry point; see fuzz_extract_core.hpp for the input layout.
//   cmake -S . -B build-fuzz -DCMAKE_CXX_COMPILER=clang++ -DPQDC_FUZZ=ON
//   cmake --build build-fuzz --target pqdc_fuzz_extract
//   build-fuzz/tests/fuzz/pqdc_fuzz_extract -max_total_time=300 NEW_CORPUS_DIR tests/fuzz/corpus
#include "fuzz_extract_core.hpp"

#include <cstdio>
#include <cstdlib>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string problem = pqdc_fuzz::check_one_input(data, size);
    if (!problem.empty()) {
        std::fprintf(stderr, "pqdc_fuzz_extract: %s\n", problem.c_str());
        std::abort();
    }
    return 0;
}
