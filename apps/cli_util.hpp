// Command-line helpers shared by the pqdc apps: CLI11 parsing with pqdc's
// messages (an option without its value, unknown options), option-value
// conversion with messages that name the option, the one error report of
// every app's try/catch, and JSON output through nlohmann-json. Header-only,
// internal to apps/ (not installed): the library never parses command lines.
//
// Conventions shared by every app: `--opt value` and `--opt=value`; a value
// option given twice takes the last value; exit codes 0 ok, 1 runtime
// error, 2 usage error. JSON: a number that is not finite is written as null
// (JSON has no NaN or infinity; nlohmann's dump does the same).
#pragma once

#include "pqdc/decimate.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/mesh_io.hpp"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <openvdb/openvdb.h>

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cctype>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <exception>
#include <filesystem>
#include <iostream>
#include <new>
#include <optional>
#include <sstream>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace pqdc_cli {

/// A bad command line; the app prints the message and exits with 2.
struct UsageError {
    std::string message;
};

/// A library message with the command's option named where it says what
/// to change ("write it with double precision" -> --precision double).
inline std::string with_option_names(std::string text) {
    const std::string precision = "write it with double precision (";
    const std::size_t at = text.find(precision);
    if (at != std::string::npos) text.insert(at + precision.size(), "--precision double: ");
    return text;
}

/// Prints the exception being handled as "program: message" and returns the
/// exit code: 2 for usage and option errors (the command line is wrong), 1
/// for everything else. `out_of_memory_hint` says what to change when memory
/// ran out. Call it from a catch (...) block only.
inline int report_current_exception(const char* program, const char* out_of_memory_hint = nullptr) {
    // Each message in one write: the ranks of pqdc-mpi share a terminal.
    const auto print = [&](const std::string& message) { std::cerr << (std::string(program) + ": " + message + "\n"); };
    try {
        throw;
    } catch (const UsageError& e) {
        print(e.message);
        return 2;
    } catch (const pqdc::option_error& e) {
        print(e.what());
        return 2;
    } catch (const std::bad_alloc&) {
        print(std::string("out of memory") + (out_of_memory_hint ? std::string("; ") + out_of_memory_hint : ""));
        return 1;
    } catch (const std::exception& e) {
        print(with_option_names(e.what()));
        return 1;
    }
}

/// What every app does with the signals a write can raise: with a file
/// size limit (ulimit -f) write() fails with EFBIG and is reported instead
/// of SIGXFSZ killing the process without a word; a closed pipe on -o - is
/// a write error (EPIPE), not a silent death by SIGPIPE.
inline void report_write_signals_as_errors() {
    std::signal(SIGXFSZ, SIG_IGN);
    std::signal(SIGPIPE, SIG_IGN);
}

/// An app's main: options = parse(argc, argv, done), then run(options)
/// unless parsing answered --help or --version itself (done); any exception
/// becomes its message and exit code (report_current_exception).
template <class Parse, class Run>
int run_app(const char* program, int argc, char** argv, const Parse& parse, const Run& run,
            const char* out_of_memory_hint = nullptr) {
    try {
        report_write_signals_as_errors();
        bool done = false;
        const auto options = parse(argc, argv, done);
        if (done) return 0;
        return run(options);
    } catch (...) {
        return report_current_exception(program, out_of_memory_hint);
    }
}

/// The whole of `text` as a double; false for garbage, trailing characters
/// and values beyond the double range. A value below it (1e-320: a
/// denormal, or 0) is a number, whatever the option then makes of it.
inline bool read_double(const std::string& text, double& v) {
    char* end = nullptr;
    errno = 0;
    v = std::strtod(text.c_str(), &end);
    const bool overflow = errno == ERANGE && std::abs(v) > 1.0;  // strtod gives +-HUGE_VAL
    return !text.empty() && end == text.c_str() + text.size() && !overflow;
}

