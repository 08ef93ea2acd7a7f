// libFuzzer target: the PFM reader the command-line tool uses (firefly_tools::parse_pfm, the
// in-memory half of read_pfm). Any input must give an image or a message, never a crash or
// an allocation beyond the bytes present; an accepted image must match its header.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "pfm.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    firefly_tools::pfm_image img;
    const std::string e = firefly_tools::parse_pfm(data, size, "fuzz", img);
    if (!e.empty()) return 0;
    const std::size_t n = static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.height) *
                          static_cast<std::size_t>(img.channels);
    // Accepted: the sizes agree, and the data is exactly the file's tail.
    if (img.width < 1 || img.height < 1 || (img.channels != 1 && img.channels != 3) || img.pixels.size() != n ||
        n * 4 > size)
        std::abort();
    return 0;
}
