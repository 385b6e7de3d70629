// Adaptive extraction (octree dual marching cubes): topology, feature and
// distance bounds, equivalence with the uniform extractor, determinism.
#include "pqdc/adaptive.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/measure.hpp"
#include "pqdc/mesh_to_volume.hpp"
#include "pqdc/noise.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/self_intersections.hpp"
#include "pqdc/volume_io.hpp"

#include "adaptive/angle_flips.hpp"
#include "adaptive/relax.hpp"
#include "l_prism.hpp"
#include "mesh_checks.hpp"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/SignedFloodFill.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

using openvdb::Vec3d;
using pqdc_test::box_corners;
using pqdc_test::require_watertight;

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

double voxel_size(const pqdc::ScalarField& f, const pqdc::ProceduralSampling& s) {
    return pqdc::procedural_transform(f, s)->voxelSize()[0];
}

openvdb::FloatGrid::Ptr fandisk() {
    const pqdc::LoadedGrid g = pqdc::read_scalar_grid(std::string(PQDC_SOURCE_DIR) + "/volumes/fandisk.vdb");
    return openvdb::gridPtrCast<openvdb::FloatGrid>(g.grid);
}

}  // namespace

TEST_CASE("adaptive options are validated", "[adaptive]") {
    const auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling s;
    s.resolution = 16;
    auto refuses = [&](auto&& edit) {
        pqdc::AdaptiveOptions o;
        edit(o);
        CHECK_THROWS_AS(pqdc::validate(o), pqdc::option_error);
        CHECK_THROWS_AS(pqdc::extract_adaptive(*field, s, o), pqdc::option_error);
    };
    refuses([](pqdc::AdaptiveOptions& o) { o.max_error_voxels = -0.1; });
    refuses([](pqdc::AdaptiveOptions& o) { o.max_error_voxels = std::nan(""); });
    refuses([](pqdc::AdaptiveOptions& o) { o.max_cell_size_voxels = 0; });
    refuses([](pqdc::AdaptiveOptions& o) { o.max_cell_size_voxels = 24; });
    refuses([](pqdc::AdaptiveOptions& o) { o.max_cell_size_voxels = 8192; });
    refuses([](pqdc::AdaptiveOptions& o) { o.base.sigma_n = -0.5; });  // -1 is sigma_n_auto
    refuses([](pqdc::AdaptiveOptions& o) { o.base.pseudo_inverse_cutoff = 1.0; });
    try {
        pqdc::AdaptiveOptions o;
        o.max_cell_size_voxels = 24;
        pqdc::validate(o);
    } catch (const pqdc::option_error& e) {
        CHECK(std::string(e.what()).find("max_cell_size") != std::string::npos);
    }
    pqdc::AdaptiveOptions ok;
    ok.max_error_voxels = std::numeric_limits<double>::infinity();
    ok.max_cell_size_voxels = 1;
    CHECK_NOTHROW(pqdc::validate(ok));
}

namespace {

/// A level set (band 3 voxels) of two separate solids: two slabs 90 x 90 x
/// 12 voxels with a gap of `gap` voxels between them, or two spheres of
/// radius 14 voxels `gap` voxels apart.
openvdb::FloatGrid::Ptr two_solids(bool slabs, double gap) {
    auto sdf = [&](const openvdb::Vec3d& p) {
        if (!slabs) {
            const double c = 14 + gap / 2;
            return std::min((p - openvdb::Vec3d(-c, 0, 0)).length(), (p - openvdb::Vec3d(c, 0, 0)).length()) - 14;
        }
        auto box = [&](double cz) {
            const openvdb::Vec3d q(std::abs(p.x()) - 45, std::abs(p.y()) - 45, std::abs(p.z() - cz) - 6);
            const openvdb::Vec3d out(std::max(q.x(), 0.0), std::max(q.y(), 0.0), std::max(q.z(), 0.0));
            return out.length() + std::min(std::max({q.x(), q.y(), q.z()}), 0.0);
        };
        return std::min(box(gap / 2 + 6), box(-gap / 2 - 6));
    };
    auto grid = openvdb::FloatGrid::create(3.0f);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    auto acc = grid->getAccessor();
    for (int i = -52; i <= 52; ++i)
        for (int j = -52; j <= 52; ++j)
            for (int k = -52; k <= 52; ++k) {
                const double d = sdf(openvdb::Vec3d(i, j, k) + openvdb::Vec3d(0.5));  // off the lattice: no zero values
                if (std::abs(d) < 3) acc.setValue(openvdb::Coord(i, j, k), float(d));
            }
    openvdb::tools::signedFloodFill(grid->tree());
    return grid;
}

}  // namespace

TEST_CASE("separate solids stay separate: no faces across a gap between large leaves", "[adaptive]") {
    // Surface leaves count as inside (adaptive.hpp, step 4): two of them on
    // either side of a gap joined the sheets with faces across it. Two flat
    // slabs 12 voxels apart were one surface at the default merge error,
    // two spheres 8 apart at 1 voxel (stage "bridges" refines them apart).
    for (const bool slabs : {true, false}) {
        for (const double gap : {6.0, 8.0, 12.0}) {
            const auto grid = two_solids(slabs, gap);
            const pqdc::TopologyReport uniform = pqdc::measure_topology(pqdc::extract(*grid, pqdc::ExtractOptions()));
            REQUIRE(uniform.connected_component_count == 2);
            for (const double e : {0.1, 0.5, 1.0}) {
                INFO((slabs ? "slabs" : "spheres") << " " << gap << " voxels apart, max_error " << e);
                pqdc::AdaptiveOptions o;
                o.max_error_voxels = e;
                pqdc::AdaptiveStats stats;
                const pqdc::Mesh mesh = pqdc::extract_adaptive(*grid, o, &stats);
                const pqdc::TopologyReport t = pqdc::measure_topology(mesh);
                CHECK(t.connected_component_count == 2);
                CHECK(t.euler_characteristic == 4);
                CHECK(t.closed());
                CHECK_FALSE(stats.untangle_fallback);
                CHECK(mesh.triangles.size() < 40000);  // still adaptive: refined only around the gap
            }
        }
    }
}

