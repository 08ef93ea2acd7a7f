tests/CMakeFiles/firefly_self_contained.dir/self_contained/firefly_version_hpp.cpp.o: \
 /work/main/build/tests/self_contained/firefly_version_hpp.cpp \
 /usr/include/stdc-predef.h /work/main/include/firefly/version.hpp
