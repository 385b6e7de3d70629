// pqdc-add-noise: adds seeded Gaussian noise to every active voxel of a scalar
// OpenVDB grid, for experiments such as the Figure 3 script (noisy input data
// where sigma_n > 0 should help). Prints a JSON summary on stdout.
// Exit codes: 0 ok, 1 runtime error, 2 usage error.
//
// The noise of a voxel is a function of (seed, voxel coordinate) only, so the
// output is the same bytes for any thread count and traversal order.

#include "pqdc/exceptions.hpp"
#include "pqdc/noise.hpp"
#include "pqdc/volume_io.hpp"

#include "cli_util.hpp"

#include <openvdb/openvdb.h>
#include <tbb/global_control.h>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace {

using pqdc_cli::UsageError;
using pqdc_cli::parse_finite;
using pqdc_cli::parse_unsigned;
using pqdc_cli::json_real;

const char* kUsage = R"(usage: pqdc-add-noise INPUT.vdb -o OUTPUT.vdb (--sigma-voxels S | --sigma-value S) [options]
       pqdc-add-noise INPUT.vdb --info

Adds Gaussian noise with standard deviation S to the value of every active
voxel of a float or double grid (active tiles are split into voxels first) and
writes the grid alone to OUTPUT.vdb, atomically (-o - writes it to standard
output). Prints a JSON summary on stdout, on stderr with -o - (grid, voxel
size, noise in world and voxel units, measured noise rms).
The noise depends only on the seed and each voxel's coordinate: the output is
identical for any thread count.)";
const std::vector<pqdc_cli::OptionSpec> kSpecs = {
    {"-o,--output", true, "the noisy .vdb (written atomically; may not be INPUT)"},
    {"--sigma-voxels", true, "std-dev in voxel sizes, S >= 0 (level sets only: their values are world distances, so S voxels = S * voxel size)", "Noise"},
    {"--sigma-value", true, "std-dev in the grid's value units, S >= 0 (any grid)", "Noise"},
    {"--seed", true, "noise seed, [0, 2^64) (default 1)", "Noise"},
    {"--grid", true, "the grid to use (default: the first scalar grid)"},
    {"--info", false, "print the JSON summary of INPUT's grid and exit"},
    {"--threads", true, "worker threads (default: all cores)", "Run"},
};


struct CliOptions {
    std::string input;
    std::string output;
    std::string grid;
    std::optional<double> sigma_voxels;
    std::optional<double> sigma_value;
    std::uint64_t seed = 1;
    bool info = false;
    int threads = 0;
};

CliOptions parse(int argc, char** argv, bool& done) {
    CliOptions o;
    done = false;
    std::vector<std::string> positional;
    const auto given = pqdc_cli::parse_options(argc, argv, "pqdc-add-noise", kUsage, kSpecs, "the input .vdb", positional, done);
    if (done) return o;
    for (const auto& [a, v] : given) {
        if (a == "--output") {
            o.output = v;
        } else if (a == "--sigma-voxels") {
            o.sigma_voxels = parse_finite(a, v);
            if (*o.sigma_voxels < 0) throw UsageError{"--sigma-voxels must be >= 0"};
        } else if (a == "--sigma-value") {
            o.sigma_value = parse_finite(a, v);
            if (*o.sigma_value < 0) throw UsageError{"--sigma-value must be >= 0"};
        } else if (a == "--seed") {
            o.seed = parse_unsigned(a, v);
        } else if (a == "--grid") {
            o.grid = v;
        } else if (a == "--info") {
            o.info = true;
        } else if (a == "--threads") {
            const double t = parse_finite(a, v);
            if (t < 1 || t > 4096 || t != std::floor(t)) throw UsageError{"--threads must be a whole number in [1, 4096]"};
            o.threads = int(t);
        }
    }
    if (positional.empty()) throw UsageError{"no input .vdb given (see pqdc-add-noise --help)"};
    if (positional.size() > 1)
        throw UsageError{"more than one input given: '" + positional[0] + "' and '" + positional[1] + "'"};
    o.input = positional[0];
    if (o.info) {
        if (!o.output.empty() || o.sigma_voxels || o.sigma_value)
            throw UsageError{"--info only prints the grid summary; drop -o/--sigma-*"};
        return o;
    }
    if (o.output.empty()) throw UsageError{"no output given; add -o OUTPUT.vdb"};
    pqdc_cli::check_distinct_files({{"the input", o.input}, {"-o", o.output}});
    if (o.sigma_voxels.has_value() == o.sigma_value.has_value())
        throw UsageError{"give exactly one of --sigma-voxels and --sigma-value"};
    return o;
}

