// The exceptions pqdc's library throws. The library never prints; apps catch
// pqdc::error, print what() and map the kind to an exit code.
#pragma once

#include <stdexcept>
#include <string>

namespace pqdc {

/// Base of every error pqdc throws on purpose.
class error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// An option value is out of range or options conflict (usage error).
class option_error : public error {
public:
    using error::error;
};

/// The input (file, grid, field) cannot be used: unreadable, wrong type,
/// unsupported transform, non-finite values, no such grid...
class input_error : public error {
public:
    using error::error;
};

/// Writing the output failed (permissions, missing directory, disk full).
class io_error : public error {
public:
    using error::error;
};

/// The job would need more memory than allowed; thrown before allocating.
class resource_error : public error {
public:
    using error::error;
};

/// The caller's progress callback asked to stop.
class cancelled_error : public error {
public:
    using error::error;
};

}  // namespace pqdc
