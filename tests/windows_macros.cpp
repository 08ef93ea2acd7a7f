// The library's entry points instantiated where windows.h's macros are defined, as in a
// renderer built without NOMINMAX: function-like min and max (std::min(a, b) then fails to
// parse, so the headers write (std::min)(a, b)) and empty near and far. The standard headers
// come first, as in such a renderer. Compiled (not run) with the header checks' flags; see
// tests/CMakeLists.txt.
#include <algorithm>
#include <array>
#include <atomic>
#include <cfloat>
#include <chrono>
#include <climits>
#include <cmath>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <numeric>
#include <string>
#include <system_error>
#include <thread>
#include <type_traits>
#include <unordered_map>
#include <utility>
#include <vector>
#if defined(__SSE2__) || defined(_M_X64)
#include <emmintrin.h>
#endif
#if defined(__ARM_NEON) || defined(__aarch64__)
#include <arm_neon.h>
#endif

#define min(a, b) (((a) < (b)) ? (a) : (b))
#define max(a, b) (((a) > (b)) ? (a) : (b))
#define near
#define far

#define FIREFLY_GLOBAL_NAMES_TU firefly_windows_macros_tu
#include "global_names.cpp"
