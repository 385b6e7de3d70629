// Option validation for both extractors: one set of rules, messages naming
// the field as the caller spells it.
#include "pqdc/adaptive.hpp"
#include "pqdc/exceptions.hpp"
#include "pqdc/extract.hpp"
#include "lattice/enum_check.hpp"

#include <cmath>
#include <string>

namespace pqdc {
namespace {

using detail::check_enum;

void validate_base(const ExtractOptions& o, const std::string& prefix) {
    check_enum(prefix + "interior", o.interior, Interior::above_isovalue);
    check_enum(prefix + "containment", o.containment, Containment::unconstrained);
    check_enum(prefix + "stored_precision", o.stored_precision, VertexPrecision::float64);
    check_enum(prefix + "faces", o.faces, FaceType::quads);
    check_enum(prefix + "normals", o.normals, GridNormals::least_squares);
    check_enum(prefix + "denoise", o.denoise, Denoise::on);
    if (!(o.sigma_n >= 0) && o.sigma_n != sigma_n_auto)
        throw option_error(prefix + "sigma_n must be >= 0 (or inf for the mass point, or sigma_n_auto), got " +
                           std::to_string(o.sigma_n));
    if (!std::isfinite(o.isovalue))
        throw option_error(prefix + "isovalue must be a finite number, got " + std::to_string(o.isovalue));
    if (!(o.pseudo_inverse_cutoff >= 0 && o.pseudo_inverse_cutoff < 1))
        throw option_error(prefix + "pseudo_inverse_cutoff must be in [0, 1), got " +
                           std::to_string(o.pseudo_inverse_cutoff));
    if (o.region.bbox) {
        const openvdb::BBoxd& b = *o.region.bbox;
        for (int a = 0; a < 3; ++a)
            if (!std::isfinite(b.min()[a]) || !std::isfinite(b.max()[a]) || !(b.min()[a] <= b.max()[a]))
                throw option_error(prefix + "region.bbox (--bbox) must be finite with min <= max on every axis, got (" +
                                   std::to_string(b.min()[0]) + ", " + std::to_string(b.min()[1]) + ", " +
                                   std::to_string(b.min()[2]) + ") - (" + std::to_string(b.max()[0]) + ", " +
                                   std::to_string(b.max()[1]) + ", " + std::to_string(b.max()[2]) + ")");
    }
    if (!(o.min_component_voxels >= 0))
        throw option_error(prefix + "min_component_voxels (--min-component) must be >= 0 voxels (0 keeps every "
                           "component), got " + std::to_string(o.min_component_voxels));
    if (o.region.invert_mask && !o.region.mask)
        throw option_error(prefix + "region.invert_mask (--invert-mask) needs a mask (--mask)");
}

}  // namespace

void validate(const ExtractOptions& options) { validate_base(options, ""); }

void validate(const AdaptiveOptions& options) {
    validate_base(options.base, "AdaptiveOptions::base.");
    if (!(options.max_error_voxels >= 0))
        throw option_error("AdaptiveOptions::max_error_voxels (--max-error) must be >= 0 voxels, got " +
                           std::to_string(options.max_error_voxels));
    const int s = options.max_cell_size_voxels;
    if (s < 1 || s > 4096 || (s & (s - 1)) != 0)
        throw option_error("AdaptiveOptions::max_cell_size_voxels (--max-cell-size) must be a power of two "
                           "in [1, 4096], got " + std::to_string(s));
}

}  // namespace pqdc
