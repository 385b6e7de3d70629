// The bridge between a running extraction (GIL released, C++ threads) and the
// Python caller: the progress hook reacquires the GIL on the calling thread,
// delivers pending signals (Ctrl-C) and calls the user's callback; a Python
// exception from either is kept and re-raised unchanged once the C++ side
// has unwound with cancelled_error.
#pragma once

#include <pybind11/pybind11.h>

#include <functional>
#include <optional>
#include <string_view>

namespace pqdc::python {

/// A callback's "stop": False, or numpy's False (what `elapsed < limit`
/// returns); None and every other value go on.
inline bool returned_false(PyObject* result) {
    if (result == Py_False) return true;
    const std::string_view type = Py_TYPE(result)->tp_name;  // numpy.bool_ (numpy 1), numpy.bool (numpy 2)
    return (type == "numpy.bool_" || type == "numpy.bool") && PyObject_IsTrue(result) == 0;
}

class RunControl {
public:
    /// callback: None, or callable(fraction) whose return value False cancels.
    explicit RunControl(pybind11::object callback) : callback_(std::move(callback)) {}

    /// The hook for C++ options (called with the GIL released).
    bool report(double fraction) {
        pybind11::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) {  // KeyboardInterrupt from the SIGINT handler
            error_.emplace();
            return false;
        }
        if (callback_.is_none()) return true;
        try {
            const pybind11::object result = callback_(fraction);
            return !returned_false(result.ptr());
        } catch (pybind11::error_already_set& e) {
            error_.emplace(std::move(e));
            return false;
        }
    }

    /// A hook reporting the sub-range [from, to] of the whole job.
    std::function<bool(double)> stage(double from, double to) {
        return [this, from, to](double f) { return report(from + (to - from) * f); };
    }

    /// Call with the GIL held after catching cancelled_error: re-raises what
    /// the hook caught, if anything (else the cancellation was the callback's).
    void rethrow_pending() {
        if (error_) {
            pybind11::error_already_set e = std::move(*error_);
            error_.reset();
            throw e;
        }
    }

private:
    pybind11::object callback_;
    std::optional<pybind11::error_already_set> error_;
};

}  // namespace pqdc::python
