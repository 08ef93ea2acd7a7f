file(REMOVE_RECURSE
  "CMakeFiles/firefly_tests.dir/test_esd.cpp.o"
  "CMakeFiles/firefly_tests.dir/test_esd.cpp.o.d"
  "CMakeFiles/firefly_tests.dir/test_glm.cpp.o"
  "CMakeFiles/firefly_tests.dir/test_glm.cpp.o.d"
  "CMakeFiles/firefly_tests.dir/test_image_view.cpp.o"
  "CMakeFiles/firefly_tests.dir/test_image_view.cpp.o.d"
  "CMakeFiles/firefly_tests.dir/test_pipeline.cpp.o"
  "CMakeFiles/firefly_tests.dir/test_pipeline.cpp.o.d"
  "CMakeFiles/firefly_tests.dir/test_reconstruct.cpp.o"
  "CMakeFiles/firefly_tests.dir/test_reconstruct.cpp.o.d"
  "CMakeFiles/firefly_tests.dir/test_sim.cpp.o"
  "CMakeFiles/firefly_tests.dir/test_sim.cpp.o.d"
  "CMakeFiles/firefly_tests.dir/test_student_t.cpp.o"
  "CMakeFiles/firefly_tests.dir/test_student_t.cpp.o.d"
  "firefly_tests"
  "firefly_tests.pdb"
)

# Per-language clean rules from dependency scanning.
foreach(lang CXX)
  include(CMakeFiles/firefly_tests.dir/cmake_clean_${lang}.cmake OPTIONAL)
endforeach()
