// pqdc-bricks: writes a brick store (pqdc/brick_store.hpp) from a .vdb grid,
// streaming the file once: its leaf buffers are read brick by brick through
// delayed loading. pqdc meshes the store directory like the .vdb file, with
// the same output bytes. Exit codes: 0 ok, 1 runtime error, 2 usage error.
#include "pqdc/brick_store.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/volume_io.hpp"

#include "cli_util.hpp"

#include <openvdb/openvdb.h>

#include <iostream>
#include <string>
#include <vector>

namespace {

const char* kUsage = R"(usage: pqdc-bricks split INPUT.vdb -o DIR [--grid NAME] [--brick-size N]

Splits a float or double grid into a brick store: DIR/grid.vdb (the grid
without voxels), one DIR/brick-N.vdb per brick of the grid, and DIR/index.txt
(written last). Mesh it with `pqdc DIR -o mesh.ply`: the same bytes as
`pqdc INPUT.vdb -o mesh.ply`.)";
const std::vector<pqdc_cli::OptionSpec> kSpecs = {
    {"-o,--output", true, "the store directory (new or empty)"},
    {"--grid", true, "the grid to split (default: the first scalar grid)"},
    {"--brick-size", true, "voxels per brick file as a cube edge, a power of two from 128 to 4096 (default 256)"},
};

int run(int argc, char** argv) {
    bool done = false;
    std::vector<std::string> positional;
    const auto given =
        pqdc_cli::parse_options(argc, argv, "pqdc-bricks", kUsage, kSpecs, "split INPUT.vdb", positional, done);
    if (done) return 0;
    std::string output, grid;
    pqdc::BrickOptions bricks;
    for (const auto& [name, value] : given) {
        if (name == "-o" || name == "--output") output = value;
        else if (name == "--grid") grid = value;
        else if (name == "--brick-size") bricks.brick_size = pqdc_cli::parse_brick_size(value);
    }
    if (positional.size() != 2 || positional[0] != "split")
        throw pqdc_cli::UsageError{"expected: pqdc-bricks split INPUT.vdb -o DIR (see --help)"};
    if (output.empty()) throw pqdc_cli::UsageError{"give the store directory with -o DIR"};
    openvdb::initialize();
    const pqdc::LoadedGrid in = pqdc::read_scalar_grid(positional[1], grid, pqdc::VolumeLoading::delayed);
    const pqdc::BrickStoreSummary s = pqdc::write_brick_store(*in.grid, output, bricks);
    std::cerr << "pqdc-bricks: wrote grid '" << in.grid->getName() << "' of '" << positional[1] << "' as " << s.bricks
              << " bricks (" << s.leaves << " leaves) to '" << output << "'\n";
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        return run(argc, argv);
    } catch (...) {
        return pqdc_cli::report_current_exception("pqdc-bricks");
    }
}