TEST_CASE("adaptive meshes of the test corpus are closed, manifold and outward", "[adaptive]") {
    pqdc::ProceduralSampling s;
    s.resolution = 40;
    for (const std::string name : {"sphere", "box", "figure3"}) {
        const auto field = pqdc::make_procedural(name);
        for (double e : {0.0, 0.1, 0.5})
            for (double sigma : {0.0, 0.1})
                for (pqdc::FaceType faces : {pqdc::FaceType::triangles, pqdc::FaceType::quads}) {
                    pqdc::AdaptiveOptions o;
                    o.max_error_voxels = e;
                    o.base.sigma_n = sigma;
                    o.base.faces = faces;
                    pqdc::AdaptiveStats st;
                    const pqdc::Mesh m = pqdc::extract_adaptive(*field, s, o, &st);
                    const auto t = require_watertight(
                        m, name + " max_error " + std::to_string(e) + " sigma_n " + std::to_string(sigma) +
                               (faces == pqdc::FaceType::quads ? " quads" : " triangles"));
                    CHECK(st.vertices == m.points.size());
                    CHECK(st.triangles + st.quads == m.face_count());
                    if (name != "figure3") {  // genus-0 single surfaces
                        CHECK(t.connected_component_count == 1);
                        CHECK(t.euler_characteristic == 2);
                    }
                    if (faces == pqdc::FaceType::quads) CHECK(!m.quads.empty());
                }
    }
}

TEST_CASE("adaptive mesh of a real model's level set is closed and much smaller", "[adaptive]") {
    const openvdb::FloatGrid::Ptr grid = fandisk();
    pqdc::ExtractOptions uo;
    const pqdc::Mesh uniform = pqdc::extract(*grid, uo);
    const auto tu = pqdc::measure_topology(uniform);
    for (double e : {0.1, 0.5}) {
        pqdc::AdaptiveOptions o;
        o.max_error_voxels = e;
        pqdc::AdaptiveStats st;
        const pqdc::Mesh m = pqdc::extract_adaptive(static_cast<const openvdb::GridBase&>(*grid), o, &st);
        const auto t = require_watertight(m, "fandisk max_error " + std::to_string(e));
        CHECK(t.connected_component_count == tu.connected_component_count);
        CHECK(t.euler_characteristic == tu.euler_characteristic);
        CHECK(st.merges > 0);
        // fandisk is mostly flat or gently curved: far fewer faces.
        CHECK(m.face_count() * 3 < uniform.face_count());
        // Vertices sit on sharp creases, where the trilinear SDF is rounded
        // and reads up to ~0.2 voxel: compare with the uniform mesh's reading.
        const double h = grid->voxelSize()[0];
        const pqdc::DistanceStats d = pqdc::measure_distance(m, *grid), du = pqdc::measure_distance(uniform, *grid);
        INFO("mean " << d.mean / h << " max " << d.max / h << " voxels; uniform mean " << du.mean / h << " max "
                     << du.max / h);
        CHECK(d.max <= du.max + e * h);
        CHECK(d.mean <= du.mean + e * h);
    }
}

TEST_CASE("sharp grid normals bring a sampled box's corners closer in adaptive mode too", "[adaptive]") {
    pqdc::BoxParams p;
    const auto field = pqdc::make_rotated_box(p);
    const auto corners = box_corners(p);
    pqdc::ProceduralSampling s;
    s.resolution = 64;
    const double h = voxel_size(*field, s);
    const openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*field, s);
    // Distance from each corner to the nearest vertex, in voxels, sorted.
    auto corner_distances = [&](pqdc::GridNormals normals) {
        pqdc::AdaptiveOptions o;
        o.base.sigma_n = 0.0;
        o.base.normals = normals;
        o.max_error_voxels = 0.1;
        const pqdc::Mesh m = pqdc::extract_adaptive(*grid, o);
        require_watertight(m, normals == pqdc::GridNormals::sharp ? "sharp" : "central");
        std::vector<double> d;
        for (const auto& c : corners) {
            double best = std::numeric_limits<double>::max();
            for (const auto& v : m.points) best = std::min(best, (v - c).length());
            d.push_back(best / h);
        }
        std::sort(d.begin(), d.end());
        return d;
    };
    // Measured: central 0.01-0.42 (median 0.38), sharp 0.04-0.29 (median 0.08).
    const std::vector<double> central = corner_distances(pqdc::GridNormals::central),
                              sharp = corner_distances(pqdc::GridNormals::sharp);
    INFO("median corner distance, voxels: central " << central[4] << ", sharp " << sharp[4]);
    CHECK(sharp[4] < 0.5 * central[4]);
    CHECK(sharp.back() < central.back());
}

