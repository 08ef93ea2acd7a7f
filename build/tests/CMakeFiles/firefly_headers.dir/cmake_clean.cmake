file(REMOVE_RECURSE
  "CMakeFiles/firefly_headers"
)

# Per-language clean rules from dependency scanning.
foreach(lang )
  include(CMakeFiles/firefly_headers.dir/cmake_clean_${lang}.cmake OPTIONAL)
endforeach()
