#include "pqdc/file_io.hpp"

#include "io/atomic_file.hpp"

namespace pqdc {

void write_file(const std::string& path, std::string_view bytes) {
    detail::AtomicFileWriter out(path);
    out.append(bytes);
    out.commit();
}

}  // namespace pqdc
