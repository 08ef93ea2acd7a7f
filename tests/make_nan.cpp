// Writes a 16x8 PFM whose every value is NaN (for the command-line checks).
#include <limits>
#include <vector>

#include "../examples/pfm.hpp"

int main(int argc, char** argv) {
    if (argc != 2) return 2;
    firefly_tools::pfm_image img;
    img.width = 16;
    img.height = 8;
    img.channels = 3;
    img.pixels.assign(16 * 8 * 3, std::numeric_limits<float>::quiet_NaN());
    return firefly_tools::write_pfm(argv[1], img).empty() ? 0 : 1;
}