TEST_CASE("rotated box keeps its corners and edges while merging flat faces", "[adaptive]") {
    pqdc::BoxParams p;
    const auto field = pqdc::make_rotated_box(p);
    const auto corners = box_corners(p);
    for (const auto& c : corners) REQUIRE(std::abs(field->value(c)) < 1e-12);
    pqdc::ProceduralSampling s;
    s.resolution = 64;
    const double h = voxel_size(*field, s);

    pqdc::ExtractOptions uo;
    const pqdc::Mesh uniform = pqdc::extract(*field, s, uo);
    for (double sigma : {0.0, 0.1}) {
        pqdc::AdaptiveOptions o;
        o.base.sigma_n = sigma;
        o.max_error_voxels = 0.1;
        pqdc::AdaptiveStats st;
        const pqdc::Mesh m = pqdc::extract_adaptive(*field, s, o, &st);
        INFO("sigma_n " << sigma << ": " << m.face_count() << " faces, uniform " << uniform.face_count());
        require_watertight(m, "box");
        CHECK(m.face_count() * 5 < uniform.face_count());
        std::uint64_t coarse = 0;
        for (int l = 3; l < 13; ++l) coarse += st.leaves_per_level[l];
        CHECK(coarse > 0);  // cells of 8 voxels and more on the faces

        // Corners: a mesh vertex on each.
        for (const auto& c : corners) {
            double best = std::numeric_limits<double>::max();
            for (const auto& v : m.points) best = std::min(best, (v - c).length());
            CHECK(best < 0.05 * h);
        }
        // Edges: points of every edge lie on the mesh surface, except where
        // the wedge between the two faces is thinner than the lattice (a cell
        // with no crossing of one face cannot put its vertex on the edge, as
        // in uniform dual contouring): 97% within 0.05 voxel, all within 0.25.
        const pqdc::MeshDistance dist(m);
        double worst = 0;
        int samples = 0, traced = 0;
        std::string worst_where;
        for (int a = 0; a < 8; ++a)
            for (int b = a + 1; b < 8; ++b) {
                const int diff = a ^ b;
                if (diff != 1 && diff != 2 && diff != 4) continue;
                // Within two voxels of a corner the one-vertex-per-cell
                // surface chamfers the edge (as uniform dual contouring does);
                // the corner itself is checked above.
                const Vec3d A = corners[a], B = corners[b], d = (B - A).unitSafe();
                const double len = (B - A).length();
                for (double t = 2 * h; t <= len - 2 * h; t += 0.25 * h) {
                    const double dd = dist(A + d * t);
                    if (dd > worst) worst_where = std::to_string(a) + "-" + std::to_string(b) + " at " + std::to_string(t / h) + " voxels";
                    worst = std::max(worst, dd);
                    traced += dd < 0.05 * h;
                    ++samples;
                }
            }
        INFO("worst edge point distance " << worst / h << " voxel over " << samples << " samples, " << worst_where);
        CHECK(samples > 1000);
        CHECK(traced >= 0.97 * samples);
        CHECK(worst < 0.25 * h);
    }
}

TEST_CASE("adaptive faces grow with the box's edge length, uniform faces with its area", "[adaptive]") {
    // The sharp edges keep fine cells (a one-dimensional set) while the flat
    // faces merge into large cells, so doubling the resolution about doubles
    // the adaptive faces and quadruples the uniform ones: the saving grows
    // linearly with resolution (about 90x at 1024 cells, measured in the README).
    const auto field = pqdc::make_procedural("box");
    pqdc::ProceduralSampling s;
    pqdc::AdaptiveOptions o;
    o.max_error_voxels = 0.1;
    double previous_adaptive = 0, previous_uniform = 0;
    for (int resolution : {64, 128, 256}) {
        s.resolution = resolution;
        const double adaptive = double(pqdc::extract_adaptive(*field, s, o).face_count());
        const double uniform = double(pqdc::extract(*field, s, o.base).face_count());
        INFO("resolution " << resolution << ": adaptive " << adaptive << " faces, uniform " << uniform);
        if (previous_adaptive > 0) {
            CHECK(uniform / previous_uniform > 3.5);
            CHECK(adaptive / previous_adaptive < 2.5);
        }
        if (resolution == 256) CHECK(uniform / adaptive > 20);
        previous_adaptive = adaptive;
        previous_uniform = uniform;
    }
}

TEST_CASE("vertices stay within max_error of the analytic surfaces", "[adaptive]") {
    pqdc::ProceduralSampling s;
    s.resolution = 64;
    for (const std::string name : {"sphere", "box"}) {  // exact signed distance fields
        const auto field = pqdc::make_procedural(name);
        const double h = voxel_size(*field, s);
        std::size_t previous_faces = std::numeric_limits<std::size_t>::max();
        for (double e : {0.1, 0.25, 0.5, 1.0}) {
            pqdc::AdaptiveOptions o;
            o.max_error_voxels = e;
            const pqdc::Mesh m = pqdc::extract_adaptive(*field, s, o);
            double worst = 0;
            for (const auto& v : m.points) worst = std::max(worst, std::abs(field->value(v)) / h);
            INFO(name << " max_error " << e << ": worst vertex " << worst << " voxel, " << m.face_count() << " faces");
            CHECK(worst <= e);
            CHECK(m.face_count() <= previous_faces);  // a looser bound never costs faces here
            previous_faces = m.face_count();
        }
    }
}

