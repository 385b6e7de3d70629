// Sparse conversion of a dense 3-D array (any numeric element type, any
// strides) to an OpenVDB float or double grid that meshes to the same bytes
// as a grid holding every voxel.
//
// Only 8^3 blocks whose voxels, plus an apron of kApron (kDenoiseApron) voxels around them,
// lie on both sides of the isovalue become leaves; every other block becomes
// an inactive tile holding one of its values (so the field keeps its sign
// there). Why that is exact: a voxel is read by the extractor only through a
// cell with a sign change (its corners, their central or ENO gradient
// stencils, 2 voxels out), and such a cell's corners lie within one voxel of
// both signs, so every voxel it reads has both signs within 3 voxels.
//
// Array voxels are active leaf voxels; voxels outside the array or in the
// padding of border leaves are inactive NaN (also the background), so cells
// touching them take no part: the surface is open at the array border, as
// with marching cubes. A numpy mask becomes a MaskGrid (mask_to_grid) for
// ExtractOptions::region, like any other mask.
#pragma once

#include <pqdc/extract.hpp>

#include <openvdb/openvdb.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>

namespace pqdc::python {

/// Element types the converter reads (numpy's fixed-size numeric kinds).
enum class ElementType { f16, f32, f64, i8, i16, i32, i64, u8, u16, u32, u64, b8 };

/// A strided 3-D array in index order: element (x, y, z) lives at
/// data + x*strides[0] + y*strides[1] + z*strides[2] (bytes).
struct ArrayView {
    const char* data = nullptr;
    ElementType type = ElementType::f32;
    std::array<std::int64_t, 3> shape{};
    std::array<std::int64_t, 3> strides{};
};

/// A mask in index order, one byte per voxel (numpy bool; nonzero: in the
/// mask): voxel (x, y, z) at data + x*strides[0] + y*strides[1] + z*strides[2].
struct MaskView {
    const std::uint8_t* data = nullptr;
    std::array<std::int64_t, 3> shape{};
    std::array<std::int64_t, 3> strides{};
};

/// Voxels the extractor's stencils reach from a crossing cell's sign change
/// (one voxel to the cell's other corners, two for ENO gradients).
constexpr int kApron = 3;

/// The same with denoising (ExtractOptions::denoise on): the smoothed
/// field's values read raw ones two voxels out,
/// a smoothed sign change lies within about three voxels of a raw one (the
/// smoothing changes only values within two gradient lengths of zero), and
/// the quadric filter reads the crossings of neighbouring cells: 7, the
/// most an 8^3 block's neighbours cover. Argued from the stencils, not
/// proven (the three voxels are the smoothing band's, not a bound); the
/// tests compare sparse against dense conversion on noisy arrays.
constexpr int kDenoiseApron = 7;

struct ConversionOptions {
    double isovalue = 0.0;
    /// below_isovalue or above_isovalue (automatic must be resolved first:
    /// the side test has to be the extractor's).
    Interior interior = Interior::below_isovalue;
    /// false: every array block becomes a leaf (the reference the sparse
    /// conversion must reproduce).
    bool sparse = true;
    /// Voxels around a block whose values decide whether it is stored:
    /// kApron, or kDenoiseApron when the extraction denoises.
    int apron = kApron;
    /// Bytes the grid may take; 0 = no check (the extractor checks later).
    std::size_t memory_limit_bytes = 0;
    /// Called between slabs of blocks (cancellation point), fraction in [0, 1].
    std::function<bool(double)> progress;
};

struct ConversionStats {
    std::uint64_t blocks = 0;       ///< 8^3 blocks touching the array
    std::uint64_t dense_leaves = 0; ///< blocks stored voxel by voxel
    std::uint64_t tiles = 0;        ///< blocks stored as one inactive value
    std::uint64_t grid_bytes = 0;   ///< memory of the grid's leaves
    double seconds = 0;
};

/// Returns a FloatGrid for elements exactly representable in float (f16, f32,
/// 8- and 16-bit integers, bool) and a DoubleGrid otherwise. Identity
/// transform, grid class unknown. Throws resource_error before allocating
/// leaves beyond options.memory_limit_bytes, cancelled_error when progress
/// returns false.
openvdb::GridBase::Ptr array_to_grid(const ArrayView& array, const ConversionOptions& options,
                                     ConversionStats* stats);

/// The mask's voxels as the active voxels of a MaskGrid in the array's index
/// space (identity transform), for ExtractOptions::region.mask.
openvdb::MaskGrid::Ptr mask_to_grid(const MaskView& mask);

}  // namespace pqdc::python
