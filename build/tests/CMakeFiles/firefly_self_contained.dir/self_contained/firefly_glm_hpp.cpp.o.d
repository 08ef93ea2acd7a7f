tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_glm_hpp.cpp.o: \
 /work/main/build/tests/self_contained/firefly_glm_hpp.cpp \
 /usr/include/stdc-predef.h /work/main/include/firefly/glm.hpp \
 /usr/include/glm/vec3.hpp /usr/include/glm/ext/vector_bool3.hpp \
 /usr/include/glm/detail/type_vec3.hpp \
 /usr/include/glm/detail/qualifier.hpp /usr/include/glm/detail/setup.hpp \
 /usr/include/c++/12/cassert \
 /usr/include/x86_64-linux-gnu/c++/12/bits/c++config.h \
 /usr/include/x86_64-linux-gnu/c++/12/bits/os_defines.h \
 /usr/include/features.h /usr/include/features-time64.h \
 /usr/include/x86_64-linux-gnu/bits/wordsize.h \
 /usr/include/x86_64-linux-gnu/bits/timesize.h \
 /usr/include/x86_64-linux-gnu/sys/cdefs.h \
 /usr/include/x86_64-linux-gnu/bits/long-double.h \
 /usr/include/x86_64-linux-gnu/gnu/stubs.h \
 /usr/include/x86_64-linux-gnu/gnu/stubs-64.h \
 /usr/include/x86_64-linux-gnu/c++/12/bits/cpu_defines.h \
 /usr/include/c++/12/pstl/pstl_config.h /usr/include/assert.h \
 /usr/include/c++/12/cstddef \
 /usr/lib/gcc/x86_64-linux-gnu/12/include/stddef.h \
 /usr/include/glm/simd/platform.h /usr/include/c++/12/cstdint \
 /usr/lib/gcc/x86_64-linux-gnu/12/include/stdint.h /usr/include/stdint.h \
 /usr/include/x86_64-linux-gnu/bits/libc-header-start.h \
 /usr/include/x86_64-linux-gnu/bits/types.h \
 /usr/include/x86_64-linux-gnu/bits/typesizes.h \
 /usr/include/x86_64-linux-gnu/bits/time64.h \
 /usr/include/x86_64-linux-gnu/bits/wchar.h \
 /usr/include/x86_64-linux-gnu/bits/stdint-intn.h \
 /usr/include/x86_64-linux-gnu/bits/stdint-uintn.h \
 /usr/include/c++/12/type_traits /usr/include/glm/detail/type_vec3.inl \
 /usr/include/glm/detail/compute_vector_relational.hpp \
 /usr/include/c++/12/limits \
 /usr/include/glm/ext/vector_bool3_precision.hpp \
 /usr/include/glm/ext/vector_float3.hpp \
 /usr/include/glm/ext/vector_float3_precision.hpp \
 /usr/include/glm/ext/vector_double3.hpp \
 /usr/include/glm/ext/vector_double3_precision.hpp \
 /usr/include/glm/ext/vector_int3.hpp \
 /usr/include/glm/ext/vector_int3_sized.hpp \
 /usr/include/glm/ext/scalar_int_sized.hpp \
 /usr/include/glm/detail/setup.hpp /usr/include/glm/ext/vector_uint3.hpp \
 /usr/include/glm/ext/vector_uint3_sized.hpp \
 /usr/include/glm/ext/scalar_uint_sized.hpp /usr/include/glm/vec4.hpp \
 /usr/include/glm/ext/vector_bool4.hpp \
 /usr/include/glm/detail/type_vec4.hpp \
 /usr/include/glm/detail/type_vec4.inl \
 /usr/include/glm/ext/vector_bool4_precision.hpp \
 /usr/include/glm/ext/vector_float4.hpp \
 /usr/include/glm/ext/vector_float4_precision.hpp \
 /usr/include/glm/ext/vector_double4.hpp \
 /usr/include/glm/ext/vector_double4_precision.hpp \
 /usr/include/glm/ext/vector_int4.hpp \
 /usr/include/glm/ext/vector_int4_sized.hpp \
 /usr/include/glm/ext/vector_uint4.hpp \
 /usr/include/glm/ext/vector_uint4_sized.hpp \
 /work/main/include/firefly/image_view.hpp \
 /work/main/include/firefly/status.hpp /usr/include/c++/12/utility \
 /usr/include/c++/12/bits/stl_relops.h \
 /usr/include/c++/12/bits/stl_pair.h /usr/include/c++/12/bits/move.h \
 /usr/include/c++/12/bits/utility.h /usr/include/c++/12/initializer_list