TEST_CASE("max_error 0 reproduces the uniform extractor's surface", "[adaptive]") {
    pqdc::ProceduralSampling s;
    s.resolution = 40;
    for (const std::string name : {"sphere", "box", "figure3"}) {
        const auto field = pqdc::make_procedural(name);
        const double h = voxel_size(*field, s);
        pqdc::ExtractOptions uo;
        const pqdc::Mesh uniform = pqdc::extract(*field, s, uo);
        pqdc::AdaptiveOptions o;
        o.max_error_voxels = 0;
        pqdc::AdaptiveStats st;
        const pqdc::Mesh m = pqdc::extract_adaptive(*field, s, o, &st);
        INFO(name);
        CHECK(st.merges == 0);
        const auto ta = pqdc::measure_topology(m), tu = pqdc::measure_topology(uniform);
        if (name != "figure3") {
            CHECK(ta.connected_component_count == tu.connected_component_count);
            CHECK(ta.euler_characteristic == tu.euler_characteristic);
        } else {
            // Surface leaves count as inside, so islands within about a voxel
            // of the main surface fuse with it and sub-voxel cavities close:
            // never more components than the uniform mesh.
            CHECK(ta.connected_component_count <= tu.connected_component_count);
        }
        // The adaptive vertices are cells' minimizers, as the uniform ones...
        const pqdc::MeshDistance to_uniform(uniform), to_adaptive(m);
        std::vector<double> a_to_u, u_to_a;
        for (const auto& v : m.points) a_to_u.push_back(to_uniform(v) / h);
        for (const auto& v : uniform.points) u_to_a.push_back(to_adaptive(v) / h);
        std::sort(a_to_u.begin(), a_to_u.end());
        std::sort(u_to_a.begin(), u_to_a.end());
        auto pct = [](const std::vector<double>& v, double q) { return v[std::size_t(q * double(v.size() - 1))]; };
        INFO("adaptive->uniform p90 " << pct(a_to_u, 0.9) << " p99 " << pct(a_to_u, 0.99) << " max " << a_to_u.back() << "; uniform->adaptive p80 " << pct(u_to_a, 0.8) << " p90 " << pct(u_to_a, 0.9) << " p95 "
                                      << pct(u_to_a, 0.95) << " max " << u_to_a.back() << " voxel");
        if (name != "figure3") {
            CHECK(pct(a_to_u, 0.99) < 0.01);
            // ...and the two surfaces are one.
            CHECK(pct(u_to_a, 0.95) < 0.1);
            CHECK(u_to_a.back() < 0.35);
        } else {
            // Voxel-scale noise: only cells bordering the outside get a
            // vertex, so pits and gaps narrower than about a voxel are
            // bridged (see adaptive.hpp); most of the surface still agrees.
            CHECK(pct(a_to_u, 0.9) < 0.01);
            CHECK(pct(u_to_a, 0.5) < 0.25);
        }
    }
}

TEST_CASE("coarse cells: merging crosses OpenVDB leaves and respects max_cell_size", "[adaptive]") {
    const auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling s;
    s.resolution = 96;
    pqdc::AdaptiveOptions o;
    o.max_error_voxels = 1.0;
    pqdc::AdaptiveStats wide;
    pqdc::extract_adaptive(*field, s, o, &wide);
    CHECK(wide.leaves_per_level[4] + wide.leaves_per_level[5] + wide.leaves_per_level[6] > 0);  // >= 16 voxels
    o.max_cell_size_voxels = 4;
    pqdc::AdaptiveStats narrow;
    const pqdc::Mesh m = pqdc::extract_adaptive(*field, s, o, &narrow);
    require_watertight(m, "max_cell_size 4");
    for (int l = 3; l < 13; ++l) CHECK(narrow.leaves_per_level[l] == 0);
    CHECK(narrow.leaves_per_level[2] > 0);
    CHECK(narrow.surface_leaves > wide.surface_leaves);
}

TEST_CASE("adaptive output is identical for any number of threads", "[adaptive]") {
    const auto field = pqdc::make_procedural("figure3");
    pqdc::ProceduralSampling s;
    s.resolution = 48;
    pqdc::AdaptiveOptions o;
    o.max_error_voxels = 0.2;
    // 8-voxel roots: hundreds of them, so the per-root collapses (one parity
    // class at a time) really run side by side.
    for (int max_cell : {64, 8}) {
        o.max_cell_size_voxels = max_cell;
        pqdc::Mesh one, many;
        pqdc::AdaptiveStats stats;
        {
            tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
            one = pqdc::extract_adaptive(*field, s, o);
        }
        {
            tbb::global_control c(tbb::global_control::max_allowed_parallelism, 4);
            many = pqdc::extract_adaptive(*field, s, o, &stats);
        }
        INFO("max cell " << max_cell << ": " << stats.collapsed_vertices << " collapses");
        CHECK(stats.collapsed_vertices > 1000);
        // The untangle stage's rebuilds and moves ran too (216 pairs found here).
        CHECK(stats.untangle_pinned_cells > 0);
        CHECK(stats.untangle_moved > 0);
        REQUIRE(one.points.size() == many.points.size());
        CHECK(one.points == many.points);
        CHECK(one.triangles == many.triangles);
    }
}

TEST_CASE("adaptive statistics count the lattice as the uniform extractor does", "[adaptive]") {
    // Each crossing edge once, though the 8^3 blocks of stage "hermite" both
    // compute the edges on their common faces; the NaN voxels too.
    auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(20.0f, openvdb::Vec3f(3, 2, 1), 1.0f);
    auto acc = grid->getAccessor();
    for (int y = -3; y <= 3; ++y)
        for (int z = -2; z <= 4; ++z) acc.setValue(openvdb::Coord(23, y, z), NAN);
    pqdc::ExtractStats u;
    pqdc::extract(*grid, pqdc::ExtractOptions{}, &u);
    pqdc::AdaptiveStats a;
    pqdc::extract_adaptive(*grid, pqdc::AdaptiveOptions{}, &a);
    REQUIRE(u.non_finite_values > 0);
    CHECK(a.non_finite_values == u.non_finite_values);
    CHECK(a.crossing_edges == u.crossing_edges);
    CHECK(a.active_cells == u.active_cells);
    CHECK(a.degenerate_normals == u.degenerate_normals);
}

