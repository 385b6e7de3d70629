// Golden output: FNV-1a hashes of the exact bytes of meshes of a fixed set of
// volumes and options, in both modes. A change that moves one vertex by one
// ulp fails here; a commit that changes output on purpose says why and
// rewrites tests/golden_hashes.txt with
//
//   PQDC_GOLDEN_UPDATE=1 build/tests/pqdc_tests "[golden]"
//
// (the new table is written over the file; git diff shows what changed).
// The hashes pin this compiler and platform (GCC 12, x86-64 SSE2 doubles,
// no FMA contraction). On another platform they may legitimately differ:
// the test still fails there, so a port regenerates the file deliberately.
#include "pqdc/adaptive.hpp"
#include "pqdc/extract.hpp"
#include "pqdc/procedural.hpp"
#include "pqdc/volume_io.hpp"

#include <catch2/catch.hpp>
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <iomanip>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace {

struct Init {
    Init() { openvdb::initialize(); }
} init_openvdb;

const std::string kHashFile = std::string(PQDC_SOURCE_DIR) + "/tests/golden_hashes.txt";

struct Fnv1a {
    std::uint64_t h = 0xcbf29ce484222325ULL;
    void bytes(const void* p, std::size_t n) {
        const auto* c = static_cast<const unsigned char*>(p);
        for (std::size_t i = 0; i < n; ++i) {
            h ^= c[i];
            h *= 0x100000001b3ULL;
        }
    }
    void u64(std::uint64_t v) { bytes(&v, sizeof v); }
};

/// Hash of the mesh's arrays: counts, then every coordinate's bits, then
/// every index, in order.
std::uint64_t mesh_hash(const pqdc::Mesh& m) {
    Fnv1a f;
    f.u64(m.points.size());
    f.u64(m.triangles.size());
    f.u64(m.quads.size());
    for (const auto& p : m.points) f.bytes(p.asPointer(), 3 * sizeof(double));
    for (const auto& t : m.triangles) f.bytes(t.asPointer(), 3 * sizeof(openvdb::Index32));
    for (const auto& q : m.quads) f.bytes(q.asPointer(), 4 * sizeof(openvdb::Index32));
    return f.h;
}

openvdb::FloatGrid::Ptr volume(const std::string& name) {
    const pqdc::LoadedGrid g = pqdc::read_scalar_grid(std::string(PQDC_SOURCE_DIR) + "/volumes/" + name + ".vdb");
    return openvdb::gridPtrCast<openvdb::FloatGrid>(g.grid);
}

/// The shipped box with its transform mirrored (scale -1 along z).
openvdb::FloatGrid::Ptr mirrored_box() {
    openvdb::FloatGrid::Ptr g = volume("box")->deepCopy();
    openvdb::math::Mat4d m = g->transform().baseMap()->getAffineMap()->getMat4();
    openvdb::math::Mat4d mirror = openvdb::math::Mat4d::identity();
    mirror(2, 2) = -1;
    g->setTransform(openvdb::math::Transform::createLinearTransform(m * mirror));
    return g;
}

/// The shipped sphere as a double grid.
openvdb::DoubleGrid::Ptr double_sphere() {
    const openvdb::FloatGrid::Ptr f = volume("sphere");
    auto d = openvdb::DoubleGrid::create(double(f->background()));
    d->setTransform(f->transform().copy());
    d->setGridClass(f->getGridClass());
    d->tree().topologyUnion(f->tree());
    for (auto it = f->tree().cbeginValueAll(); it; ++it) {
        if (it.isVoxelValue()) d->tree().setValueOnly(it.getCoord(), double(*it));
    }
    return d;
}

/// A fog volume: density 1 - phi / w clamped to [0, 1] from the shipped
/// sphere's level set, background 0, inside above the isovalue 0.5.
openvdb::FloatGrid::Ptr fog_sphere() {
    const openvdb::FloatGrid::Ptr ls = volume("sphere");
    openvdb::FloatGrid::Ptr fog = ls->deepCopy();
    const float w = float(3 * ls->voxelSize()[0]);
    for (auto it = fog->tree().beginValueAll(); it; ++it) {
        const float v = *it;
        it.setValue(std::min(1.0f, std::max(0.0f, 0.5f - 0.5f * v / w)));
    }
    fog->tree().root().setBackground(0.0f, /*updateChildNodes=*/true);
    fog->setGridClass(openvdb::GRID_FOG_VOLUME);
    return fog;
}

using Case = std::function<pqdc::Mesh()>;

std::map<std::string, Case> cases() {
    std::map<std::string, Case> c;
    pqdc::ProceduralSampling s;
    s.resolution = 48;
    auto uniform_proc = [s](const std::string& field, double sigma, pqdc::FaceType faces) {
        return [=] {
            pqdc::ExtractOptions o;
            o.sigma_n = sigma;
            o.faces = faces;
            return pqdc::extract(*pqdc::make_procedural(field), s, o);
        };
    };
    auto adaptive_proc = [s](const std::string& field, double sigma, double error, pqdc::FaceType faces) {
        return [=] {
            pqdc::AdaptiveOptions o;
            o.base.sigma_n = sigma;
            o.base.faces = faces;
            o.max_error_voxels = error;
            return pqdc::extract_adaptive(*pqdc::make_procedural(field), s, o);
        };
    };
    const double inf = std::numeric_limits<double>::infinity();
    for (const std::string f : {"sphere", "box", "figure3"}) {
        c["uniform/procedural/" + f + "/sigma0.1"] = uniform_proc(f, 0.1, pqdc::FaceType::triangles);
        c["adaptive/procedural/" + f + "/sigma0.1/E0.1"] = adaptive_proc(f, 0.1, 0.1, pqdc::FaceType::triangles);
    }
    c["uniform/procedural/box/sigma0"] = uniform_proc("box", 0.0, pqdc::FaceType::triangles);
    c["uniform/procedural/box/sigmainf"] = uniform_proc("box", inf, pqdc::FaceType::triangles);
    c["uniform/procedural/figure3/sigma0.25/quads"] = uniform_proc("figure3", 0.25, pqdc::FaceType::quads);
    c["adaptive/procedural/box/sigma0/E0.5"] = adaptive_proc("box", 0.0, 0.5, pqdc::FaceType::triangles);
    c["adaptive/procedural/sphere/sigma0.1/E0"] = adaptive_proc("sphere", 0.1, 0.0, pqdc::FaceType::triangles);
    c["adaptive/procedural/figure3/sigma0.1/E1/quads"] = adaptive_proc("figure3", 0.1, 1.0, pqdc::FaceType::quads);

    auto uniform_grid = [](std::function<openvdb::GridBase::Ptr()> grid, pqdc::ExtractOptions o) {
        return [=] { return pqdc::extract(*grid(), o); };
    };
    auto adaptive_grid = [](std::function<openvdb::GridBase::Ptr()> grid, pqdc::AdaptiveOptions o) {
        return [=] { return pqdc::extract_adaptive(*grid(), o); };
    };
    auto file = [](const std::string& name) { return [=]() -> openvdb::GridBase::Ptr { return volume(name); }; };
    pqdc::ExtractOptions central;
    pqdc::ExtractOptions sharp;
    sharp.sigma_n = 0;
    sharp.normals = pqdc::GridNormals::sharp;
    pqdc::ExtractOptions quads;
    quads.faces = pqdc::FaceType::quads;
    pqdc::ExtractOptions free_vertices;
    free_vertices.containment = pqdc::Containment::unconstrained;
    pqdc::AdaptiveOptions adaptive;
    pqdc::AdaptiveOptions adaptive_sharp;
    adaptive_sharp.base = sharp;
    adaptive_sharp.max_error_voxels = 0.25;
    for (const std::string v : {"fandisk", "armadillo", "box", "figure3"}) {
        c["uniform/file/" + v + "/central"] = uniform_grid(file(v), central);
        c["adaptive/file/" + v + "/central/E0.1"] = adaptive_grid(file(v), adaptive);
    }
    c["uniform/file/fandisk/sharp/sigma0"] = uniform_grid(file("fandisk"), sharp);
    c["adaptive/file/fandisk/sharp/sigma0/E0.25"] = adaptive_grid(file("fandisk"), adaptive_sharp);
    c["uniform/file/figure3/quads"] = uniform_grid(file("figure3"), quads);
    c["uniform/file/armadillo/unconstrained"] = uniform_grid(file("armadillo"), free_vertices);
    c["uniform/file/box/mirrored"] = uniform_grid([] { return mirrored_box(); }, central);
    c["adaptive/file/box/mirrored/E0.1"] = adaptive_grid([] { return mirrored_box(); }, adaptive);
    c["uniform/double/sphere"] = uniform_grid([] { return double_sphere(); }, central);
    c["adaptive/double/sphere/E0.1"] = adaptive_grid([] { return double_sphere(); }, adaptive);
    pqdc::ExtractOptions fog;
    fog.isovalue = 0.5;
    pqdc::AdaptiveOptions adaptive_fog;
    adaptive_fog.base = fog;
    c["uniform/fog/sphere/iso0.5"] = uniform_grid([] { return fog_sphere(); }, fog);
    c["adaptive/fog/sphere/iso0.5/E0.1"] = adaptive_grid([] { return fog_sphere(); }, adaptive_fog);
    return c;
}

std::string line(const std::string& name, const pqdc::Mesh& m) {
    std::ostringstream s;
    s << name << ' ' << m.points.size() << ' ' << m.face_count() << ' ' << std::hex << std::setw(16)
      << std::setfill('0') << mesh_hash(m);
    return s.str();
}

}  // namespace

