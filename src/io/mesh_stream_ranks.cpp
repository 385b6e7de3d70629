// MeshStreamWriter::finish(group): one file from the parts several ranks
// wrote (issue 14: "the output is written collectively at computed offsets,
// or as per-rank parts joined in rank order").
//
// Each rank's writer holds its own pieces as formatted sections
// (mesh_stream_impl.hpp). The file is the header, then section 0 of rank 0,
// rank 1, ..., then section 1 of every rank, and so on, so every part's place
// follows from the section sizes alone. One all-gather brings every rank the
// sizes, counts and index ranges (the header and the index check need the
// totals). Then:
//  - shared file: rank 0 creates the temporary file and stamps a random token
//    into it; every rank opens it by name and reads the token back, which
//    proves that it sees the same file. If every rank does, each writes its
//    sections at their offsets (pwrite) and syncs them; rank 0 writes the
//    header and renames the file into place once all have reported success.
//    The formatting was done in parallel, as the pieces arrived, and no mesh
//    bytes travel to rank 0.
//  - through root (asked for, or a rank could not open the file: no shared
//    file system): every rank sends its sections to rank 0 in chunks of at
//    most 4 MiB, and rank 0 writes them in file order.
// Failures are gathered at rank 0, which removes the temporary file first,
// and broadcast: every rank throws the same error, or none does.
#include "pqdc/distributed.hpp"
#include "pqdc/mesh_stream.hpp"

#include "io/mesh_stream_impl.hpp"
#include "io/temporary_files.hpp"
#include "ranks/rank_exchange.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace pqdc {
namespace {

using io::AtomicFileWriter;

constexpr const char* kParts = "the ranks' parts of a mesh file";
constexpr std::size_t kMaxSections = 4;  // OBJ: v, vn, f3, f4

/// What every rank tells the others about its part.
struct PartInfo {
    std::uint64_t broken = 0, points = 0, triangles = 0, quads = 0;
    io::IndexRange triangle_range, quad_range;
    std::uint64_t format = 0, normals = 0, precision = 0, section_count = 0;
    std::array<std::uint64_t, kMaxSections> section_bytes{};
};

/// The file's layout: where each rank's sections go, after the header.
struct Layout {
    std::uint64_t points = 0, triangles = 0, quads = 0;
    std::uint64_t body_bytes = 0;  ///< every section of every rank
    std::vector<std::array<std::uint64_t, kMaxSections>> offset;  ///< [rank][section], from the end of the header
};

Layout lay_out(const std::vector<PartInfo>& parts) {
    Layout l;
    l.offset.resize(parts.size());
    std::uint64_t at = 0;
    for (std::size_t k = 0; k < parts[0].section_count; ++k)
        for (std::size_t r = 0; r < parts.size(); ++r) {
            l.offset[r][k] = at;
            at += parts[r].section_bytes[k];
        }
    l.body_bytes = at;
    for (const PartInfo& p : parts) l.points += p.points, l.triangles += p.triangles, l.quads += p.quads;
    return l;
}

/// The first face (numbered in the whole file) holding the largest index of
/// one kind, as one writer given every part in rank order would have found.
io::IndexRange whole_range(const std::vector<PartInfo>& parts, bool triangles) {
    io::IndexRange whole;
    std::uint64_t before = 0;
    for (const PartInfo& p : parts) {
        whole.add(triangles ? p.triangle_range : p.quad_range, before);
        before += triangles ? p.triangles : p.quads;
    }
    return whole;
}

/// Collective: every rank's error (empty: none) at rank 0, which calls
/// on_failure() and broadcasts the first one, naming its rank; every rank
/// then throws it as io_error.
template <class OnFailure>
void agree(RankGroup& group, const std::string& error, const OnFailure& on_failure) {
    std::string verdict;
    const std::vector<std::string> errors = group.gather_at_root(error);
    if (group.rank() == 0) {
        for (std::size_t r = 0; r < errors.size() && verdict.empty(); ++r)
            if (!errors[r].empty()) verdict = errors[r] + " (rank " + std::to_string(r) + ")";
        if (!verdict.empty()) on_failure();
    }
    verdict = group.broadcast_from_root(verdict);
    if (!verdict.empty()) throw io_error(verdict);
}

/// The message of the exception f() throws, or "" (a rank must reach the
/// next collective step whatever happened).
template <class F>
std::string error_of(const F& f) {
    try {
        f();
    } catch (const std::exception& e) {
        return e.what();
    }
    return {};
}

/// What rank 0 tells the others once it has created the file.
struct FileTicket {
    std::string error;      ///< non-empty: the file could not be created
    std::string temp_path;  ///< empty: no file others could open (standard output, a device)
    std::string token;      ///< the bytes stamped at its start
    std::uint64_t header_bytes = 0;
};

std::string encode(const FileTicket& t) {
    std::string bytes;
    detail::PartWriter w(bytes);
    for (const std::string* s : {&t.error, &t.temp_path, &t.token}) {
        w.put(std::uint64_t(s->size()));
        w.put_bytes(s->data(), s->size());
    }
    w.put(t.header_bytes);
    return bytes;
}

FileTicket decode(const std::string& bytes) {
    detail::PartReader r(bytes, kParts);
    FileTicket t;
    for (std::string* s : {&t.error, &t.temp_path, &t.token}) {
        const auto n = r.get<std::uint64_t>();
        if (n > r.left()) r.malformed("it ends early");
        s->resize(std::size_t(n));
        r.get_bytes(s->data(), s->size());
    }
    t.header_bytes = r.get<std::uint64_t>();
    return t;
}

std::string random_token() {
    std::random_device device;
    std::string token(16, '\0');
    for (char& c : token) c = char(device() & 0xff);
    return token;
}

/// Another rank's handle on rank 0's temporary file, proven to be the same
/// file by its token; closes without syncing unless sync_and_close() ran.
class SharedFile {
public:
    SharedFile(const FileTicket& ticket) {
        if (ticket.temp_path.empty()) return;
        fd_ = ::open(ticket.temp_path.c_str(), O_RDWR | O_CLOEXEC);
        if (fd_ < 0) return;
        std::string seen(ticket.token.size(), '\0');
        same_ = ::pread(fd_, seen.data(), seen.size(), 0) == ssize_t(seen.size()) && seen == ticket.token;
        // Should rank 0 be killed outright, this rank can still remove it.
        if (same_) listing_.list(ticket.temp_path);
    }
    ~SharedFile() {
        if (fd_ >= 0) ::close(fd_);
    }
    SharedFile(const SharedFile&) = delete;
    SharedFile& operator=(const SharedFile&) = delete;

