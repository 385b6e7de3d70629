// Adaptive stage "bridges": faces that join two sheets across empty space.
//
// Step 4 of include/pqdc/adaptive.hpp counts every surface leaf as inside.
// Two surface leaves of different sheets that share a face are then two
// inside corners of a dual cell joined by a dual edge, and marching cubes
// joins the sheets across the gap between them: with leaves of s voxels,
// gaps up to about 2s wide. Two spheres 8 voxels apart became one surface
// at --max-error 1; a knot gained handles at 0.5 (an exploratory pass).
// Such a face has an edge whose middle lies well outside the surface,
// where the field says empty space; a face of one sheet has its edges'
// middles within about the merge error of it (term (d) holds them there).
// The driver pins the finest cells around both ends of every such edge and
// builds the octree again (as stage "untangle" does for intersections),
// until that pins nothing new: the leaves shrink until the gap separates
// them, down to the finest lattice, where only gaps under about a voxel
// close (the documented limit of the uniform extractor as well).
#pragma once

#include "adaptive/field_probe.hpp"
#include "adaptive/octree.hpp"
#include "adaptive/untangle.hpp"
#include "lattice/resources.hpp"
#include "pqdc/mesh.hpp"
#include "pqdc/stats.hpp"

#include <openvdb/openvdb.h>

#include <vector>

namespace pqdc::adaptive_detail {

/// The end points (index space) of the edges of `mesh` (index space) whose
/// middle lies outside the surface by more than bridge_limit_voxels: by the
/// first-order field distance (infinity where the field is flat, as in a
/// level set's clamped background), at most half the edge plus
/// max_error_voxels (how far the middle can be when the ends are within the
/// merge error of the surface). Each edge once, in a fixed order.
std::vector<openvdb::Vec3d> bridge_ends(const Mesh& mesh, const FieldSource& field, double max_error_voxels);

/// How far outside (voxels) an edge's middle must lie to be a bridge for
/// this merge bound: 1 voxel beyond max_error_voxels (noise and the sagitta
/// of a concave merged region stay within that), at most 2 voxels, so that a
/// level set's narrow band (3 voxels) still shows the gap. 0 (no merging)
/// gives infinity: nothing to refine.
double bridge_limit_voxels(double max_error_voxels);

/// The stage: while `mesh` (index space, built with `pinned`) has bridges,
/// pins the finest cells around their ends and builds it again with
/// `rebuild`, reporting in a shrinking tail of `span`. Returns the last mesh;
/// `pinned` keeps the cells (stage "untangle" starts from them, so its
/// rebuilds do not join the sheets again). stats.bridges_found counts the
/// first build's bridges; a rebuild's counters replace the build's, stages
/// carry over.
Mesh refine_bridges(Mesh mesh, const Rebuild& rebuild, const FieldSource& field, const Octree& frame,
                    double max_error_voxels, PinnedCells& pinned, const detail::ProgressSpan& span,
                    AdaptiveStats& stats);

}  // namespace pqdc::adaptive_detail