TEST_CASE("meshes of the golden set are byte-identical to tests/golden_hashes.txt", "[golden]") {
    std::map<std::string, std::string> expected;
    {
        std::ifstream in(kHashFile);
        std::string l;
        while (std::getline(in, l)) {
            if (l.empty() || l[0] == '#') continue;
            expected[l.substr(0, l.find(' '))] = l;
        }
    }
    const bool update = std::getenv("PQDC_GOLDEN_UPDATE") != nullptr;
    std::ostringstream table;
    table << "# name vertices faces fnv1a64 (tests/test_golden.cpp; regenerate with PQDC_GOLDEN_UPDATE=1)\n";
    for (const auto& [name, make] : cases()) {
        const std::string got = line(name, make());
        table << got << '\n';
        if (update) continue;
        {
            const tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
            INFO("golden case " << name << " on one thread");
            CHECK(line(name, make()) == got);
        }
        INFO("golden case " << name << " (a deliberate change of output regenerates " << kHashFile
                            << " with PQDC_GOLDEN_UPDATE=1 and says why in its commit)");
        REQUIRE(expected.count(name) == 1);
        CHECK(got == expected[name]);
    }
    if (update) {
        std::ofstream(kHashFile) << table.str();
        WARN("rewrote " << kHashFile);
    } else {
        CHECK(expected.size() == cases().size());  // no stale lines
    }
}