TEST_CASE("adaptive grids: float and double, world transform, unsupported input", "[adaptive]") {
    const float radius = 20.0f, voxel = 0.05f;
    const openvdb::FloatGrid::Ptr f =
        openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(radius * voxel, Vec3d(3.0, -2.0, 1.0), voxel, 3.0f);
    pqdc::AdaptiveOptions o;
    o.max_error_voxels = 0.25;
    const pqdc::Mesh mf = pqdc::extract_adaptive(*f, o);
    require_watertight(mf, "float sphere");
    for (const auto& v : mf.points) CHECK(std::abs((v - Vec3d(3.0, -2.0, 1.0)).length() - radius * voxel) < 0.35 * voxel);

    const openvdb::DoubleGrid::Ptr d =
        openvdb::tools::createLevelSetSphere<openvdb::DoubleGrid>(radius * voxel, Vec3d(3.0, -2.0, 1.0), voxel, 3.0);
    const pqdc::Mesh md = pqdc::extract_adaptive(static_cast<const openvdb::GridBase&>(*d), o);
    require_watertight(md, "double sphere");
    CHECK(md.face_count() > mf.face_count() / 2);
    CHECK(md.face_count() < mf.face_count() * 2);

    openvdb::Int32Grid::Ptr ints = openvdb::Int32Grid::create(0);
    ints->setName("labels");
    ints->tree().setValue(openvdb::Coord(0), 1);
    try {
        pqdc::extract_adaptive(static_cast<const openvdb::GridBase&>(*ints), o);
        FAIL("no exception");
    } catch (const pqdc::input_error& e) {
        CHECK(std::string(e.what()).find("labels") != std::string::npos);
    }

    // Affine maps are meshed (test_affine.cpp); frustums are refused.
    openvdb::FloatGrid::Ptr camera = f->deepCopy();
    camera->setTransform(openvdb::math::Transform::createFrustumTransform(
        openvdb::BBoxd(Vec3d(-10.0), Vec3d(10.0)), 0.5, 2.0, 1.0));
    CHECK_THROWS_AS(pqdc::extract_adaptive(*camera, o), pqdc::input_error);

    const pqdc::Mesh empty = pqdc::extract_adaptive(*openvdb::FloatGrid::create(1.0f), o);
    CHECK(empty.empty());
}

TEST_CASE("adaptive extraction reports progress and can be cancelled", "[adaptive]") {
    const auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling s;
    s.resolution = 24;
    pqdc::AdaptiveOptions o;
    std::vector<double> seen;
    o.base.progress = [&](double f) {
        seen.push_back(f);
        return true;
    };
    pqdc::extract_adaptive(*field, s, o);
    REQUIRE(seen.size() >= 2);
    CHECK(seen.front() == 0.0);
    CHECK(seen.back() == 1.0);
    CHECK(std::is_sorted(seen.begin(), seen.end()));
    o.base.progress = [](double f) { return f < 0.5; };
    CHECK_THROWS_AS(pqdc::extract_adaptive(*field, s, o), pqdc::cancelled_error);
    o.base.progress = nullptr;
    o.base.memory_limit_bytes = 1024;
    CHECK_THROWS_AS(pqdc::extract_adaptive(*field, s, o), pqdc::resource_error);
}

TEST_CASE("adaptive progress comes inside every stage and leaves the mesh unchanged", "[adaptive]") {
    // Fine enough for several report chunks per stage (a Ctrl-C in Python is
    // answered at the next report).
    const auto field = pqdc::make_procedural("figure3");
    pqdc::ProceduralSampling s;
    s.resolution = 160;
    pqdc::AdaptiveOptions o;
    o.max_error_voxels = 0.02;
    const pqdc::Mesh plain = pqdc::extract_adaptive(*field, s, o);
    std::vector<double> seen;
    o.base.progress = [&](double f) {
        seen.push_back(f);
        return true;
    };
    const pqdc::Mesh reported = pqdc::extract_adaptive(*field, s, o);
    CHECK(reported.points == plain.points);
    CHECK(reported.triangles == plain.triangles);
    REQUIRE(std::is_sorted(seen.begin(), seen.end()));
    // Reports strictly inside each stage's share (extract_adaptive.cpp):
    // hermite (0.1, 0.2875), octree (0.2875, 0.4), dual grid (0.4, 0.5125),
    // polygons (0.5125, 0.85), untangle's check (0.85, 0.95). The octree
    // stage merges only the levels above 8-voxel cells (stage "hermite"
    // merges the lower ones brick by brick): one report after each of its
    // three levels, two of them inside.
    for (const auto& [lo, hi] : {std::pair{0.1, 0.2875}, {0.2875, 0.4}, {0.4, 0.5125}, {0.5125, 0.85}, {0.85, 0.95}}) {
        const auto inside = std::count_if(seen.begin(), seen.end(), [&](double f) { return f > lo && f < hi; });
        INFO("stage (" << lo << ", " << hi << ")");
        CHECK(inside >= (lo == 0.2875 ? 2 : 3));
        // Cancelling there stops the extraction there.
        double last = 0;
        o.base.progress = [&, stop = lo + 0.5 * (hi - lo)](double f) {
            last = f;
            return f < stop;
        };
        CHECK_THROWS_AS(pqdc::extract_adaptive(*field, s, o), pqdc::cancelled_error);
        CHECK(last <= hi);
    }
}

TEST_CASE("adaptive angle flips: slivers of a flat pair flip, creases, frozen pairs and existing edges do not",
          "[adaptive]") {
    namespace ad = pqdc::adaptive_detail;
    // A flat rhombus, long diagonal a-b (0-1): two slivers, whose flip gives
    // two fat triangles along the short diagonal c-d.
    std::vector<Vec3d> points{{0, 0, 0}, {4, 0, 0}, {2, 0.5, 0}, {2, -0.5, 0}};
    const std::vector<openvdb::Vec3I> rhombus{{0, 1, 2}, {1, 0, 3}};
    auto run = [&](std::vector<openvdb::Vec3I> tris, std::vector<std::uint8_t> frozen) {
        std::vector<std::uint8_t> alive(tris.size(), 1), changed(tris.size(), 0);
        const std::size_t flips = ad::flip_for_angles(points, tris, alive, frozen, changed, nullptr);
        return std::make_pair(flips, tris);
    };
    {
        const auto [flips, tris] = run(rhombus, {0, 0});
        REQUIRE(flips == 1);
        for (const auto& t : tris) {  // the new edge is 2-3 and both faces keep the upward normal
            const bool has2 = t[0] == 2 || t[1] == 2 || t[2] == 2, has3 = t[0] == 3 || t[1] == 3 || t[2] == 3;
            CHECK((has2 && has3));
            const Vec3d n = (points[t[1]] - points[t[0]]).cross(points[t[2]] - points[t[0]]);
            CHECK(n.z() > 0);
        }
    }
    CHECK(run(rhombus, {1, 0}).first == 0);  // a frozen (quad) half stays
    // Folded along a-b by 90 degrees: a crease, kept.
    points[3] = {2, 0, -0.5};
    CHECK(run(rhombus, {0, 0}).first == 0);
    points[3] = {2, -0.5, 0};
    // A closed fan where c-d already exists (an octahedron's worth of faces
    // around the pair): flipping would duplicate that edge.
    points.push_back({2, 0, 3});  // 4: above, joined to c and d
    const std::vector<openvdb::Vec3I> with_edge{{0, 1, 2}, {1, 0, 3}, {2, 3, 4}};
    const auto [flips, tris] = run(with_edge, {0, 0, 0});
    CHECK(flips == 0);
    CHECK(tris == with_edge);
}

