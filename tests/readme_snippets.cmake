# The README's C++ examples compile as written: each ```cpp block becomes the body of a
# function whose parameters declare what the block takes from its surroundings (the
# renderer's buffers, sizes, options). A block added to the README without its declarations
# here stops the configure with a message, so an example can neither drift nor go unchecked.
# Included from tests/CMakeLists.txt; defines firefly_readme_snippets (an object library).

set(_readme "${PROJECT_SOURCE_DIR}/README.md")
set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS "${_readme}")
file(READ "${_readme}" _text)

# What each block, in README order, takes from its surroundings.
set(_context_1 "#include <cstdio>
void readme_snippet_1(float* a_rgb, float* a_var, float* b_rgb, float* b_var, int w, int h) {")
set(_context_2 "#include <vector>
void readme_snippet_2(std::vector<std::vector<float>>& renders, int w, int h) {")
set(_context_3 "#include \"half_float.hpp\"
using half = firefly_examples::half16;  // a renderer's 16-bit float, with its channel_traits
struct readme_jobs {
    void parallel_for(std::size_t n, const firefly::executor::task& t) { for (std::size_t i = 0; i < n; ++i) t(i); }
};
void log(const char* message);
void readme_snippet_3(float* a_planes, half* a_var_planes, float* b_rgba, half* b_var, float* fb, int w, int h,
                      int fb_width, int fb_height, int x0, int y0, int tw, int th,
                      const firefly::detector_options& options, readme_jobs& my_jobs,
                      const firefly::image_view<std::uint8_t>& mask_a, const firefly::image_view<std::uint8_t>& mask_b) {")
set(_blocks 3)

set(_sources "")
set(_n 0)
set(_open "```cpp\n")
string(FIND "${_text}" "${_open}" _at)
while(_at GREATER -1)
  math(EXPR _n "${_n} + 1")
  math(EXPR _start "${_at} + 7")
  string(SUBSTRING "${_text}" ${_start} -1 _text)
  string(FIND "${_text}" "\n```" _end)
  if(_end EQUAL -1)
    message(FATAL_ERROR "README.md: C++ block ${_n} is not closed")
  endif()
  string(SUBSTRING "${_text}" 0 ${_end} _body)
  if(NOT DEFINED _context_${_n})
    message(FATAL_ERROR "README.md has a C++ block ${_n} that tests/readme_snippets.cmake does not declare: "
                        "add _context_${_n} (what the block takes from its surroundings) and raise _blocks")
  endif()
  # firefly.hpp first: the block's own #include of it is then empty (#pragma once).
  set(_tu "${CMAKE_CURRENT_BINARY_DIR}/readme_snippets/snippet_${_n}.cpp")
  file(WRITE "${_tu}.in" "#include <firefly/firefly.hpp>\n${_context_${_n}}\n${_body}\n}\n")
  configure_file("${_tu}.in" "${_tu}" COPYONLY)
  list(APPEND _sources "${_tu}")
  string(FIND "${_text}" "${_open}" _at)
endwhile()
if(NOT _n EQUAL _blocks)
  message(FATAL_ERROR "README.md has ${_n} C++ blocks where tests/readme_snippets.cmake declares ${_blocks}")
endif()

add_library(firefly_readme_snippets OBJECT ${_sources})
target_link_libraries(firefly_readme_snippets PRIVATE firefly::firefly)
target_include_directories(firefly_readme_snippets PRIVATE "${PROJECT_SOURCE_DIR}/examples")
# Examples declare what they show and may leave it unused (a tile view, a report); they and
# the headers they instantiate meet -Wsign-conversion (which the unit tests turn off) and
# -Wdouble-promotion.
target_compile_options(firefly_readme_snippets PRIVATE ${FIREFLY_WARNINGS} -Wsign-conversion -Wdouble-promotion -Werror
                       -fno-exceptions -Wno-unused-variable -Wno-unused-but-set-variable
                       -Wno-unused-parameter)
add_custom_target(firefly_readme_examples ALL DEPENDS firefly_readme_snippets)
