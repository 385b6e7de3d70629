#include "mpi_rank_group.hpp"

#include <algorithm>
#include <cstdint>
#include <stdexcept>

namespace pqdc_mpi {
namespace {

constexpr std::size_t kChunkBytes = std::size_t(1) << 30;
constexpr int kPartTag = 14;

void check(int code, const char* what) {
    if (code == MPI_SUCCESS) return;
    char text[MPI_MAX_ERROR_STRING];
    int length = 0;
    MPI_Error_string(code, text, &length);
    throw std::runtime_error(std::string("MPI ") + what + " failed: " + std::string(text, std::size_t(length)));
}

}  // namespace

MpiRankGroup::MpiRankGroup(MPI_Comm comm) : comm_(comm) {
    check(MPI_Comm_rank(comm_, &rank_), "Comm_rank");
    check(MPI_Comm_size(comm_, &size_), "Comm_size");
}

std::vector<std::string> MpiRankGroup::gather_at_root(std::string part) {
    const auto mine = std::uint64_t(part.size());
    std::vector<std::uint64_t> sizes(rank_ == 0 ? std::size_t(size_) : 0);
    check(MPI_Gather(&mine, 1, MPI_UINT64_T, sizes.data(), 1, MPI_UINT64_T, 0, comm_), "Gather");
    if (rank_ != 0) {
        for (std::size_t at = 0; at < part.size(); at += kChunkBytes)
            check(MPI_Send(part.data() + at, int(std::min(kChunkBytes, part.size() - at)), MPI_BYTE, 0, kPartTag,
                           comm_),
                  "Send");
        return {};
    }
    std::vector<std::string> parts(static_cast<std::size_t>(size_));
    parts[0] = std::move(part);
    for (int r = 1; r < size_; ++r) {
        std::string& p = parts[std::size_t(r)];
        p.resize(std::size_t(sizes[std::size_t(r)]));
        for (std::size_t at = 0; at < p.size(); at += kChunkBytes)
            check(MPI_Recv(p.data() + at, int(std::min(kChunkBytes, p.size() - at)), MPI_BYTE, r, kPartTag, comm_,
                           MPI_STATUS_IGNORE),
                  "Recv");
    }
    return parts;
}

}  // namespace pqdc_mpi