    bool same() const { return same_; }
    int descriptor() const { return fd_; }
    void sync_and_close(const std::string& target) {
        const int fd = fd_;
        fd_ = -1;
        if (::fsync(fd) != 0 || ::close(fd) != 0)
            throw io_error("cannot write '" + target + "': " + std::strerror(errno) +
                           " (while flushing this rank's part to disk)");
    }

private:
    int fd_ = -1;
    bool same_ = false;
    detail::TemporaryFileListing listing_;
};

/// Chunk messages of the through-root transfer: a tag byte, then data.
constexpr char kData = 'd', kEnd = 'e', kFailed = 'x';

using Sections = std::vector<std::unique_ptr<AtomicFileWriter>>;

/// This rank's sections written at `offset` (after the header) into the
/// shared file: rank 0's `file` (also the header and the final size), or
/// `shared` on the other ranks. Returns the error, or "".
std::string write_in_place(const Sections& sections, const std::array<std::uint64_t, kMaxSections>& offset,
                           const FileTicket& ticket, const std::string& header, std::uint64_t body_bytes,
                           AtomicFileWriter* file, SharedFile& shared, const std::string& target) {
    return error_of([&] {
        const int fd = file ? file->flushed_descriptor() : shared.descriptor();
        for (std::size_t k = 0; k < sections.size(); ++k)
            sections[k]->copy_to(fd, ticket.header_bytes + offset[k], target);
        if (!file) return shared.sync_and_close(target);
        AtomicFileWriter::write_all_at(fd, header.data(), header.size(), 0, target);
        // The token may reach past a file shorter than it (an empty OFF mesh's header).
        if (::ftruncate(fd, off_t(header.size() + body_bytes)) != 0)
            throw io_error("cannot write '" + target + "': " + std::strerror(errno) +
                           " (while setting the file's size)");
    });
}

/// Every rank's sections through rank 0, which writes them into `file` in
/// file order (section by section, rank by rank); the other ranks send
/// theirs in chunks. Returns this rank's error, or "": a rank that fails
/// stops sending and says so, and rank 0 stops reading from it.
std::string send_through_root(const Sections& sections, const std::string& header, RankGroup& group,
                              AtomicFileWriter* file) {
    std::string error;
    if (group.rank() != 0) {
        for (const auto& section : sections) {
            if (error.empty())
                error = error_of([&] {
                    section->read_back(
                        [&](const char* data, std::size_t n) { group.send_to_root(kData + std::string(data, n)); });
                });
            group.send_to_root(std::string(1, error.empty() ? kEnd : kFailed));
        }
        return error;
    }
    error = error_of([&] { file->append(header); });
    for (const auto& section : sections)
        for (int r = 0; r < group.size(); ++r) {
            if (r == 0) {
                if (error.empty()) error = error_of([&] { section->copy_into(*file); });
                continue;
            }
            for (std::string m = group.receive_from(r); !m.empty() && m[0] == kData; m = group.receive_from(r))
                if (error.empty()) error = error_of([&] { file->append(m.data() + 1, m.size() - 1); });
        }
    return error;
}

}  // namespace

