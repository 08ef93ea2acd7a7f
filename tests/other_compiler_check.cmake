# Builds firefly's header checks and unit tests with a second compiler (Clang where the tests
# are built with GCC, GCC where they are built with Clang) and runs them: the compilers differ
# in their warnings and in what they fuse into multiply-add (Clang contracts within an
# expression by default and does not define __FP_FAST_FMA), and a user may take either.
cmake_minimum_required(VERSION 3.16)
file(REMOVE_RECURSE "${WORK}")

include("${CMAKE_CURRENT_LIST_DIR}/check_run.cmake")

run(${CMAKE_COMMAND} -S "${FIREFLY_SOURCE}" -B "${WORK}" -G "${GENERATOR}" -DCMAKE_CXX_COMPILER=${OTHER_CXX}
    -DCMAKE_BUILD_TYPE=Release -DFIREFLY_BUILD_TESTS=ON -DFIREFLY_BUILD_BENCHMARKS=OFF
    -DFIREFLY_BUILD_EXAMPLES=OFF -DFIREFLY_BUILD_PYTHON=OFF -DFIREFLY_INSTALL=OFF
    -DFIREFLY_SHARED_DATA=${SHARED_DATA} "-DCMAKE_CXX_FLAGS=${FLAGS}")
# every header on its own with warnings as errors, and the unit tests (their bit-exact
# invariants: flips, transposes, layouts, executors), where the host has FMA with fusing
# across statements (-mfma -ffp-contract=fast), the most a compiler may contract
run(${CMAKE_COMMAND} --build "${WORK}" --parallel 2 --target firefly_self_contained firefly_tests)
run("${WORK}/tests/firefly_tests")
