// What pqdc says about a finished mesh: the summary line, the --stats JSON
// and the reason a grid gave no surface.
#pragma once

#include "options.hpp"

#include "pqdc/adaptive.hpp"
#include "pqdc/decimate.hpp"
#include "pqdc/extract.hpp"

#include <openvdb/openvdb.h>

#include <optional>
#include <string>

namespace pqdc_app {

/// One mesh's figures: the uniform extractor's, or the adaptive one's mapped
/// onto them plus its own.
struct MeshReport {
    std::string source;  ///< "in.vdb:grid" or "procedural sphere at resolution 128"
    std::string grid;    ///< grid name, empty for procedural fields
    std::string output;  ///< the file written ("-" = standard output)
    pqdc::ExtractStats stats;
    std::optional<pqdc::AdaptiveStats> adaptive;
    std::optional<pqdc::DecimateStats> decimation;  ///< with --decimate: the written mesh is its output
    double read_seconds = -1;   ///< reading the volume (grids only; -1: not measured)
    double write_seconds = -1;  ///< writing the mesh file (-1: not measured)
};

/// "N active cells -> V vertices, T triangles and Q quads in S s, ...; wrote 'out'".
std::string summary_line(const CliOptions& o, const MeshReport& r);

/// The --stats document (see README): settings, counts, timings; non-finite numbers are null.
std::string stats_json(const CliOptions& o, const MeshReport& r);

}  // namespace pqdc_app