/// check() (a library validate()) with its option_error turned into a
/// UsageError that names the command-line options, `names` (library field
/// as the message gives it, option), instead of the library's fields.
template <class Check>
void check_with_option_names(const Check& check, const std::vector<std::pair<std::string, std::string>>& names) {
    try {
        check();
    } catch (const pqdc::option_error& e) {
        std::string message = e.what();
        for (const auto& [field, option] : names)
            for (std::size_t at = message.find(field); at != std::string::npos; at = message.find(field, at))
                message.replace(at, field.size(), option);
        throw UsageError{message};
    }
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

/// --brick-size (pqdc::BrickOptions::brick_size): a power of two from 128 to 4096.
inline int parse_brick_size(const std::string& text) {
    const int size = int(parse_integer("--brick-size", text, 128, 4096));
    if (size & (size - 1))
        throw UsageError{"--brick-size must be a power of two from 128 to 4096 voxels, got " + text};
    return size;
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

/// --format's value (the apps that write meshes).
inline pqdc::MeshFormat parse_mesh_format(const std::string& text) {
    try {
        return pqdc::mesh_format_from_name(text);
    } catch (const pqdc::error&) {
        throw UsageError{"--format expects obj, ply, off or stl, got '" + text + "'"};
    }
}

/// --precision's value (the apps that write meshes).
inline pqdc::VertexPrecision parse_vertex_precision(const std::string& text) {
    if (text == "float") return pqdc::VertexPrecision::float32;
    if (text == "double") return pqdc::VertexPrecision::float64;
    throw UsageError{"--precision expects float or double, got '" + text + "'"};
}

/// -o - names no file, so no extension says the format: --format must.
inline void check_output_format(const std::string& output, const std::optional<pqdc::MeshFormat>& format) {
    if (output == "-" && !format)
        throw UsageError{"-o - writes the mesh to standard output; say which format with --format obj|ply|off|stl"};
    if (output == "-" || !format) return;
    // An extension of another format would name a file that readers
    // (pqdc's own too) take for what it is not.
    std::optional<pqdc::MeshFormat> named;
    try {
        named = pqdc::mesh_format_from_path(output);
    } catch (const pqdc::option_error&) {  // not a mesh extension: --format decides
    }
    if (named && *named != *format)
        throw UsageError{"the extension of -o '" + output + "' says " + pqdc::mesh_format_name(*named) +
                         " but --format says " + pqdc::mesh_format_name(*format) +
                         "; make them agree (or drop --format)"};
}

/// True when a and b name the same file, existing or not (links, "." and
/// ".." resolved where the path exists).
inline bool same_file(const std::string& a, const std::string& b) {
    // Absolute first: weakly_canonical leaves a relative path none of
    // whose parts exists as it is ("o.ply"), but resolves "./o.ply".
    std::error_code ea, eb;
    const auto ca = std::filesystem::weakly_canonical(std::filesystem::absolute(a, ea), ea),
               cb = std::filesystem::weakly_canonical(std::filesystem::absolute(b, eb), eb);
    return (!ea && !eb) ? ca == cb : a == b;
}

/// True when `path` lies inside the existing directory `dir` (a brick
/// store the run reads), links resolved.
inline bool inside_directory(const std::string& dir, const std::string& path) {
    std::error_code ed, ep;
    if (!std::filesystem::is_directory(dir, ed)) return false;
    const auto cd = std::filesystem::weakly_canonical(std::filesystem::absolute(dir, ed), ed),
               cp = std::filesystem::weakly_canonical(std::filesystem::absolute(path, ep), ep);
    if (ed || ep) return false;
    const auto rel = cp.lexically_relative(cd);
    return !rel.empty() && *rel.begin() != "..";
}

/// A UsageError when two of the run's files, (what the message calls it,
/// path), are the same file, or a file it writes lies in a directory it
/// reads (a brick store); the first `reads` entries are read, the others
/// written. Empty paths are skipped; "-" is a stream: two outputs to
/// standard output are refused (their bytes would mix), stdin and stdout
/// are not. A run must never write over its input or one output over another.
inline void check_distinct_files(const std::vector<std::pair<std::string, std::string>>& files,
                                 std::size_t reads = 1) {
    for (std::size_t i = 0; i < files.size(); ++i)
        for (std::size_t j = i + 1; j < files.size(); ++j) {
            const std::string &a = files[i].second, &b = files[j].second;
            if (a.empty() || b.empty()) continue;
            if (a == "-" || b == "-") {
                if (a == b && i >= reads)
                    throw UsageError{files[i].first + " and " + files[j].first +
                                     " both write to standard output; give one of them a file"};
                continue;
            }
            if (i < reads && j >= reads && inside_directory(a, b))
                throw UsageError{files[j].first + " '" + b + "' lies inside " + files[i].first + " '" + a +
                                 "', which the run reads; write it elsewhere"};
            if (!same_file(a, b)) continue;
            throw UsageError{files[j].first + " '" + b + "' is the same file as " + files[i].first +
                             "; give different paths"};
        }
}

/// OpenVDB as Debian builds it (with log4cplus) prints its warnings, such
/// as "more than one grid named x" while reading, to std::cout: into a mesh
/// or JSON an app writes to standard output. After this call they go to
/// standard error. So apps write their results to standard output with
/// write_stdout() or through file descriptor 1, never with std::cout.
inline void start_openvdb() {
    openvdb::initialize();
    std::cout.rdbuf(std::cerr.rdbuf());
}

/// `text` to standard output (stdio, not std::cout: see start_openvdb),
/// flushed; io_error when it cannot be written (a full disk, a closed pipe).
inline void write_stdout(const std::string& text) {
    const std::size_t written = std::fwrite(text.data(), 1, text.size(), stdout);
    if (written != text.size() || std::fflush(stdout) != 0 || std::ferror(stdout))
        throw pqdc::io_error(std::string("cannot write to standard output: ") + std::strerror(errno));
}

/// v as JSON: the number (nlohmann prints the shortest round-trip digits),
/// or null when it is not finite. The one rule of every app's JSON.
inline nlohmann::ordered_json json_real(double v) {
    if (!std::isfinite(v)) return nullptr;
    return v;
}

/// Fails (io_error) before any work when a result could not be written at
/// all: missing or unwritable directory, a directory in the file's place.
inline void check_output_path(const std::string& option, const std::string& path) {
    if (path == "-") return;
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode))
        throw pqdc::io_error("cannot write '" + path + "' (" + option + "): it is a directory; give a file name");
    const std::size_t slash = path.find_last_of('/');
    const std::string dir = slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
    if (::stat(dir.c_str(), &st) != 0)
        throw pqdc::io_error("cannot write '" + path + "' (" + option + "): the directory '" + dir + "' " +
                             (errno == ENOENT ? "does not exist; create it first or choose another path"
                                              : std::string("cannot be accessed: ") + std::strerror(errno)));
    if (!S_ISDIR(st.st_mode))
        throw pqdc::io_error("cannot write '" + path + "' (" + option + "): '" + dir + "' is not a directory");
    if (::access(dir.c_str(), W_OK | X_OK) != 0)
        throw pqdc::io_error("cannot write '" + path + "' (" + option + "): cannot create files in '" + dir +
                             "' (" + std::strerror(errno) + "); choose a writable directory");
}

