// The peer of bench/bench_process.sh: the whole job done the way an OpenVDB
// user would write it in one call: read the grid, openvdb::tools::volumeToMesh
// (uniform, adaptivity 0), write binary little-endian float PLY (quads kept).
//
//   vdb_to_mesh IN.vdb OUT.ply [ISOVALUE]
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/VolumeToMesh.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: vdb_to_mesh IN.vdb OUT.ply [ISOVALUE]\n");
        return 2;
    }
    const double iso = argc > 3 ? std::atof(argv[3]) : 0.0;
    openvdb::initialize();
    openvdb::io::File file(argv[1]);
    file.open(false);
    openvdb::GridBase::Ptr base = file.readGrid(file.beginName().gridName());
    file.close();
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> tris;
    std::vector<openvdb::Vec4I> quads;
    if (auto g = openvdb::gridPtrCast<openvdb::FloatGrid>(base)) {
        openvdb::tools::volumeToMesh(*g, points, tris, quads, iso, 0.0);
    } else if (auto d = openvdb::gridPtrCast<openvdb::DoubleGrid>(base)) {
        openvdb::tools::volumeToMesh(*d, points, tris, quads, iso, 0.0);
    } else {
        std::fprintf(stderr, "vdb_to_mesh: not a float or double grid\n");
        return 1;
    }
    base.reset();
    std::ofstream out(argv[2], std::ios::binary);
    out << "ply\nformat binary_little_endian 1.0\nelement vertex " << points.size()
        << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << tris.size() + quads.size()
        << "\nproperty list uchar int vertex_indices\nend_header\n";
    out.write(reinterpret_cast<const char*>(points.data()), std::streamsize(points.size() * sizeof(points[0])));
    std::vector<char> faces;
    faces.reserve(tris.size() * 13 + quads.size() * 17);
    auto put = [&](const unsigned* idx, int n) {
        faces.push_back(char(n));
        for (int k = 0; k < n; ++k) {
            const int v = int(idx[k]);
            faces.insert(faces.end(), reinterpret_cast<const char*>(&v), reinterpret_cast<const char*>(&v) + 4);
        }
    };
    for (const auto& t : tris) put(t.asPointer(), 3);
    for (const auto& q : quads) put(q.asPointer(), 4);
    out.write(faces.data(), std::streamsize(faces.size()));
    out.close();
    if (!out) {
        std::fprintf(stderr, "vdb_to_mesh: writing %s failed\n", argv[2]);
        return 1;
    }
    std::printf("%zu points, %zu triangles, %zu quads\n", points.size(), tris.size(), quads.size());
    return 0;
}
