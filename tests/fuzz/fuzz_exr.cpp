// libFuzzer target: the EXR reading path of the command-line tool, in memory: an Imf::IStream
// over the fuzz bytes, through firefly_tools::read_exr (the function the file reader calls).
// Any input must give an image or a message: no crash, no uncaught exception, no allocation
// the file's size does not justify.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "image_io.hpp"

namespace {

// Reads from a byte range; end of data throws, as Imf::StdIFStream does.
class memory_istream : public Imf::IStream {
public:
    memory_istream(const std::uint8_t* data, std::size_t size) : Imf::IStream("fuzz.exr"), data_(data), size_(size) {}
    bool read(char c[], int n) override {
        if (n < 0 || static_cast<std::uint64_t>(n) > size_ - pos_) throw std::runtime_error("unexpected end of file");
        std::memcpy(c, data_ + pos_, static_cast<std::size_t>(n));
        pos_ += static_cast<std::uint64_t>(n);
        return pos_ < size_;
    }
    uint64_t tellg() override { return pos_; }
    void seekg(uint64_t pos) override {
        if (pos > size_) throw std::runtime_error("seek past the end");
        pos_ = pos;
    }

private:
    const std::uint8_t* data_;
    std::uint64_t size_, pos_ = 0;
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    // The channel sets the tool asks for: colour + variance (+ alpha), colour + one variance,
    // and a multi-part file's channels named with their parts' names.
    static const std::vector<std::string> sets[] = {
        {"R", "G", "B", "Variance.R", "Variance.G", "Variance.B", "A"},
        {"R", "G", "B", "Variance.R", "Variance.G", "Variance.B"},
        {"R", "G", "B", "Variance"},
        {"beauty.R", "beauty.G", "beauty.B", "variance.R", "variance.G", "variance.B", "beauty.A"},
    };
    for (const auto& names : sets) {
        memory_istream in(data, size);
        firefly_tools::image img;
        const std::string e = firefly_tools::read_exr(in, size, "fuzz.exr", names, img);
        if (!e.empty()) continue;
        const std::size_t n = static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.height) * names.size();
        if (img.width < 1 || img.height < 1 || img.pixels.size() != n || img.channels != names)
            std::abort();
        return 0;
    }
    return 0;
}
