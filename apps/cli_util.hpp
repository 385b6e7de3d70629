// Command-line helpers shared by the pqdc apps: option-value parsing with
// messages that name the option, the one error report of every app's
// try/catch, and JSON string/number formatting for the apps'
// machine-readable output. Header-only, internal to apps/ (not
// installed): the library itself never parses command lines.
#pragma once

#include "pqdc/exceptions.hpp"

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <new>
#include <string>

namespace pqdc_cli {

/// A bad command line; the app prints the message and exits with 2.
struct UsageError {
    std::string message;
};

/// Prints the exception being handled as "program: message" and returns the
/// exit code: 2 for usage and option errors (the command line is wrong), 1
/// for everything else. `out_of_memory_hint` says what to change when memory
/// ran out. Call it from a catch (...) block only.
inline int report_current_exception(const char* program, const char* out_of_memory_hint = nullptr) {
    try {
        throw;
    } catch (const UsageError& e) {
        std::cerr << program << ": " << e.message << "\n";
        return 2;
    } catch (const pqdc::option_error& e) {
        std::cerr << program << ": " << e.what() << "\n";
        return 2;
    } catch (const std::bad_alloc&) {
        std::cerr << program << ": out of memory" << (out_of_memory_hint ? "; " : "")
                  << (out_of_memory_hint ? out_of_memory_hint : "") << "\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << program << ": " << e.what() << "\n";
        return 1;
    }
}

/// The whole of `text` as a double; false for garbage, trailing characters
/// and out-of-range values (ERANGE).
inline bool read_double(const std::string& text, double& v) {
    char* end = nullptr;
    errno = 0;
    v = std::strtod(text.c_str(), &end);
    return !text.empty() && end == text.c_str() + text.size() && errno != ERANGE;
}

/// A number, infinities included ("inf" is a real value for --sigma-n);
/// NaN, garbage and out-of-range text are refused.
inline double parse_number(const std::string& option, const std::string& text) {
    double v;
    if (!read_double(text, v) || std::isnan(v)) throw UsageError{option + " expects a number, got '" + text + "'"};
    return v;
}

inline double parse_finite(const std::string& option, const std::string& text) {
    double v;
    if (!read_double(text, v) || !std::isfinite(v))
        throw UsageError{option + " expects a finite number, got '" + text + "'"};
    return v;
}

/// A whole number in [lo, hi].
inline long parse_integer(const std::string& option, const std::string& text, long lo, long hi) {
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(text.c_str(), &end, 10);
    if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE)
        throw UsageError{option + " expects a whole number, got '" + text + "'"};
    if (v < lo || v > hi)
        throw UsageError{option + " must be between " + std::to_string(lo) + " and " + std::to_string(hi) +
                         ", got " + text};
    return v;
}

/// A whole number >= 0 of up to 64 bits (seeds).
inline std::uint64_t parse_unsigned(const std::string& option, const std::string& text) {
    char* end = nullptr;
    errno = 0;
    const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
    // strtoull accepts "-1" (as 2^64 - 1); a seed typed with a sign is a mistake.
    if (text.empty() || text[0] == '-' || end != text.c_str() + text.size() || errno == ERANGE)
        throw UsageError{option + " expects a whole number >= 0, got '" + text + "'"};
    return v;
}

/// s as a JSON string literal, quotes included.
inline std::string json_string(const std::string& s) {
    std::string out = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\') {
            out += '\\';
            out += c;
        } else if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", c);
            out += buf;
        } else {
            out += c;
        }
    }
    return out + "\"";
}

/// v with full precision; JSON has no NaN or infinity, so those become null.
inline std::string json_number(double v) {
    if (!std::isfinite(v)) return "null";
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.17g", v);
    return buf;
}

}  // namespace pqdc_cli
