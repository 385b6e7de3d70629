// pqdc::RankGroup over an MPI communicator (Open MPI from Debian): the only
// transport code in pqdc.
#pragma once

#include "pqdc/distributed.hpp"

#include <mpi.h>

#include <string>
#include <vector>

namespace pqdc_mpi {

class MpiRankGroup : public pqdc::RankGroup {
public:
    explicit MpiRankGroup(MPI_Comm comm);
    int rank() const override { return rank_; }
    int size() const override { return size_; }
    /// MPI_Gather of the part sizes, then each part sent to rank 0 in
    /// chunks of at most 1 GiB (MPI counts are ints), received in rank order.
    std::vector<std::string> gather_at_root(std::string part) override;
    /// MPI_Bcast of the size, then of the bytes in chunks of at most 1 GiB.
    std::string broadcast_from_root(std::string value) override;
    /// The size, then the bytes in chunks, on a tag of their own.
    void send_to_root(std::string message) override;
    std::string receive_from(int from) override;

private:
    MPI_Comm comm_;
    int rank_ = 0, size_ = 1;
};

}  // namespace pqdc_mpi