namespace {

/// A signed field given by a function, as the polygons stage probes it.
template <class F>
struct FunctionProbe final : pqdc::adaptive_detail::FieldProbe {
    explicit FunctionProbe(F f) : f(f) {}
    double value(const Vec3d& p) override { return f(p); }
    F f;
};

}  // namespace

TEST_CASE("adaptive angle flips unfold a flap facing inward, not a crease", "[adaptive]") {
    namespace ad = pqdc::adaptive_detail;
    auto flips = [](const std::vector<Vec3d>& points, std::vector<openvdb::Vec3I>& tris, ad::FieldProbe* field) {
        std::vector<std::uint8_t> alive(tris.size(), 1), frozen(tris.size(), 0), changed(tris.size(), 0);
        return ad::flip_for_angles(points, tris, alive, frozen, changed, field);
    };
    // Four coplanar points; a-b (0-1) runs outside the quadrilateral b c a d,
    // so (a, b, c) faces up and lies over (b, a, d), which faces down as the
    // field's gradient does (outside below z = 0): the flaps dual cells of
    // different sizes left on spheres.
    const std::vector<Vec3d> flap{{0, 0, 0}, {4, 0, 0}, {2, 0.5, 0}, {2, 1.5, 0}};
    FunctionProbe below([](const Vec3d& p) { return -p.z(); });
    std::vector<openvdb::Vec3I> tris{{0, 1, 2}, {1, 0, 3}};
    REQUIRE(flips(flap, tris, &below) == 1);
    for (const auto& t : tris) {  // the new edge is c-d, both faces down
        CHECK(std::count(t.asPointer(), t.asPointer() + 3, 2u) == 1);
        CHECK(std::count(t.asPointer(), t.asPointer() + 3, 3u) == 1);
        const Vec3d n = (flap[t[1]] - flap[t[0]]).cross(flap[t[2]] - flap[t[0]]);
        CHECK(n.z() < 0);
    }
    tris = {{0, 1, 2}, {1, 0, 3}};
    CHECK(flips(flap, tris, nullptr) == 0);  // without the field, no unfolding
    // A 90-degree crease along a-b, c on its top face, d on its side: the
    // flipped pair would be flat (a chamfer) but both faces face outward.
    const std::vector<Vec3d> crease{{0, 0, 0}, {4, 0, 0}, {2, 0.5, 0}, {2, 0, -0.5}};
    FunctionProbe wedge([](const Vec3d& p) { return std::max(p.z(), -p.y()); });
    tris = {{0, 1, 2}, {1, 0, 3}};
    CHECK(flips(crease, tris, &wedge) == 0);
    // A knife edge (c and d on its flanks, 6 degrees apart): the flipped
    // pair would cut through the wedge, folding as much; kept.
    const std::vector<Vec3d> knife{{0, 0, 0}, {4, 0, 0}, {2, -10, 0.5}, {2, -10, -0.5}};
    FunctionProbe blade([](const Vec3d& p) { return std::max(std::abs(p.z()) - 0.05 * -p.y(), p.y()); });
    tris = {{0, 1, 2}, {1, 0, 3}};
    CHECK(flips(knife, tris, &blade) == 0);
}

TEST_CASE("adaptive faces of a sphere face outward: no flaps where cells of different sizes meet", "[adaptive]") {
    // Before angle flips unfolded pairs, 2-4% of these triangles were flaps
    // facing inward (face normals up to 134 degrees off) with fine vertex normals.
    const auto field = pqdc::make_procedural("sphere");
    for (int resolution : {24, 48, 96}) {
        pqdc::ProceduralSampling s;
        s.resolution = resolution;
        const pqdc::Mesh m = pqdc::extract_adaptive(*field, s, pqdc::AdaptiveOptions{});
        const pqdc::NormalDeviation d = pqdc::measure_normal_deviation(m, *field);
        INFO("resolution " << resolution);
        CHECK(d.skipped_count == 0);
        CHECK(d.max_degrees < 15);
        CHECK(pqdc::measure_triangle_quality(m).min_angle_min_degrees > 10);
    }
}

namespace {

/// A grid of n x n points over [0, n-1]^2 at height z = fold(x, y), two
/// triangles per square; interior points moved by `jitter(i, j)` in x and y
/// before the height is taken, so they stay on the surface.
struct FoldedGrid {
    std::vector<Vec3d> points;
    std::vector<openvdb::Vec3I> tris;
    std::vector<std::uint8_t> interior;
};

template <class Fold, class Jitter>
FoldedGrid folded_grid(int n, const Fold& fold, const Jitter& jitter) {
    FoldedGrid g;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            const bool inner = i > 0 && j > 0 && i < n - 1 && j < n - 1;
            const std::pair<double, double> d = inner ? jitter(i, j) : std::make_pair(0.0, 0.0);
            const double x = i + d.first, y = j + d.second;
            g.points.emplace_back(x, y, fold(x, y));
            g.interior.push_back(inner);
        }
    auto id = [n](int i, int j) { return i * n + j; };
    for (int i = 0; i + 1 < n; ++i)
        for (int j = 0; j + 1 < n; ++j) {
            g.tris.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1));
            g.tris.emplace_back(id(i, j), id(i + 1, j + 1), id(i, j + 1));
        }
    return g;
}

