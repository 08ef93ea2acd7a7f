# Builds tests/consumer as a user would: against an installed firefly (find_package), through
# add_subdirectory, or by dropping include/firefly into a code base and compiling by hand; and
# checks that a translation unit built with -ffast-math is refused (fast_math).
cmake_minimum_required(VERSION 3.16)
file(REMOVE_RECURSE "${WORK}")
file(MAKE_DIRECTORY "${WORK}")

include("${CMAKE_CURRENT_LIST_DIR}/check_run.cmake")

if(MODE STREQUAL "find_package")
  # Install firefly alone (no tests, benchmarks or examples) to a temporary prefix.
  # Configured for one prefix, installed to another (`cmake --install --prefix`): what is
  # installed must not name the first.
  run(${CMAKE_COMMAND} -S "${FIREFLY_SOURCE}" -B "${WORK}/firefly-build" -G "${GENERATOR}"
      -DCMAKE_INSTALL_PREFIX=${WORK}/configured-prefix -DFIREFLY_BUILD_TESTS=OFF
      -DFIREFLY_BUILD_BENCHMARKS=OFF -DFIREFLY_BUILD_EXAMPLES=OFF -DFIREFLY_INSTALL=ON)
  # The headers install from a tree configured but not built (the README's command), then
  # again once it is built (with the Python module where pybind11 is found).
  run(${CMAKE_COMMAND} --install "${WORK}/firefly-build" --prefix "${WORK}/prefix")
  run(${CMAKE_COMMAND} --build "${WORK}/firefly-build")
  run(${CMAKE_COMMAND} --install "${WORK}/firefly-build" --prefix "${WORK}/prefix")
  foreach(f include/firefly/firefly.hpp share/cmake/firefly/fireflyConfig.cmake
            share/cmake/firefly/fireflyConfigVersion.cmake share/pkgconfig/firefly.pc)
    if(NOT EXISTS "${WORK}/prefix/${f}")
      message(FATAL_ERROR "not installed: ${f}")
    endif()
  endforeach()
  run(${CMAKE_COMMAND} -S "${CONSUMER}" -B "${WORK}/consumer-build" -G "${GENERATOR}"
      -DCMAKE_CXX_COMPILER=${CXX} -DCONSUMER_MODE=find_package -DCMAKE_PREFIX_PATH=${WORK}/prefix)
  run(${CMAKE_COMMAND} --build "${WORK}/consumer-build")
  run("${WORK}/consumer-build/consumer")
  # An incompatible version must be refused: another major, and before 1.0 another minor.
  foreach(v 99 0.0.5)  # 0.1.0 is neither 99.x nor, before 1.0, 0.0.x
    execute_process(COMMAND ${CMAKE_COMMAND} -S "${CONSUMER}" -B "${WORK}/consumer-v${v}" -G "${GENERATOR}"
        -DCONSUMER_MODE=find_package -DCONSUMER_VERSION=${v} -DCMAKE_PREFIX_PATH=${WORK}/prefix
        RESULT_VARIABLE rc OUTPUT_QUIET ERROR_VARIABLE err)
    if(rc EQUAL 0 OR NOT err MATCHES "considered but not accepted")  # refused for its version, not another error
      message(FATAL_ERROR "find_package(firefly ${v}) not refused for its version (${rc}):\n${err}")
    endif()
  endforeach()
  # The README's call, find_package(firefly 0.1), takes it.
  run(${CMAKE_COMMAND} -S "${CONSUMER}" -B "${WORK}/consumer-v0.1" -G "${GENERATOR}"
      -DCMAKE_CXX_COMPILER=${CXX} -DCONSUMER_MODE=find_package -DCONSUMER_VERSION=0.1 -DCMAKE_PREFIX_PATH=${WORK}/prefix)
  # The target carries the threads std::thread needs (-pthread on glibc before 2.34).
  file(READ "${WORK}/prefix/share/cmake/firefly/fireflyTargets.cmake" targets)
  if(NOT targets MATCHES "Threads::Threads")
    message(FATAL_ERROR "firefly::firefly does not carry Threads::Threads")
  endif()
  # pkg-config users get the installed include path, and it builds the consumer.
  file(READ "${WORK}/prefix/share/pkgconfig/firefly.pc" pc)
  if(NOT pc MATCHES "Cflags: -I" OR NOT pc MATCHES "Libs: -pthread" OR pc MATCHES "configured-prefix")
    message(FATAL_ERROR "firefly.pc names no include path, or the configured prefix:\n${pc}")
  endif()
  find_program(PKG_CONFIG pkg-config)
  if(PKG_CONFIG)
    set(ENV{PKG_CONFIG_PATH} "${WORK}/prefix/share/pkgconfig")
    execute_process(COMMAND ${PKG_CONFIG} --cflags firefly OUTPUT_VARIABLE cflags RESULT_VARIABLE rc
                    OUTPUT_STRIP_TRAILING_WHITESPACE)
    separate_arguments(cflags UNIX_COMMAND "${cflags}")
    if(NOT rc EQUAL 0)
      message(FATAL_ERROR "pkg-config --cflags firefly failed")
    endif()
    # The user's standard is theirs: a -std= in the flags, coming after it, took C++20 away.
    if(cflags MATCHES "-std=")
      message(FATAL_ERROR "pkg-config --cflags firefly sets the language standard: ${cflags}")
    endif()
    run(${CXX} -std=c++20 ${cflags} -fsyntax-only "${CONSUMER}/main.cpp")
  endif()
