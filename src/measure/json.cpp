// The measures as JSON objects (non-finite numbers as null).
#include "pqdc/measure.hpp"

#include <nlohmann/json.hpp>

#include <string>

namespace pqdc {
namespace {

/// Keys in the order given, compact, non-finite numbers as null
/// (nlohmann's rule, the apps' too).
class JsonObject {
public:
    template <class T>
    JsonObject& add(const char* key, const T& value) {
        json_[key] = value;
        return *this;
    }
    std::string str() const { return json_.dump(); }

private:
    nlohmann::ordered_json json_ = nlohmann::ordered_json::object();
};

}  // namespace

std::string to_json(const TopologyReport& r) {
    return JsonObject()
        .add("vertex_count", r.vertex_count)
        .add("unreferenced_vertex_count", r.unreferenced_vertex_count)
        .add("triangle_count", r.triangle_count)
        .add("quad_count", r.quad_count)
        .add("edge_count", r.edge_count)
        .add("boundary_edge_count", r.boundary_edge_count)
        .add("non_manifold_edge_count", r.non_manifold_edge_count)
        .add("inconsistent_edge_count", r.inconsistent_edge_count)
        .add("non_manifold_vertex_count", r.non_manifold_vertex_count)
        .add("degenerate_face_count", r.degenerate_face_count)
        .add("non_finite_point_count", r.non_finite_point_count)
        .add("connected_component_count", r.connected_component_count)
        .add("euler_characteristic", r.euler_characteristic)
        .add("edge_manifold", r.edge_manifold())
        .add("vertex_manifold", r.vertex_manifold())
        .add("consistently_oriented", r.consistently_oriented())
        .add("closed", r.closed())
        .str();
}

std::string to_json(const TriangleQuality& q) {
    return JsonObject()
        .add("triangle_count", q.triangle_count)
        .add("min_angle_mean_degrees", q.min_angle_mean_degrees)
        .add("min_angle_min_degrees", q.min_angle_min_degrees)
        .add("min_angle_p05_degrees", q.min_angle_p05_degrees)
        .add("fraction_below_10_degrees", q.fraction_below_10_degrees)
        .str();
}

std::string to_json(const DistanceStats& s) {
    return JsonObject()
        .add("sample_count", s.sample_count)
        .add("mean", s.mean)
        .add("rms", s.rms)
        .add("max", s.max)
        .add("mean_signed", s.mean_signed)
        .add("unreliable_count", s.unreliable_count)
        .str();
}

std::string to_json(const NormalDeviation& d) {
    return JsonObject()
        .add("sample_count", d.sample_count)
        .add("mean_degrees", d.mean_degrees)
        .add("rms_degrees", d.rms_degrees)
        .add("max_degrees", d.max_degrees)
        .add("skipped_count", d.skipped_count)
        .str();
}

}  // namespace pqdc