double smallest_angle(const std::vector<Vec3d>& p, const std::vector<openvdb::Vec3I>& tris) {
    double worst = 180;
    for (const auto& t : tris)
        for (int k = 0; k < 3; ++k) {
            const Vec3d u = p[t[(k + 1) % 3]] - p[t[k]], v = p[t[(k + 2) % 3]] - p[t[k]];
            worst = std::min(worst, std::acos(u.dot(v) / (u.length() * v.length())) * 180 / M_PI);
        }
    return worst;
}

}  // namespace

TEST_CASE("adaptive relaxation: vertices slide within flat parts and along creases, others stay", "[adaptive]") {
    namespace ad = pqdc::adaptive_detail;
    auto jitter = [](int i, int j) { return std::make_pair(0.3 * std::sin(3.0 * i + j), 0.3 * std::cos(i - 2.0 * j)); };
    {
        // Flat: interior points stay in the plane and the triangles fatten;
        // the border (boundary edges) stays.
        FoldedGrid g = folded_grid(6, [](double, double) { return 0.0; }, jitter);
        const std::vector<Vec3d> before = g.points;
        const std::vector<std::uint8_t> alive(g.tris.size(), 1), all(g.points.size(), 1);
        const std::size_t moved = ad::relax_tangentially(g.points, g.tris, alive, all);
        CHECK(moved > 0);
        for (std::size_t v = 0; v < g.points.size(); ++v) {
            CHECK(g.points[v].z() == 0.0);
            if (!g.interior[v]) CHECK(g.points[v] == before[v]);
        }
        CHECK(smallest_angle(g.points, g.tris) > smallest_angle(before, g.tris) + 3);
        // Vertices not movable stay; the rest do not depend on the threads.
        std::vector<Vec3d> fixed = before;
        const std::vector<std::uint8_t> none(g.points.size(), 0);
        CHECK(ad::relax_tangentially(fixed, g.tris, alive, none) == 0);
        CHECK(fixed == before);
        std::vector<Vec3d> one_thread = before;
        tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
        ad::relax_tangentially(one_thread, g.tris, alive, all);
        CHECK(one_thread == g.points);
    }
    {
        // A 90-degree roof along the row j = 3 (y = 3): crease points slide
        // along it only, the others stay on their face's plane.
        auto roof = [](double, double y) { return -std::abs(y - 3.0); };
        auto along = [](int i, int j) {
            return j == 3 ? std::make_pair(0.35 * std::sin(2.0 * i), 0.0)
                          : std::make_pair(0.3 * std::sin(3.0 * i + j), 0.3 * std::cos(i - 2.0 * j) * (j < 3 ? 1 : -1) *
                                                                          (std::abs(j - 3) > 1 ? 1 : 0.5));
        };
        FoldedGrid g = folded_grid(7, roof, along);
        const std::vector<Vec3d> before = g.points;
        const std::vector<std::uint8_t> alive(g.tris.size(), 1), all(g.points.size(), 1);
        ad::relax_tangentially(g.points, g.tris, alive, all);
        bool crease_slid = false;
        for (std::size_t v = 0; v < g.points.size(); ++v) {
            const Vec3d& p = g.points[v];
            if (before[v].y() == 3.0) {
                CHECK(std::abs(p.y() - 3.0) < 1e-12);
                CHECK(std::abs(p.z()) < 1e-12);
                crease_slid = crease_slid || std::abs(p.x() - before[v].x()) > 1e-3;
            } else {
                CHECK((before[v].y() < 3.0) == (p.y() < 3.0));
                CHECK(std::abs(p.z() - roof(p.x(), p.y())) < 1e-12);
            }
        }
        CHECK(crease_slid);
    }
}

TEST_CASE("adaptive output on a noisy sphere: relaxation and angle flips lift the thinnest triangles", "[adaptive]") {
    const auto field = pqdc::make_procedural("sphere");
    pqdc::ProceduralSampling s;
    s.resolution = 96;
    openvdb::FloatGrid::Ptr grid = pqdc::sample_field(*field, s);
    pqdc::add_gaussian_noise(*grid, 0.3 * grid->voxelSize()[0], 1);
    pqdc::AdaptiveOptions o;
    pqdc::AdaptiveStats st;
    const pqdc::Mesh mesh = pqdc::extract_adaptive(*grid, o, &st);
    require_watertight(mesh, "noisy sphere, adaptive");
    CHECK(st.angle_flips > 100);
    CHECK(st.relaxed_vertices > 100);
    // Without either step this mesh's 5th-percentile smallest angle is about
    // 15 degrees (bench_quality at 128 cells: 14.9), with flips alone about
    // 19, with relaxation before the flips 26.2.
    CHECK(pqdc::measure_triangle_quality(mesh).min_angle_p05_degrees > 23);
}

namespace {
openvdb::math::Mat3d rotation_about_123(double degrees) {
    return openvdb::math::rotation<openvdb::math::Mat3d>(openvdb::Vec3d(1, 2, 3).unit(), degrees * M_PI / 180);
}
}  // namespace