/// A decimation's figures (pqdc --decimate --stats, pqdc-decimate --stats):
/// the faces before and after (the written mesh's), the collapses and the
/// candidates refused by reason.
inline nlohmann::ordered_json decimation_json(const pqdc::DecimateStats& d) {
    return {{"input_triangles", d.input_faces},
            {"output_triangles", d.output_faces},
            {"output_vertices", d.output_vertices},
            {"collapses", d.collapses},
            {"passes", d.passes},
            {"locked_vertices", d.locked_vertices},
            {"dropped_faces", d.dropped_faces},
            {"voxel_size", json_real(d.voxel_size)},
            {"noise_voxels", json_real(d.noise_voxels)},
            {"sigma_position_voxels", json_real(d.sigma_position_voxels)},
            {"refused",
             {{"link", d.rejected_link},
              {"flip", d.rejected_flip},
              {"quality", d.rejected_quality},
              {"intersection", d.rejected_intersection},
              {"distance", d.rejected_distance}}}};
}

/// A number as messages show it: six significant digits, 1e-300 as 1e-300
/// (std::to_string prints 0.000000).
inline std::string number_text(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

/// A warning when decimation stopped above its face targets (every collapse
/// left was refused; e.g. a mesh cut by a region keeps its border fixed),
/// else empty. The targets as the options give them, named as the CLIs do.
inline std::string decimation_short_of_target(const pqdc::DecimateStats& s, const pqdc::DecimateOptions& o) {
    if (o.target_faces == 0 && o.target_ratio == 0) return {};
    // With several targets, decimation stops at the first one reached: the
    // larger face count.
    const double ratio_faces = o.target_ratio * double(s.input_faces);
    const double target = std::max(double(o.target_faces), ratio_faces);
    if (double(s.output_faces) <= target) return {};
    std::ostringstream w;
    w << "decimation stopped at " << s.output_faces << " triangles, above "
      << (double(o.target_faces) >= ratio_faces ? "--target-faces " + std::to_string(o.target_faces)
                                                : "--target-ratio " + number_text(o.target_ratio))
      << ": every further collapse was refused (" << s.locked_vertices
      << " border or non-manifold vertices stay fixed; refused: " << s.rejected_link << " link, " << s.rejected_flip
      << " flip, " << s.rejected_quality << " quality, " << s.rejected_intersection << " intersection, "
      << s.rejected_distance << " distance)";
    return w.str();
}

/// The JSON text every app writes: two-space indent, non-ASCII bytes kept,
/// invalid UTF-8 in file names replaced rather than thrown on.
inline std::string json_text(const nlohmann::ordered_json& j) {
    return j.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n";
}

/// Parses argv into `app`. Returns false when --help was printed. Throws
/// UsageError, in pqdc's words, for a value option at the end or followed by
/// another option ("-o needs a value"), unknown options, and CLI11's other
/// complaints. Numbers with a minus sign are values, not options.
inline bool parse_command_line(CLI::App& app, int argc, char** argv, const std::string& program) {
    const std::vector<std::string> args(argv + 1, argv + argc);
    auto is_option = [&](const std::string& a) {
        if (a.size() < 2 || a[0] != '-') return false;
        if (a[1] != '-' && (std::isdigit(static_cast<unsigned char>(a[1])) || a[1] == '.')) return false;
        return true;
    };
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        if (a == "--") break;
        if (!is_option(a)) continue;
        if (const std::size_t eq = a.find('='); eq != std::string::npos) {
            // "--sigma-n=" took the next argument as its value.
            const CLI::Option* opt = app.get_option_no_throw(a.substr(0, eq));
            if (opt && opt->get_items_expected_min() > 0 && eq + 1 == a.size())
                throw UsageError{a.substr(0, eq) + " needs a value after '='"};
            continue;
        }
        const CLI::Option* opt = app.get_option_no_throw(a);
        if (!opt || opt->get_items_expected_min() == 0) continue;  // unknown (reported below) or a flag
        if (i + 1 >= args.size()) throw UsageError{a + " needs a value"};
        const std::string& v = args[i + 1];
        // "-o --quads" is a forgotten value, not an output named "--quads".
        if (v.size() > 2 && v.compare(0, 2, "--") == 0)
            throw UsageError{a + " needs a value, got the option '" + v + "'"};
    }
    app.allow_extras();
    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp&) {
        std::cout << app.help();
        return false;
    } catch (const CLI::CallForVersion&) {
        std::cout << app.version() << "\n";
        return false;
    } catch (const CLI::ParseError& e) {
        throw UsageError{std::string(e.what()) + " (see " + program + " --help)"};
    }
    for (const std::string& extra : app.remaining()) {
        if (extra == "--") continue;  // the end of the options: what follows is positional
        if (is_option(extra)) throw UsageError{"unknown option '" + extra + "' (see " + program + " --help)"};
        throw UsageError{"unexpected argument '" + extra + "' (see " + program + " --help)"};
    }
    return true;
}