elseif(MODE STREQUAL "add_subdirectory")
  run(${CMAKE_COMMAND} -S "${CONSUMER}" -B "${WORK}/consumer-build" -G "${GENERATOR}"
      -DCMAKE_CXX_COMPILER=${CXX} -DCONSUMER_MODE=add_subdirectory -DFIREFLY_SOURCE=${FIREFLY_SOURCE})
  run(${CMAKE_COMMAND} --build "${WORK}/consumer-build")
  run("${WORK}/consumer-build/consumer")
  # The consumer's build must not contain any of firefly's own targets.
  if(EXISTS "${WORK}/consumer-build/firefly/tests" OR EXISTS "${WORK}/consumer-build/firefly/bench")
    message(FATAL_ERROR "add_subdirectory built firefly's tests or benchmarks")
  endif()
elseif(MODE STREQUAL "header_drop")
  file(COPY "${FIREFLY_SOURCE}/include/firefly" DESTINATION "${WORK}/vendor")
  run(${CXX} -std=c++17 -fno-exceptions -fno-rtti -Wall -Wextra -Wpedantic -Werror
      -I "${WORK}/vendor" "${CONSUMER}/main.cpp" -o "${WORK}/consumer" -pthread)
  run("${WORK}/consumer")
  foreach(std c++20 c++2b)  # later standards: the same headers, the same warnings
    run(${CXX} -std=${std} -fsyntax-only -fno-exceptions -fno-rtti -Wall -Wextra -Wpedantic -Werror
        -I "${WORK}/vendor" "${CONSUMER}/main.cpp")
  endforeach()
  # An older standard is refused first with what is needed, not with an error deep in a header.
  execute_process(COMMAND ${CXX} -std=c++14 -fsyntax-only -I "${WORK}/vendor" "${CONSUMER}/main.cpp"
                  RESULT_VARIABLE rc ERROR_VARIABLE err)
  string(FIND "${err}" "error:" first_error)
  string(FIND "${err}" "firefly needs C++17" needs)
  math(EXPR gap "${needs} - ${first_error}")
  if(rc EQUAL 0 OR needs EQUAL -1 OR gap LESS 0 OR gap GREATER 40)
    message(FATAL_ERROR "-std=c++14: not refused first with 'firefly needs C++17' (${rc})\n${err}")
  endif()
elseif(MODE STREQUAL "fast_math")
  # A translation unit built with -ffast-math is refused with the way out in the message
  # (floating_point.hpp), and builds when the user opts in with FIREFLY_ALLOW_FAST_MATH.
  foreach(flag -ffast-math -ffinite-math-only)
    execute_process(COMMAND ${CXX} -std=c++17 ${flag} -fsyntax-only -I "${FIREFLY_SOURCE}/include" "${CONSUMER}/main.cpp"
                    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
    if(rc EQUAL 0 OR NOT err MATCHES "FIREFLY_ALLOW_FAST_MATH")
      message(FATAL_ERROR "${flag}: not refused with the way out (${rc})\n${err}")
    endif()
    run(${CXX} -std=c++17 ${flag} -DFIREFLY_ALLOW_FAST_MATH -fsyntax-only -I "${FIREFLY_SOURCE}/include" "${CONSUMER}/main.cpp")
  endforeach()
else()
  message(FATAL_ERROR "unknown MODE ${MODE}")
endif()
