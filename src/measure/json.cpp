// The measures as compact JSON objects, keys in the order given, non-finite
// numbers as null (nlohmann's rule, the apps' too).
#include "pqdc/measure.hpp"

#include <nlohmann/json.hpp>

#include <string>

namespace pqdc {

std::string to_json(const TopologyReport& r) {
    return nlohmann::ordered_json{
        {"vertex_count", r.vertex_count},
        {"unreferenced_vertex_count", r.unreferenced_vertex_count},
        {"triangle_count", r.triangle_count},
        {"quad_count", r.quad_count},
        {"edge_count", r.edge_count},
        {"boundary_edge_count", r.boundary_edge_count},
        {"non_manifold_edge_count", r.non_manifold_edge_count},
        {"inconsistent_edge_count", r.inconsistent_edge_count},
        {"non_manifold_vertex_count", r.non_manifold_vertex_count},
        {"degenerate_face_count", r.degenerate_face_count},
        {"non_finite_point_count", r.non_finite_point_count},
        {"connected_component_count", r.connected_component_count},
        {"euler_characteristic", r.euler_characteristic},
        {"edge_manifold", r.edge_manifold()},
        {"vertex_manifold", r.vertex_manifold()},
        {"consistently_oriented", r.consistently_oriented()},
        {"closed", r.closed()}}
        .dump();
}

std::string to_json(const TriangleQuality& q) {
    return nlohmann::ordered_json{
        {"triangle_count", q.triangle_count},
        {"min_angle_mean_degrees", q.min_angle_mean_degrees},
        {"min_angle_min_degrees", q.min_angle_min_degrees},
        {"min_angle_p05_degrees", q.min_angle_p05_degrees},
        {"fraction_below_10_degrees", q.fraction_below_10_degrees}}
        .dump();
}

std::string to_json(const DistanceStats& s) {
    return nlohmann::ordered_json{
        {"sample_count", s.sample_count},
        {"mean", s.mean},
        {"rms", s.rms},
        {"max", s.max},
        {"mean_signed", s.mean_signed},
        {"unreliable_count", s.unreliable_count},
        {"skipped_count", s.skipped_count}}
        .dump();
}

std::string to_json(const NormalDeviation& d) {
    return nlohmann::ordered_json{
        {"sample_count", d.sample_count},
        {"mean_degrees", d.mean_degrees},
        {"rms_degrees", d.rms_degrees},
        {"max_degrees", d.max_degrees},
        {"skipped_count", d.skipped_count}}
        .dump();
}

}  // namespace pqdc