/// A value option as text, converted by the app (so messages stay pqdc's):
/// the last occurrence wins.
inline CLI::Option* add_text(CLI::App& app, const std::string& names, std::string& value,
                             const std::string& help, const std::string& group) {
    return app.add_option(names, value, help)
        ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast)
        ->group(group);
}

/// CLI11's help layout for pqdc's apps. Their descriptions carry their usage
/// lines, so CLI11's generic one ("Usage: NAME [OPTIONS] [inputs...]", which
/// suggests several inputs) is left out.
class HelpFormatter : public CLI::Formatter {
public:
    std::string make_usage(const CLI::App*, std::string) const override { return {}; }
};

inline void use_help_layout(CLI::App& app, std::size_t column_width) {
    auto formatter = std::make_shared<HelpFormatter>();
    formatter->column_width(column_width);
    formatter->label("TEXT", "VALUE");
    app.formatter(formatter);
}

/// One option of a small app: "-o,--output" style names, whether it takes a
/// value, its help line and its --help group.
struct OptionSpec {
    std::string names;
    bool takes_value;
    std::string help;
    std::string group = "Options";
};

/// CLI11 parsing for the small apps, which keep their own per-option
/// conversion: returns (long name, value) for every option given (a flag
/// given as --flag=false counts as not given), in the
/// order of first appearance, with the last value of a repeated option;
/// positional arguments go to `positional`. Empty with `done` set when
/// --help was printed.
inline std::vector<std::pair<std::string, std::string>> parse_options(
    int argc, char** argv, const std::string& program, const std::string& description,
    const std::vector<OptionSpec>& specs, const std::string& positional_help, std::vector<std::string>& positional,
    bool& done, const std::string& footer = "") {
    CLI::App app(description, program);
    if (!footer.empty()) app.footer(footer);
    use_help_layout(app, 34);
    std::vector<std::string> values(specs.size());
    std::deque<bool> flags(specs.size(), false);  // addressable, unlike vector<bool>
    std::vector<CLI::Option*> options;
    for (std::size_t i = 0; i < specs.size(); ++i) {
        CLI::Option* opt = specs[i].takes_value
                               ? app.add_option(specs[i].names, values[i], specs[i].help)
                                     ->multi_option_policy(CLI::MultiOptionPolicy::TakeLast)
                               : app.add_flag(specs[i].names, flags[i], specs[i].help);
        opt->group(specs[i].group);
        options.push_back(opt);
    }
    app.add_option("inputs", positional, positional_help);
    app.set_help_flag("-h,--help", "this text");
    done = !parse_command_line(app, argc, argv, program);
    std::vector<std::pair<std::string, std::string>> out;
    if (done) return out;
    std::vector<bool> seen(specs.size(), false);
    for (const CLI::Option* opt : app.parse_order())
        for (std::size_t i = 0; i < options.size(); ++i)
            if (options[i] == opt && !seen[i] && (specs[i].takes_value || flags[i])) {  // --flag=false: not given
                seen[i] = true;
                out.emplace_back("--" + opt->get_lnames().front(), specs[i].takes_value ? values[i] : std::string());
            }
    return out;
}

/// Whether parse_options() returned option `name` (its long name).
inline bool option_given(const std::vector<std::pair<std::string, std::string>>& given, const std::string& name) {
    for (const auto& option : given)
        if (option.first == name) return true;
    return false;
}

}  // namespace pqdc_cli
