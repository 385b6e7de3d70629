#include "mpi_rank_group.hpp"

#include <algorithm>
#include <cstdint>
#include <stdexcept>

namespace pqdc_mpi {
namespace {

constexpr std::size_t kChunkBytes = std::size_t(1) << 30;
constexpr int kPartTag = 14;
constexpr int kMessageTag = 15;

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

std::string MpiRankGroup::broadcast_from_root(std::string value) {
    auto size = std::uint64_t(value.size());
    check(MPI_Bcast(&size, 1, MPI_UINT64_T, 0, comm_), "Bcast");
    value.resize(std::size_t(size));
    for (std::size_t at = 0; at < value.size(); at += kChunkBytes)
        check(MPI_Bcast(value.data() + at, int(std::min(kChunkBytes, value.size() - at)), MPI_BYTE, 0, comm_), "Bcast");
    return value;
}

void MpiRankGroup::send_to_root(std::string message) {
    const auto size = std::uint64_t(message.size());
    check(MPI_Send(&size, 1, MPI_UINT64_T, 0, kMessageTag, comm_), "Send");
    for (std::size_t at = 0; at < message.size(); at += kChunkBytes)
        check(MPI_Send(message.data() + at, int(std::min(kChunkBytes, message.size() - at)), MPI_BYTE, 0, kMessageTag,
                       comm_),
              "Send");
}

std::string MpiRankGroup::receive_from(int from) {
    std::uint64_t size = 0;
    check(MPI_Recv(&size, 1, MPI_UINT64_T, from, kMessageTag, comm_, MPI_STATUS_IGNORE), "Recv");
    std::string message(std::size_t(size), '\0');
    for (std::size_t at = 0; at < message.size(); at += kChunkBytes)
        check(MPI_Recv(message.data() + at, int(std::min(kChunkBytes, message.size() - at)), MPI_BYTE, from,
                       kMessageTag, comm_, MPI_STATUS_IGNORE),
              "Recv");
    return message;
}

}  // namespace pqdc_mpi
