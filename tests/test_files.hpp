// Whole-file reads and writes for the tests (byte comparisons of outputs).
#pragma once

#include <fstream>
#include <iterator>
#include <string>

namespace pqdc_test {

inline std::string read_file(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
}

inline void write_file(const std::string& path, const std::string& bytes) {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    f << bytes;
}

}  // namespace pqdc_test
