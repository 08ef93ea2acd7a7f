
# Consider dependencies only in project.
set(CMAKE_DEPENDS_IN_PROJECT_ONLY OFF)

# The set of languages for which implicit dependencies are needed:
set(CMAKE_DEPENDS_LANGUAGES
  )

# The set of dependency files which are needed:
set(CMAKE_DEPENDS_DEPENDENCY_FILES
  "/work/main/tests/test_esd.cpp" "tests/CMakeFiles/firefly_tests.dir/test_esd.cpp.o" "gcc" "tests/CMakeFiles/firefly_tests.dir/test_esd.cpp.o.d"
  "/work/main/tests/test_glm.cpp" "tests/CMakeFiles/firefly_tests.dir/test_glm.cpp.o" "gcc" "tests/CMakeFiles/firefly_tests.dir/test_glm.cpp.o.d"
  "/work/main/tests/test_image_view.cpp" "tests/CMakeFiles/firefly_tests.dir/test_image_view.cpp.o" "gcc" "tests/CMakeFiles/firefly_tests.dir/test_image_view.cpp.o.d"
  "/work/main/tests/test_pipeline.cpp" "tests/CMakeFiles/firefly_tests.dir/test_pipeline.cpp.o" "gcc" "tests/CMakeFiles/firefly_tests.dir/test_pipeline.cpp.o.d"
  "/work/main/tests/test_reconstruct.cpp" "tests/CMakeFiles/firefly_tests.dir/test_reconstruct.cpp.o" "gcc" "tests/CMakeFiles/firefly_tests.dir/test_reconstruct.cpp.o.d"
  "/work/main/tests/test_sim.cpp" "tests/CMakeFiles/firefly_tests.dir/test_sim.cpp.o" "gcc" "tests/CMakeFiles/firefly_tests.dir/test_sim.cpp.o.d"
  "/work/main/tests/test_student_t.cpp" "tests/CMakeFiles/firefly_tests.dir/test_student_t.cpp.o" "gcc" "tests/CMakeFiles/firefly_tests.dir/test_student_t.cpp.o.d"
  )

# Targets to which this target links.
set(CMAKE_TARGET_LINKED_INFO_FILES
  )

# Fortran module output directory.
set(CMAKE_Fortran_TARGET_MODULE_DIR "")
