# CMake generated Testfile for 
# Source directory: /work/main/tests
# Build directory: /work/main/build/tests
# 
# This file includes the relevant testing commands required for 
# testing this directory and lists subdirectories to be tested as well.
add_test(unit "/work/main/build/tests/firefly_tests")
set_tests_properties(unit PROPERTIES  _BACKTRACE_TRIPLES "/work/main/tests/CMakeLists.txt;29;add_test;/work/main/tests/CMakeLists.txt;0;")
add_test(consumer_find_package "/usr/bin/cmake" "-DFIREFLY_SOURCE=/work/main" "-DCONSUMER=/work/main/tests/consumer" "-DWORK=/work/main/build/tests/consumer-work/installed" "-DMODE=find_package" "-DGENERATOR=Unix Makefiles" "-DCXX=/usr/bin/c++" "-P" "/work/main/tests/consumer_check.cmake")
set_tests_properties(consumer_find_package PROPERTIES  LABELS "consumer" _BACKTRACE_TRIPLES "/work/main/tests/CMakeLists.txt;56;add_test;/work/main/tests/CMakeLists.txt;0;")
add_test(consumer_add_subdirectory "/usr/bin/cmake" "-DFIREFLY_SOURCE=/work/main" "-DCONSUMER=/work/main/tests/consumer" "-DWORK=/work/main/build/tests/consumer-work/subdir" "-DMODE=add_subdirectory" "-DGENERATOR=Unix Makefiles" "-DCXX=/usr/bin/c++" "-P" "/work/main/tests/consumer_check.cmake")
set_tests_properties(consumer_add_subdirectory PROPERTIES  LABELS "consumer" _BACKTRACE_TRIPLES "/work/main/tests/CMakeLists.txt;61;add_test;/work/main/tests/CMakeLists.txt;0;")
add_test(consumer_header_drop "/usr/bin/cmake" "-DFIREFLY_SOURCE=/work/main" "-DCONSUMER=/work/main/tests/consumer" "-DWORK=/work/main/build/tests/consumer-work/drop" "-DMODE=header_drop" "-DCXX=/usr/bin/c++" "-P" "/work/main/tests/consumer_check.cmake")
set_tests_properties(consumer_header_drop PROPERTIES  LABELS "consumer" _BACKTRACE_TRIPLES "/work/main/tests/CMakeLists.txt;66;add_test;/work/main/tests/CMakeLists.txt;0;")