const char* grid_class_name(openvdb::GridClass c) {
    switch (c) {
        case openvdb::GRID_LEVEL_SET: return "level set";
        case openvdb::GRID_FOG_VOLUME: return "fog volume";
        case openvdb::GRID_STAGGERED: return "staggered";
        default: return "unknown";
    }
}

int run(const CliOptions& o) {
    std::optional<tbb::global_control> threads;
    if (o.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, std::size_t(o.threads));

    const pqdc::LoadedGrid loaded = pqdc::read_scalar_grid(o.input, o.grid);
    openvdb::GridBase& grid = *loaded.grid;
    const openvdb::Vec3d voxel = grid.voxelSize();
    const bool uniform = grid.hasUniformVoxels();
    const bool level_set = grid.getGridClass() == openvdb::GRID_LEVEL_SET;

    nlohmann::ordered_json j = {{"input", o.input},
                                {"grid", grid.getName()},
                                {"value_type", grid.valueType()},
                                {"grid_class", grid_class_name(grid.getGridClass())},
                                {"voxel_size", uniform ? json_real(voxel[0]) : nullptr},
                                {"active_voxels", grid.activeVoxelCount()}};
    if (o.info) {
        pqdc_cli::write_stdout(pqdc_cli::json_text(j));
        return 0;
    }

    double sigma_world = 0;
    if (o.sigma_voxels) {
        if (!level_set) {
            throw pqdc::input_error("grid '" + grid.getName() + "' in '" + o.input + "' is a " +
                                    grid_class_name(grid.getGridClass()) +
                                    ", whose values are not distances; use --sigma-value (grid value units)");
        }
        if (!uniform) {
            throw pqdc::input_error("grid '" + grid.getName() + "' in '" + o.input +
                                    "' has non-uniform voxels, so a voxel size is ambiguous; use --sigma-value");
        }
        sigma_world = *o.sigma_voxels * voxel[0];
    } else {
        sigma_world = *o.sigma_value;
    }

    pqdc::NoiseSummary summary;
    if (auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(loaded.grid)) {
        // Draws reach about 6 sigma: beyond float's range they were stored as
        // infinities, with exit 0 (1e40 turned 97% of a sphere's voxels to inf).
        if (6.0 * sigma_world > double(std::numeric_limits<float>::max()))
            throw pqdc_cli::UsageError{(o.sigma_voxels ? "--sigma-voxels " + pqdc_cli::number_text(*o.sigma_voxels) +
                                                         " (" + pqdc_cli::number_text(sigma_world) + " in world units)"
                                                   : "--sigma-value " + pqdc_cli::number_text(sigma_world)) +
                                       " reaches beyond the range of the float values of grid '" + grid.getName() +
                                       "' (6 sigma above " + pqdc_cli::number_text(double(std::numeric_limits<float>::max())) +
                                       "); give a smaller value"};
        summary = pqdc::add_gaussian_noise(*f, sigma_world, o.seed);
    } else if (auto d = openvdb::GridBase::grid<openvdb::DoubleGrid>(loaded.grid)) {
        summary = pqdc::add_gaussian_noise(*d, sigma_world, o.seed);
    } else {
        throw pqdc::input_error("grid '" + grid.getName() + "' in '" + o.input + "' is " + grid.valueType() +
                                "; only float and double grids are supported");
    }
    pqdc::write_grid(grid, o.output);

    const double rms = summary.voxels ? std::sqrt(summary.sum_squares / double(summary.voxels)) : 0.0;
    j["output"] = o.output;
    j["seed"] = o.seed;
    j["noise_sigma_world"] = json_real(sigma_world);
    // Voxels only where values are distances (a level set).
    j["noise_sigma_voxels"] = uniform && level_set ? json_real(sigma_world / voxel[0]) : nullptr;
    j["noised_voxels"] = summary.voxels;
    j["noise_rms_world"] = json_real(rms);
    if (o.output == "-")  // the grid is on standard output: the summary must not follow it there
        std::fputs(pqdc_cli::json_text(j).c_str(), stderr);
    else
        pqdc_cli::write_stdout(pqdc_cli::json_text(j));
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    return pqdc_cli::run_app("pqdc-add-noise", argc, argv, parse, [](const CliOptions& o) {
        pqdc_cli::start_openvdb();
        return run(o);
    });
}