void MeshStreamWriter::finish(RankGroup& group, PartTransfer transfer) {
    if (group.size() == 1) return finish();
    Impl& s = *impl_;
    const bool root = group.rank() == 0;
    s.rank_part = false;

    PartInfo mine;
    mine.broken = s.broken;
    mine.points = s.points, mine.triangles = s.triangles, mine.quads = s.quads;
    mine.triangle_range = s.triangle_range, mine.quad_range = s.quad_range;
    mine.format = std::uint64_t(s.format), mine.normals = s.normals, mine.precision = std::uint64_t(s.options.precision);
    mine.section_count = s.sections.size();
    for (std::size_t k = 0; k < s.sections.size() && !s.broken; ++k) mine.section_bytes[k] = s.sections[k]->position();
    s.broken = true;  // whatever happens below, this writer is done
    const std::vector<PartInfo> parts = detail::all_gather_values(group, std::vector<PartInfo>{mine}, kParts);

    for (std::size_t r = 0; r < parts.size(); ++r)
        if (parts[r].broken)
            throw io_error("cannot write '" + s.target + "': rank " + std::to_string(r) +
                           "'s part failed earlier; start it again");
    for (const PartInfo& p : parts)
        if (p.format != mine.format || p.normals != mine.normals || p.precision != mine.precision ||
            p.section_count != mine.section_count)
            throw std::logic_error("MeshStreamWriter::finish(group): the ranks' writers differ in format, "
                                   "precision or normals; every rank must open the same target with the same options");
    const Layout layout = lay_out(parts);
    s.points = layout.points, s.triangles = layout.triangles, s.quads = layout.quads;
    s.triangle_range = whole_range(parts, true);
    s.quad_range = whole_range(parts, false);
    s.check_indices();  // the same verdict on every rank

    if (s.format == MeshFormat::stl) {  // facets need every corner: only rank 0 may hold pieces
        for (std::size_t r = 1; r < parts.size(); ++r)
            if (parts[r].points + parts[r].triangles + parts[r].quads > 0)
                throw std::logic_error("MeshStreamWriter::finish(group): STL pieces must all be on rank 0");
        std::string error;
        if (root) {
            s.broken = false;
            error = error_of([&] { finish(); });
        }
        return agree(group, error, [] {});
    }

    // Rank 0 creates the file and tells the others where it is.
    std::unique_ptr<AtomicFileWriter> file;
    std::string header;
    FileTicket ticket;
    if (root) {
        ticket.error = error_of([&] {
            header = s.header();
            // Named: the other ranks open the temporary by its name.
            file = transfer == PartTransfer::shared_file
                       ? std::make_unique<AtomicFileWriter>(s.path, AtomicFileWriter::Named{})
                       : std::make_unique<AtomicFileWriter>(s.path);
            ticket.header_bytes = header.size();
            if (transfer == PartTransfer::shared_file && !file->temp_path().empty()) {
                ticket.token = random_token();
                const int fd = file->flushed_descriptor();
                AtomicFileWriter::write_all_at(fd, ticket.token.data(), ticket.token.size(), 0, s.target);
                // On a network file system the other nodes read what the server holds.
                if (::fsync(fd) != 0)
                    throw io_error("cannot write '" + s.target + "': " + std::strerror(errno) +
                                   " (while flushing the new file to disk)");
                ticket.temp_path = file->temp_path();
            }
        });
    }
    ticket = decode(group.broadcast_from_root(root ? encode(ticket) : std::string()));
    if (!ticket.error.empty()) throw io_error(ticket.error);

    // Shared file when every rank sees rank 0's.
    SharedFile shared(ticket);
    const bool sees = root || shared.same();
    const std::vector<std::uint8_t> seen = detail::all_gather_values(group, std::vector<std::uint8_t>{sees}, kParts);
    bool all_see = !ticket.temp_path.empty();
    for (std::uint8_t v : seen) all_see = all_see && v;

    const auto discard = [&] { file.reset(); };
    const Sections& sections = s.sections;
    const std::string error =
        all_see ? write_in_place(sections, layout.offset[std::size_t(group.rank())], ticket, header,
                                 layout.body_bytes, root ? file.get() : nullptr, shared, s.target)
                : send_through_root(sections, header, group, file.get());
    agree(group, error, discard);
    agree(group, root ? error_of([&] { file->commit(); }) : std::string(), discard);
    s.sections.clear();
    if (root && s.options.progress) s.options.progress(1.0);
}

}  // namespace pqdc
