#include <firefly/version.hpp>
#include <firefly/version.hpp>  // include guard
int firefly_version_hpp_tu() { return 0; }
