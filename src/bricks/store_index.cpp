#include "bricks/store_index.hpp"

#include "pqdc/exceptions.hpp"
#include "io/foreign_message.hpp"
#include "bricks/bricks.hpp"
#include "bricks/file_digest.hpp"

#include <openvdb/io/File.h>

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

namespace pqdc::detail {
namespace {

namespace fs = std::filesystem;

/// Throws input_error naming the permissions when `file` exists but this
/// process may not read it: not a damaged store, so no "split it again".
void check_permission(const std::string& store, const fs::path& file) {
    if (::access(file.c_str(), R_OK) == 0 || errno != EACCES) return;
    throw input_error("brick store '" + store + "': cannot read '" + file.string() + "': " + std::strerror(EACCES) +
                      " (check its permissions)");
}

/// Throws input_error unless `file` has the size index.txt recorded for it.
void check_brick_size(const std::string& store, const fs::path& file, std::uintmax_t expected) {
    std::error_code ec;
    const std::uintmax_t actual = fs::file_size(file, ec);
    if (ec)
        throw input_error("brick store '" + store + "': cannot read '" + file.string() + "' (" + ec.message() +
                          "); split the volume again with pqdc-bricks split");
    if (actual != expected)
        throw input_error("brick store '" + store + "': '" + file.string() + "' is " + std::to_string(actual) +
                          " bytes, index.txt says " + std::to_string(expected) +
                          " (the file was cut short or replaced); split the volume again with pqdc-bricks split");
}

/// A file size as index.txt writes it (decimal digits), into `bytes`.
bool parse_size(const std::string& text, std::uint64_t& bytes) {
    if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos || text.size() > 19) return false;
    bytes = std::stoull(text);
    return true;
}

/// The brick extent whose boxes have the size of `box`, or 0 when none does.
openvdb::Coord extent_of(const openvdb::CoordBBox& box) {
    for (int size = 128; size <= 4096; size *= 2)
        if (box.dim() == brick_extent(size)) return brick_extent(size);
    return openvdb::Coord(0);
}

}  // namespace

std::string brick_file_name(std::size_t k) {
    char name[32];
    std::snprintf(name, sizeof name, "brick-%06llu.vdb", static_cast<unsigned long long>(k));
    return name;
}

StoreIndex::StoreIndex(const std::string& dir) : dir_(dir) {
    check_permission(dir, fs::path(dir) / "index.txt");
    std::ifstream index(fs::path(dir) / "index.txt");
    std::string magic, shell_line, line;
    // Lines as written, or with CRLF endings (a copy through Windows or git's
    // autocrlf): the format said "pqdc-brick-store 2\r" was newer than 2.
    const auto next_line = [&index](std::string& text) {
        if (!std::getline(index, text)) return false;
        if (!text.empty() && text.back() == '\r') text.pop_back();
        return true;
    };
    next_line(magic);
    next_line(shell_line);
    const int version = magic == kStoreIndexMagic ? 3 : magic == kStoreIndexMagicV2 ? 2 : magic == kStoreIndexMagicV1 ? 1 : 0;
    const bool has_end = version >= 2, has_digests = version >= 3;
    if (index && magic.rfind("pqdc-brick-store ", 0) == 0 && version == 0)
        throw input_error("brick store '" + dir + "': index.txt is of format '" + magic + "', newer than this pqdc "
                          "reads ('" + kStoreIndexMagic + "'); use the pqdc that wrote it, or split the volume "
                          "again with this pqdc-bricks");
    if (!index || version == 0 || shell_line.rfind("shell grid.vdb", 0) != 0)
        throw input_error("'" + dir + "' is not a pqdc brick store (index.txt missing or of another format); "
                          "make one with pqdc-bricks split");
    read_shell_line(shell_line, has_digests);
    bool ended = false;
    while (next_line(line)) {
        if (line.empty()) continue;
        if (has_end && !ended && line.rfind("end ", 0) == 0) {
            ended = true;
            if (line != "end " + std::to_string(bricks_.size()))
                throw input_error("brick store '" + dir + "': index.txt lists " + std::to_string(bricks_.size()) +
                                  " bricks but its last line is '" + line +
                                  "' (lines were lost or added); split the volume again with pqdc-bricks split");
            continue;
        }
        if (ended)
            throw input_error("brick store '" + dir + "': index.txt goes on after its end line ('" + line +
                              "'); split the volume again with pqdc-bricks split");
        std::istringstream in(line);
        std::string word;
        StoreBrickFile b;
        in >> word >> b.file >> b.box.min().x() >> b.box.min().y() >> b.box.min().z() >> b.box.max().x() >>
            b.box.max().y() >> b.box.max().z();
        const auto bad_line = [&](const std::string& why) {
            return input_error("brick store '" + dir + "': index.txt has a bad line '" + line + "'" + why +
                               "; split the volume again with pqdc-bricks split");
        };
        if (!in || word != "brick" || b.file.find('/') != std::string::npos) throw bad_line("");
        // pqdc-bricks numbers the files in the order of their lines: a gap is
        // a line taken out (its part of the volume would be a hole).
        if (b.file != brick_file_name(bricks_.size()))
            throw bad_line(" (expected '" + brick_file_name(bricks_.size()) +
                           "': the lines name the files in order, so one was removed or renamed)");
        // Stores written before the sizes were recorded end the line here.
        if (std::string bytes; in >> bytes) {
            if (!parse_size(bytes, b.bytes)) throw bad_line("");
            check_brick_size(dir, fs::path(dir) / b.file, b.bytes);
            if (has_digests && !(in >> b.digest && is_file_digest(b.digest))) throw bad_line(" (no checksum)");
            if (std::string more; in >> more) throw bad_line("");
        } else if (has_digests) {
            throw bad_line(" (no size and checksum)");
        } else {
            std::error_code ec;
            b.bytes = fs::file_size(fs::path(dir) / b.file, ec);  // a missing file is named when it is opened
            if (ec) b.bytes = 0;
        }
        const openvdb::Coord extent = extent_of(b.box);
        if (extent == openvdb::Coord(0) || brick_origin(b.box.min(), extent) != b.box.min())
            throw bad_line(" (the box is not a brick of pqdc-bricks split)");
        if (bricks_.empty()) extent_ = extent;
        if (extent != extent_) throw bad_line(" (the box's size differs from the first brick's)");
        if (!by_min_.emplace(b.box.min(), bricks_.size()).second) throw bad_line(" (a second file for one box)");
        bricks_.push_back(std::move(b));
    }
    if (has_end && !ended)
        throw input_error("brick store '" + dir + "': index.txt has no end line after its " +
                          std::to_string(bricks_.size()) +
                          " bricks (it was cut short, or pqdc-bricks did not finish); split the volume again "
                          "with pqdc-bricks split");
}

