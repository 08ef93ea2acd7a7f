# Builds firefly's unit tests for aarch64 with a cross compiler and runs them under qemu-user:
# the NEON kernels (stddev.hpp) and a target where the compiler may fuse any multiply and add
# (GCC's default in gnu++ modes) must give what the tests ask on x86-64, bit-exact invariants
# included.
cmake_minimum_required(VERSION 3.16)
file(REMOVE_RECURSE "${WORK}")
file(MAKE_DIRECTORY "${WORK}/include/catch2")
file(COPY "${CATCH2}" DESTINATION "${WORK}/include/catch2")  # the header alone, not the host's /usr/include

include("${CMAKE_CURRENT_LIST_DIR}/check_run.cmake")

run(${CXX} -std=gnu++17 -O2 -Wall -Wextra -I "${INCLUDE}" -I "${WORK}/include"
    "-DFIREFLY_TEST_DATA=\"${DATA}\"" "-DFIREFLY_SHARED_DATA=\"${SHARED_DATA}\""
    ${SOURCES} -o "${WORK}/firefly_tests" -pthread)
execute_process(COMMAND "${CMAKE_COMMAND}" -E env "QEMU_LD_PREFIX=${SYSROOT}" "${QEMU}" "${WORK}/firefly_tests"
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
string(REGEX MATCH "All tests passed[^\n]*|test cases:[^\n]*" summary "${out}")
message("aarch64: ${summary}")
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "the unit tests failed on aarch64 (${rc})\n${out}\n${err}")
endif()
