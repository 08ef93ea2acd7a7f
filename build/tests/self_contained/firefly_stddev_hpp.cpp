#include <firefly/stddev.hpp>
#include <firefly/stddev.hpp>  // include guard
int firefly_stddev_hpp_tu() { return 0; }