void StoreIndex::read_shell_line(const std::string& line, bool has_digests) {
    std::istringstream in(line);
    std::string word, file, bytes, more;
    in >> word >> file;
    if (!has_digests) {
        if (line == "shell grid.vdb") return;
    } else if (word == "shell" && file == "grid.vdb" && in >> bytes >> shell_digest_ && !(in >> more)) {
        // The size is not checked apart: the checksum covers it, and a
        // missing grid.vdb is named where it is read.
        std::uint64_t size = 0;
        if (parse_size(bytes, size) && is_file_digest(shell_digest_)) return;
    }
    throw input_error("brick store '" + dir_ + "': index.txt has a bad line '" + line +
                      "'; split the volume again with pqdc-bricks split");
}

std::string StoreIndex::shell_path() const { return (fs::path(dir_) / "grid.vdb").string(); }

std::vector<std::size_t> StoreIndex::overlapping(const openvdb::CoordBBox& box) const {
    std::vector<std::size_t> found;
    if (bricks_.empty() || box.empty()) return found;
    const openvdb::Coord lo = brick_origin(box.min(), extent_);
    // In 64 bits: a box reaching the end of the int range would wrap the steps.
    for (std::int64_t x = lo.x(); x <= box.max().x(); x += extent_.x())
        for (std::int64_t y = lo.y(); y <= box.max().y(); y += extent_.y())
            for (std::int64_t z = lo.z(); z <= box.max().z(); z += extent_.z()) {
                const auto it = by_min_.find(openvdb::Coord(int(x), int(y), int(z)));
                if (it != by_min_.end()) found.push_back(it->second);
            }
    std::sort(found.begin(), found.end());
    return found;
}

std::size_t StoreIndex::holding(const openvdb::Coord& p) const {
    if (bricks_.empty()) return 0;
    const auto it = by_min_.find(brick_origin(p, extent_));
    return it == by_min_.end() ? bricks_.size() : it->second;
}

void check_file_digest(const std::string& store, const std::string& path, const std::string& digest) {
    if (digest.empty()) return;
    std::string actual;
    try {
        actual = file_digest(path);
    } catch (const std::system_error& e) {
        check_permission(store, path);
        throw input_error("brick store '" + store + "': cannot read '" + path + "' (" + e.code().message() +
                          "); split the volume again with pqdc-bricks split");
    }
    if (actual != digest)
        throw input_error("brick store '" + store + "': '" + path + "' does not match the checksum index.txt " +
                          "records for it (the file was damaged or changed after the split); split the volume " +
                          "again with pqdc-bricks split");
}

openvdb::GridBase::Ptr open_brick_file(const std::string& store, const std::string& file) {
    const std::string path = (fs::path(store) / file).string();
    check_permission(store, path);
    try {
        openvdb::io::File f(path);
        f.setCopyMaxBytes(0);
        f.open(true);
        const openvdb::GridPtrVecPtr grids = f.getGrids();
        f.close();
        if (!grids || grids->size() != 1) throw input_error("it does not hold exactly one grid");
        return grids->front();
    } catch (const std::exception& e) {
        throw input_error("brick store '" + store + "': cannot read '" + path + "' (" + foreign_message(e.what()) +
                          "); split the volume again with pqdc-bricks split");
    }
}

void check_brick_identity(const std::string& store, const StoreBrickFile& file, const openvdb::GridBase& brick,
                          double brick_background, const openvdb::GridBase& shell, double shell_background) {
    const auto refuse = [&](const std::string& what) {
        throw input_error("brick store '" + store + "': '" + file.file + "' has another " + what +
                          " than the store's grid.vdb (one of them comes from another volume); split the volume "
                          "again with pqdc-bricks split");
    };
    if (brick.getName() != shell.getName()) refuse("grid name ('" + brick.getName() + "', not '" + shell.getName() + "')");
    if (brick.transform() != shell.transform()) refuse("transform (voxel size, origin or rotation)");
    if (!(brick_background == shell_background || (std::isnan(brick_background) && std::isnan(shell_background))))
        refuse("background value");
}

}  // namespace pqdc::detail