TEST_CASE("an outside leaf walled in at a concave crease is filled instead of meshed as a bubble", "[adaptive]") {
    // Found by sweeping rotations and voxel sizes of the L-prism's exact
    // level set: here merged surface leaves (which count as inside) wall in
    // one empty leaf at the concave crease. Meshed, it was a closed,
    // inside-out octahedron beside the surface.
    pqdc::MeshToLevelSetOptions o;
    o.voxel_size = 0.031;
    const auto grid = pqdc::mesh_to_level_set(pqdc_test::l_prism(rotation_about_123(40)), o);
    pqdc::AdaptiveStats stats;
    const pqdc::Mesh m = pqdc::extract_adaptive(*grid, {}, &stats);
    CHECK(stats.filled_pockets == 1);
    const pqdc::TopologyReport t = pqdc::measure_topology(m);
    CHECK(t.connected_component_count == 1);
    CHECK(t.closed());
    CHECK(pqdc::find_self_intersections(m).pair_count == 0);
    // The other rotations of the sweep have no pocket and one component.
    for (double degrees : {26.0, 54.0}) {
        const auto other = pqdc::mesh_to_level_set(pqdc_test::l_prism(rotation_about_123(degrees)), o);
        pqdc::AdaptiveStats s;
        CHECK(pqdc::measure_topology(pqdc::extract_adaptive(*other, {}, &s)).connected_component_count == 1);
        CHECK(s.filled_pockets == 0);
    }
}

TEST_CASE("empty leaves without a value take the side of the empty leaves they touch", "[adaptive]") {
    // A level set copied into a grid whose background is NaN: beyond the
    // band, inside and outside, the field is NaN. The NaN core's empty
    // leaves were taken as outside: 33 components and 618 open edges at
    // radius 10, 57 components at 12, no warning.
    for (float radius : {10.f, 12.f}) {
        const auto band = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(radius, openvdb::Vec3f(0.f), 1.f, 3.f);
        const auto g = openvdb::FloatGrid::create(std::numeric_limits<float>::quiet_NaN());
        for (auto it = band->cbeginValueOn(); it; ++it) g->tree().setValue(it.getCoord(), *it);
        g->setGridClass(openvdb::GRID_LEVEL_SET);
        pqdc::AdaptiveStats st;
        const pqdc::Mesh m = pqdc::extract_adaptive(*g, pqdc::AdaptiveOptions{}, &st);
        CHECK(st.undefined_leaves_inside > 0);
        CHECK(!st.untangle_fallback);
        const auto t = require_watertight(m, "NaN background, radius " + std::to_string(radius));
        CHECK(t.connected_component_count == 1);
        // The band's own grid has a value everywhere: the same octree sides.
        pqdc::AdaptiveStats own;
        const pqdc::Mesh reference = pqdc::extract_adaptive(*band, pqdc::AdaptiveOptions{}, &own);
        CHECK(own.undefined_leaves_inside == 0);
        CHECK(m.triangles.size() == reference.triangles.size());
    }
    // A 1.5-voxel band: crossings next to NaN lack a finest cell, where the
    // uniform mesh is open, but the octree closes them. The count said
    // "open where the surface leaves the active region" of a closed mesh.
    const auto thin = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(10.f, openvdb::Vec3f(0.f), 1.f, 1.5f);
    const auto g = openvdb::FloatGrid::create(std::numeric_limits<float>::quiet_NaN());
    for (auto it = thin->cbeginValueOn(); it; ++it) g->tree().setValue(it.getCoord(), *it);
    g->setGridClass(openvdb::GRID_LEVEL_SET);
    pqdc::ExtractStats uniform;
    CHECK(!pqdc::measure_topology(pqdc::extract(*g, pqdc::ExtractOptions{}, &uniform)).closed());
    CHECK(uniform.boundary_crossings > 0);
    pqdc::AdaptiveStats st;
    const pqdc::Mesh closed = pqdc::extract_adaptive(*g, pqdc::AdaptiveOptions{}, &st);
    require_watertight(closed, "NaN background, 1.5-voxel band");
    CHECK(st.boundary_crossings == 0);
}

TEST_CASE("adaptive mode keeps a concave crease the dual cells would cut off", "[adaptive]") {
    // The L-prism's concave edge, rotated off the lattice. Surface leaves
    // count as inside, so the dual cells along a concave crease join the two
    // faces' vertices directly; before the crease splits the edge lay
    // 0.58 voxel (default options) and 0.42 (max_error 0) from the mesh.
    const auto rotation = rotation_about_123(40);
    const openvdb::Vec3d shift(0.01, 0.02, 0.03);
    pqdc::MeshToLevelSetOptions lo;
    lo.voxel_size = 2.0 / 32;
    const auto grid = pqdc::mesh_to_level_set(pqdc_test::l_prism(rotation, shift), lo);
    for (const double max_error : {0.1, 0.0}) {
        pqdc::AdaptiveOptions o;
        o.max_error_voxels = max_error;
        pqdc::AdaptiveStats stats;
        const pqdc::Mesh m = pqdc::extract_adaptive(*grid, o, &stats);
        INFO("max_error " << max_error);
        const pqdc::MeshDistance to_mesh(m);
        double sum = 0;
        int n = 0;
        for (double z = 0.05; z < 0.96; z += 0.25 * lo.voxel_size, ++n)
            sum += to_mesh(rotation * openvdb::Vec3d(1, 1, z) + shift) / lo.voxel_size;
        CHECK(sum / n < 0.2);
        require_watertight(m, "L-prism");
        CHECK(pqdc::find_self_intersections(m).pair_count == 0);
        CHECK_FALSE(stats.untangle_fallback);
    }
}

TEST_CASE("adaptive mode reads the grid to its end: it never calls values_done", "[adaptive][memory]") {
    const auto grid = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(16.f, Vec3d(0.3, -0.2, 0.1), 1.f, 3.f);
    pqdc::AdaptiveOptions a;
    int calls = 0;
    a.base.values_done = [&] { ++calls; };
    CHECK(!pqdc::extract_adaptive(*grid, a).empty());
    CHECK(calls == 0);
}
