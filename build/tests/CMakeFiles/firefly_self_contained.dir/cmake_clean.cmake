file(REMOVE_RECURSE
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_bound_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_bound_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_esd_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_esd_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_firefly_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_firefly_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_glm_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_glm_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_highlight_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_highlight_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_image_view_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_image_view_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_parallel_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_parallel_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_pipeline_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_pipeline_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_reconstruct_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_reconstruct_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_sim_metrics_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_sim_metrics_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_sim_scene_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_sim_scene_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_statistics_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_statistics_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_status_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_status_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_stddev_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_stddev_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_student_t_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_student_t_hpp.cpp.o.d"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_version_hpp.cpp.o"
  "CMakeFiles/firefly_self_contained.dir/self_contained/firefly_version_hpp.cpp.o.d"
)

# Per-language clean rules from dependency scanning.
foreach(lang CXX)
  include(CMakeFiles/firefly_self_contained.dir/cmake_clean_${lang}.cmake OPTIONAL)
endforeach()
