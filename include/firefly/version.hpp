// firefly: version, written once here; CMake parses these three lines.
#pragma once

#define FIREFLY_VERSION_MAJOR 0
#define FIREFLY_VERSION_MINOR 1
#define FIREFLY_VERSION_PATCH 0

#define FIREFLY_VERSION \
    (FIREFLY_VERSION_MAJOR * 10000 + FIREFLY_VERSION_MINOR * 100 + FIREFLY_VERSION_PATCH)
