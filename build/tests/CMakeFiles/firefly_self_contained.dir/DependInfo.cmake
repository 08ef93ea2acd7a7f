
# Consider dependencies only in project.
set(CMAKE_DEPENDS_IN_PROJECT_ONLY OFF)

# The set of languages for which implicit dependencies are needed:
set(CMAKE_DEPENDS_LANGUAGES
  )

# The set of dependency files which are needed:
set(CMAKE_DEPENDS_DEPENDENCY_FILES
  "/work/main/build/tests/self_contained/firefly_bound_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_bound_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_bound_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_esd_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_esd_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_esd_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_firefly_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_firefly_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_firefly_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_glm_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_glm_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_glm_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_highlight_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_highlight_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_highlight_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_image_view_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_image_view_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_image_view_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_parallel_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_parallel_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_parallel_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_pipeline_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_pipeline_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_pipeline_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_reconstruct_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_reconstruct_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_reconstruct_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_sim_metrics_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_sim_metrics_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_sim_metrics_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_sim_scene_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_sim_scene_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_sim_scene_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_statistics_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_statistics_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_statistics_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_status_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_status_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_status_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_stddev_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_stddev_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_stddev_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_student_t_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_student_t_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_student_t_hpp.cpp.o.d"
  "/work/main/build/tests/self_contained/firefly_version_hpp.cpp" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_version_hpp.cpp.o" "gcc" "tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_version_hpp.cpp.o.d"
  )

# Targets to which this target links.
set(CMAKE_TARGET_LINKED_INFO_FILES
  )

# Fortran module output directory.
set(CMAKE_Fortran_TARGET_MODULE_DIR "")
